//! Foliage: beams return inside a stand at its mean free path, pass thin stands, never reach
//! a stand behind a wall, and differ from scan to scan; the ray-box crossing agrees with a
//! march along the ray; the park's hedges leave a park without them as it was.

use nalgebra::{Point2, Vector2};
use qicp_sim::{Foliage, SimConfig, Simulation, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A custom world holding `obstacles` (TOML), the robot at the origin facing +x, a noise-free
/// laser of `beams` beams over `fov_deg`, 30 m range.
fn world(obstacles: &str, beams: usize, fov_deg: f64) -> SimConfig {
    let text = format!(
        r#"
[world]
kind = "custom"
{obstacles}
[laser]
beams = {beams}
fov_deg = {fov_deg}
max_range = 30.0
range_sigma = 0.0
[drive]
waypoints = [[0.0, 0.0], [1.0, 0.0]]
"#
    );
    SimConfig::from_toml_str(&text).expect("valid config")
}

const DEEP_STAND: &str = r#"
[[world.obstacles]]
kind = "foliage"
center = [7.0, 0.0]
half_size = [5.0, 20.0]
mean_free_path = 0.5
"#;

#[test]
fn beams_return_inside_a_stand_at_its_mean_free_path() {
    let mut sim = Simulation::new(world(DEEP_STAND, 361, 40.0)).expect("sim");
    let mut depths = Vec::new();
    let mut first: Option<Vec<f64>> = None;
    for _ in 0..4 {
        let scan = sim.scan_now().expect("scan");
        let g = scan.geometry;
        for (i, &r) in scan.ranges().iter().enumerate() {
            // The stand spans x in [2, 12]: along a beam at bearing b, [2, 12] / cos b.
            let cos = g.angle(i).cos();
            let (t_in, t_out) = (2.0 / cos, 12.0 / cos);
            assert!(
                r >= t_in - 1e-9 && r < t_out,
                "beam {i}: {r} outside [{t_in}, {t_out}]"
            );
            depths.push(r - t_in);
        }
        match &first {
            None => first = Some(scan.ranges().to_vec()),
            // Leaves return another surface at every scan.
            Some(f) => {
                let same = f.iter().zip(scan.ranges()).filter(|(a, b)| a == b).count();
                assert_eq!(same, 0, "{same} beams returned the same range twice");
            }
        }
    }
    let n = depths.len() as f64;
    let mean = depths.iter().sum::<f64>() / n;
    // Exponential: the mean is 0.5 m, its standard error 0.5 / √1444 = 0.013 m.
    assert!((mean - 0.5).abs() < 0.05, "mean depth {mean}");
    let sd = (depths.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!((sd - 0.5).abs() < 0.07, "depth spread {sd}");
}

#[test]
fn a_thin_stand_lets_most_beams_through_to_the_wall_behind() {
    // 0.1 m of foliage of mean free path 1 m across the beams' path, a wall at x = 8 behind it:
    // a beam straight ahead passes with probability exp(-0.1) = 0.905.
    let obstacles = r#"
[[world.obstacles]]
kind = "foliage"
center = [4.0, 0.0]
half_size = [0.05, 10.0]
mean_free_path = 1.0
[[world.obstacles]]
kind = "wall"
a = [8.1, -10.0]
b = [8.1, 10.0]
thickness = 0.2
"#;
    let mut sim = Simulation::new(world(obstacles, 11, 2.0)).expect("sim");
    let (mut wall, mut leaves, mut n) = (0, 0, 0);
    for _ in 0..300 {
        let scan = sim.scan_now().expect("scan");
        let g = scan.geometry;
        for (i, &r) in scan.ranges().iter().enumerate() {
            let cos = g.angle(i).cos();
            if (r - 8.0 / cos).abs() < 1e-4 {
                wall += 1;
            } else {
                assert!(r >= 3.95 / cos - 1e-9 && r < 4.05 / cos, "beam {i}: {r}");
                leaves += 1;
            }
            n += 1;
        }
    }
    let passed = f64::from(wall) / f64::from(n);
    assert_eq!(wall + leaves, n);
    assert!((passed - (-0.1f64).exp()).abs() < 0.02, "passed {passed}");
}

#[test]
fn foliage_behind_a_wall_is_never_seen() {
    let obstacles = format!(
        r#"{DEEP_STAND}
[[world.obstacles]]
kind = "wall"
a = [1.6, -10.0]
b = [1.6, 10.0]
thickness = 0.2
"#
    );
    let mut sim = Simulation::new(world(&obstacles, 21, 20.0)).expect("sim");
    let scan = sim.scan_now().expect("scan");
    let g = scan.geometry;
    for (i, &r) in scan.ranges().iter().enumerate() {
        assert!((r - 1.5 / g.angle(i).cos()).abs() < 1e-4, "beam {i}: {r}");
    }
}

/// The brute-force twin of [`Foliage::crossing`]: march along the ray in steps of `step` and
/// keep where the point lies inside the outline.
fn marched(f: &Foliage, o: &Point2<f64>, d: &Vector2<f64>, step: f64) -> Option<(f64, f64)> {
    let outline = f.outline();
    let inside: Vec<f64> = (0..40_000)
        .map(|k| k as f64 * step)
        .filter(|&t| outline.signed_distance(&(o + d * t)) <= 0.0)
        .collect();
    Some((*inside.first()?, *inside.last()?))
}

#[test]
fn the_crossing_agrees_with_a_march_along_the_ray() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let step = 1e-3;
    let mut hits = 0;
    for _ in 0..400 {
        let f = Foliage {
            center: Point2::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0)),
            half: Vector2::new(rng.random_range(0.2..4.0), rng.random_range(0.2..2.0)),
            angle: rng.random_range(-3.2..3.2),
            mean_free_path: 0.3,
        };
        let o = Point2::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0));
        // Most rays aimed near the stand, the rest anywhere.
        let to = f.center - o;
        let a: f64 = if rng.random_bool(0.75) {
            to.y.atan2(to.x) + rng.random_range(-0.6..0.6)
        } else {
            rng.random_range(-3.2..3.2)
        };
        let d = Vector2::new(a.cos(), a.sin());
        match (f.crossing(&o, &d), marched(&f, &o, &d, step)) {
            (None, None) => {}
            (Some((t_in, t_out)), Some((m_in, m_out))) => {
                hits += 1;
                assert!(t_in >= 0.0 && t_in < t_out);
                assert!(
                    (t_in - m_in).abs() <= step,
                    "enters at {t_in}, march {m_in}"
                );
                assert!(
                    (t_out - m_out).abs() <= step,
                    "leaves at {t_out}, march {m_out}"
                );
            }
            // A grazing ray may clip a corner by less than one step of the march.
            (Some((t_in, t_out)), None) => assert!(t_out - t_in < step, "{t_in}..{t_out}"),
            (None, Some((m_in, m_out))) => panic!("missed a crossing at {m_in}..{m_out}"),
        }
    }
    assert!(
        hits > 120,
        "only {hits} rays crossed: the test would prove little"
    );
}

#[test]
fn a_park_without_hedges_is_laid_out_as_before_and_hedges_become_foliage() {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/worlds/park.toml"),
    )
    .expect("shipped park");
    let plain = SimConfig::from_toml_str(&text).expect("park");
    let explicit =
        SimConfig::from_toml_str(&text.replace("benches = 2", "benches = 2\nhedges = 0"))
            .expect("park with hedges = 0");
    let hedged = SimConfig::from_toml_str(&text.replace("benches = 2", "benches = 2\nhedges = 8"))
        .expect("park with hedges");
    let (a, b, c) = (
        World::build(&plain).expect("world"),
        World::build(&explicit).expect("world"),
        World::build(&hedged).expect("world"),
    );
    assert_eq!(a, b);
    assert!(a.foliage.is_empty());
    // The hedges are placed after everything else: the solid layout stays.
    assert_eq!(c.obstacles, a.obstacles);
    assert_eq!(c.route, a.route);
    assert_eq!(c.foliage.len(), 8);
    for f in &c.foliage {
        assert!((f.mean_free_path - 0.3).abs() < 1e-12);
        assert!(f.half.x >= 1.5 && f.half.x <= 5.0 && f.half.y >= 0.5 && f.half.y <= 1.0);
    }
}
