//! The paper's Alg. 2 through the indexes equals mutual nearest neighbours found by brute force.

use qicp_core::testdata::{SplitMix, laser_scans};
use qicp_core::{
    BruteForce, CorrespondenceMetric, KdTree, MutualNearest, Pair, Point2, Pose2, QuadTree, Query,
    SpatialIndex, dist_sq,
};

/// Brute-force Alg. 2: p pairs with its nearest map point c if no scan point is nearer to c.
fn brute_mutual(map: &[Point2<f64>], scan_ref: &[Point2<f64>], max_dist: f64) -> Vec<(u32, f64)> {
    let mut out = Vec::new();
    for (k, p) in scan_ref.iter().enumerate() {
        let Some((c, d)) = map
            .iter()
            .map(|m| (*m, dist_sq(m, p)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
        else {
            continue;
        };
        if d > max_dist * max_dist {
            continue;
        }
        let nearest_to_c = scan_ref
            .iter()
            .map(|q| dist_sq(q, &c))
            .fold(f64::INFINITY, f64::min);
        // Mutual when p is (one of) c's nearest scan points.
        if dist_sq(p, &c) <= nearest_to_c * (1.0 + 1e-12) {
            out.push((k as u32, d));
        }
    }
    out
}

/// 181 points of `map` within 8·`scale` m of `pose` (all when fewer), moved by up to
/// 2·`scale` cm and taken in the frame of `pose`.
fn scan_near(map: &[Point2<f64>], pose: &Pose2, seed: u64, scale: f64) -> Vec<Point2<f64>> {
    let mut r = SplitMix::new(seed);
    let o = Point2::new(pose.x, pose.y);
    let (reach, noise) = (8.0 * scale, 0.02 * scale);
    let seen: Vec<&Point2<f64>> = map
        .iter()
        .filter(|m| dist_sq(m, &o) < reach * reach)
        .collect();
    (0..181.min(seen.len()))
        .map(|_| {
            let m = seen[(r.next_u64() % seen.len() as u64) as usize];
            let noisy = Point2::new(m.x + r.range(-noise, noise), m.y + r.range(-noise, noise));
            pose.inverse_transform_point(&noisy)
        })
        .collect()
}

/// One metric over 20 scans, as a matcher uses it. The laser-scan map is shrunk by `scale`:
/// at 1 its walls hold a point every ~1.3 cm, at 0.1 every ~1.3 mm, so the kept
/// neighbourhoods (whose widths are in metres, not in map units) hold hundreds of points and
/// adapt their width scan after scan.
fn check<M: SpatialIndex + Default, S: SpatialIndex + Default>(scale: f64) {
    let map_points: Vec<Point2<f64>> = laser_scans(20_000, 11)
        .into_iter()
        .map(|p| Point2::new(p.x * scale, p.y * scale))
        .collect();
    let mut map = M::default();
    for p in &map_points {
        map.insert(*p).expect("finite point");
    }
    let mut r = SplitMix::new(5);
    let mut compared = 0;
    let mut metric = MutualNearest::<S>::default();
    for trial in 0..20 {
        // A scan of map points near a pose, with centimetres of noise, in its own frame.
        let mut pose = Pose2::new(
            r.range(-15.0, 15.0) * scale,
            r.range(-5.0, 5.0) * scale,
            r.range(-3.0, 3.0),
        );
        let local = scan_near(&map_points, &pose, 100 + trial, scale);
        metric.begin_scan(&local);
        let mut pairs: Vec<Pair> = Vec::new();
        // The estimate wanders as an iteration moves it, with the gate shrinking: the searches
        // kept between iterations must give what fresh ones give.
        for it in 0..12 {
            let step = if it % 5 == 4 { 0.2 } else { 0.005 };
            pose = pose
                * Pose2::new(
                    r.range(-step, step) * scale,
                    r.range(-step, step) * scale,
                    r.range(-step, step),
                );
            let max_dist = [0.5, 0.25, 0.1][it / 4] * scale;
            let moved: Vec<Point2<f64>> = local.iter().map(|p| pose * *p).collect();
            let query = Query {
                local: &local,
                points: &moved,
                pose,
                max_dist,
            };
            metric.pair(&map, &query, &mut pairs);
            let want = brute_mutual(&map_points, &moved, max_dist);
            if want.len() < MutualNearest::<S>::MIN_PAIRS {
                continue; // the sparse-scene guard hands back closest pairs instead
            }
            let got: Vec<(u32, f64)> = pairs.iter().map(|p| (p.scan, p.dist_sq)).collect();
            assert_eq!(got, want, "trial {trial}, iteration {it}");
            compared += got.len();
        }
    }
    assert!(compared > 2_000, "only {compared} pairs compared");
}

/// A metric that searched one map and is then asked about another (no new scan in between)
/// answers from the new map, not from what it kept of the old one.
fn check_new_reference<M: SpatialIndex + Default>() {
    let first: Vec<Point2<f64>> = laser_scans(5_000, 21);
    let second: Vec<Point2<f64>> = first.iter().map(|p| Point2::new(p.x + 0.03, p.y)).collect();
    let pose = Pose2::new(0.2, -0.1, 0.05);
    let local = scan_near(&first, &pose, 22, 1.0);
    let moved: Vec<Point2<f64>> = local.iter().map(|p| pose * *p).collect();
    let query = Query {
        local: &local,
        points: &moved,
        pose,
        max_dist: 0.5,
    };
    let mut metric = MutualNearest::<M>::default();
    metric.begin_scan(&local);
    let mut pairs: Vec<Pair> = Vec::new();
    for points in [&first, &second] {
        let mut map = M::default();
        for p in points.iter() {
            map.insert(*p).expect("finite point");
        }
        metric.pair(&map, &query, &mut pairs);
        let got: Vec<(u32, f64)> = pairs.iter().map(|p| (p.scan, p.dist_sq)).collect();
        assert_eq!(got, brute_mutual(points, &moved, 0.5));
    }
}

#[test]
fn a_new_reference_is_searched_afresh() {
    check_new_reference::<QuadTree>();
    check_new_reference::<KdTree>();
}

#[test]
fn alg2_over_quadtrees_equals_brute_force() {
    check::<QuadTree, QuadTree>(1.0);
}

#[test]
fn alg2_over_kdtrees_equals_brute_force() {
    check::<KdTree, KdTree>(1.0);
}

#[test]
fn alg2_over_brute_force_indexes_equals_brute_force() {
    check::<BruteForce, BruteForce>(1.0);
}

#[test]
fn alg2_over_dense_quadtrees_equals_brute_force() {
    check::<QuadTree, QuadTree>(0.1);
}

#[test]
fn alg2_over_dense_kdtrees_equals_brute_force() {
    check::<KdTree, KdTree>(0.1);
}
