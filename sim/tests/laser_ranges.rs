//! The laser's beams hit known obstacles at analytically known ranges.

use qicp_core::BeamStatus;
use qicp_sim::{SimConfig, Simulation};

/// A custom world: a wall across x = 5 (thickness 0.2, so its face is at x = 4.9), a post of
/// radius 0.25 at (3, 3), a box below the robot; the robot at the origin facing +x.
fn world(offset_x: f64) -> SimConfig {
    let text = format!(
        r#"
[world]
kind = "custom"
[[world.obstacles]]
kind = "wall"
a = [5.0, -2.0]
b = [5.0, 2.0]
thickness = 0.2
[[world.obstacles]]
kind = "circle"
center = [3.0, 3.0]
radius = 0.25
[[world.obstacles]]
kind = "box"
center = [0.0, -3.0]
half_size = [1.0, 0.5]
angle_deg = 0.0
[laser]
beams = 181
fov_deg = 180.0
max_range = 10.0
range_sigma = 0.0
offset_x = {offset_x}
[drive]
waypoints = [[0.0, 0.0], [1.0, 0.0]]
max_scans = 1
"#
    );
    SimConfig::from_toml_str(&text).expect("valid config")
}

#[test]
fn beams_hit_a_wall_a_post_and_a_box_at_their_analytic_ranges() {
    let mut sim = Simulation::new(world(0.0)).expect("sim");
    let record = sim.next().expect("one record").expect("scan");
    assert_eq!(record.timestamp(), 0.0);
    let truth = record.truth.expect("truth");
    assert!(truth.x.abs() < 1e-9 && truth.y.abs() < 1e-9 && truth.theta.abs() < 1e-9);
    let scan = &record.scan;
    assert_eq!(scan.beams(), 181);
    let r = scan.ranges();
    let deg = |i: usize| scan.geometry.angle(i).to_degrees();
    // Beam 90 looks straight ahead at the wall's face.
    assert!((deg(90)).abs() < 1e-9);
    assert!((r[90] - 4.9).abs() < 1e-4, "wall: {}", r[90]);
    // Off-axis beams hit the same plane at 4.9 / cos(bearing) while within the wall.
    for i in [80, 85, 95, 100] {
        let expected = 4.9 / deg(i).to_radians().cos();
        assert!(
            (r[i] - expected).abs() < 1e-4,
            "beam {i}: {} vs {expected}",
            r[i]
        );
    }
    // The post sits at bearing +45°, beam 135: its near surface is √18 − 0.25 away.
    assert!((deg(135) - 45.0).abs() < 1e-9);
    assert!(
        (r[135] - (18f64.sqrt() - 0.25)).abs() < 1e-4,
        "post: {}",
        r[135]
    );
    // Straight down (beam 0, −90°) the box's top face is 2.5 m away.
    assert!((r[0] - 2.5).abs() < 1e-4, "box: {}", r[0]);
    // Straight left (beam 180, +90°) there is nothing: max range, marked as no return.
    assert_eq!(r[180], 10.0);
    assert_eq!(scan.status()[180], BeamStatus::MaxRange);
    assert_eq!(scan.status()[90], BeamStatus::Valid);
}

#[test]
fn the_laser_offset_moves_the_ray_origin() {
    let mut sim = Simulation::new(world(0.4)).expect("sim");
    let record = sim.next().expect("one record").expect("scan");
    assert!((record.laser_offset.x - 0.4).abs() < 1e-12);
    assert!((record.scan.ranges()[90] - 4.5).abs() < 1e-4);
}

#[test]
fn direct_ray_casts_match_the_geometry() {
    let sim = Simulation::new(world(0.0)).expect("sim");
    let hit = sim
        .cast_ray((0.0, 0.0), 0.0, 10.0)
        .expect("the wall is in range");
    assert!((hit - 4.9).abs() < 1e-4);
    // A ray from (3, 0) straight up meets the post's bottom at y = 2.75.
    let hit = sim
        .cast_ray((3.0, 0.0), std::f64::consts::FRAC_PI_2, 10.0)
        .expect("post");
    assert!((hit - 2.75).abs() < 1e-4);
    // Out of range: no hit.
    assert_eq!(sim.cast_ray((0.0, 0.0), 0.0, 4.0), None);
    // The robot's own body is not seen.
    let back = sim.cast_ray((0.0, 0.0), std::f64::consts::PI, 10.0);
    assert_eq!(back, None);
}

#[test]
fn range_noise_has_the_configured_spread() {
    let mut cfg = world(0.0);
    cfg.laser.range_sigma = 0.05;
    cfg.laser.beams = 11;
    cfg.laser.fov_deg = 10.0;
    let mut sim = Simulation::new(cfg).expect("sim");
    let mut errors = Vec::new();
    for _ in 0..200 {
        let scan = sim.scan_now().expect("scan");
        let g = scan.geometry;
        for (i, &r) in scan.ranges().iter().enumerate() {
            errors.push(r - 4.9 / g.angle(i).cos());
        }
    }
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let sd = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(mean.abs() < 0.01, "mean {mean}");
    assert!((sd - 0.05).abs() < 0.005, "sd {sd}");
}
