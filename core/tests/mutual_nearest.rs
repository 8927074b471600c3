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

fn check<M: SpatialIndex + Default, S: SpatialIndex + Default>() {
    let map_points = laser_scans(20_000, 11);
    let mut map = M::default();
    for p in &map_points {
        map.insert(*p).unwrap();
    }
    let mut r = SplitMix::new(5);
    for trial in 0..20 {
        // A scan in its own frame, and the estimate that moves it into the map frame.
        let local: Vec<Point2<f64>> = laser_scans(181, 100 + trial)
            .iter()
            .map(|p| Point2::new(p.x * 0.5, p.y * 0.5))
            .collect();
        let pose = Pose2::new(r.range(-1.0, 1.0), r.range(-1.0, 1.0), r.range(-0.2, 0.2));
        let moved: Vec<Point2<f64>> = local.iter().map(|p| pose * *p).collect();
        let mut metric = MutualNearest::<S>::default();
        metric.begin_scan(&local);
        let mut pairs: Vec<Pair> = Vec::new();
        let query = Query {
            local: &local,
            points: &moved,
            pose,
            max_dist: 0.5,
        };
        metric.pair(&map, &query, &mut pairs);
        let want = brute_mutual(&map_points, &moved, 0.5);
        if want.len() < MutualNearest::<S>::MIN_PAIRS {
            continue; // the sparse-scene guard hands back closest pairs instead
        }
        let got: Vec<(u32, f64)> = pairs.iter().map(|p| (p.scan, p.dist_sq)).collect();
        assert_eq!(got, want, "trial {trial}");
    }
}

#[test]
fn alg2_over_quadtrees_equals_brute_force() {
    check::<QuadTree, QuadTree>();
}

#[test]
fn alg2_over_kdtrees_equals_brute_force() {
    check::<KdTree, KdTree>();
}

#[test]
fn alg2_over_brute_force_indexes_equals_brute_force() {
    check::<BruteForce, BruteForce>();
}
