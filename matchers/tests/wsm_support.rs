//! A WSM estimate whose pairs fall out of the shrinking gate is not reported as a match: with
//! fewer final pairs than `min_correspondences` the result is a fallback to the guess.

use qicp_core::{BeamGeometry, Fallback, Pose2, QuadTree, Reference, Scan, ScanMatcher};
use qicp_matchers::{IcpParams, Wsm, WsmParams};

/// Ranges of beams spread over ±30° that hit a wall at x = 5, minus `short` on every beam
/// whose index is in `clutter` (something standing 0.5 m in front of the wall).
fn wall_scan(beams: usize, clutter: &[usize], short: f64) -> Scan {
    let fov = 60f64.to_radians();
    let geometry = BeamGeometry::centered(beams, fov, 30.0);
    let ranges = (0..beams)
        .map(|i| {
            let r = 5.0 / geometry.angle(i).cos();
            if clutter.contains(&i) { r - short } else { r }
        })
        .collect();
    Scan::new(0.0, geometry, ranges).expect("valid scan")
}

fn reference() -> Reference<QuadTree> {
    let mut r = Reference::new(QuadTree::default());
    r.insert_scan(&wall_scan(121, &[], 0.0), &Pose2::IDENTITY, None)
        .expect("insert");
    r
}

fn matcher(min_correspondences: usize) -> Wsm {
    let icp = IcpParams {
        min_correspondences,
        ..IcpParams::default()
    };
    Wsm::new(icp, WsmParams::default())
}

#[test]
fn pairs_lost_to_the_shrinking_gate_make_a_fallback() {
    // 12 points: 8 on the wall, 4 on clutter 0.5 m in front of it. The first gate (1 m) pairs
    // all 12; the last (0.2 m) only the 8 on the wall.
    let scan = wall_scan(12, &[1, 4, 7, 10], 0.5);
    let guess = Pose2::new(0.02, 0.0, 0.0);
    let result = matcher(12).match_with_prior(&reference(), &scan, guess, None);
    assert_eq!(
        result.fallback,
        Some(Fallback::TooFewCorrespondences { found: 8 }),
        "{result:?}"
    );
    assert_eq!(result.pose, guess);
}

#[test]
fn enough_pairs_left_make_a_match() {
    let scan = wall_scan(12, &[1, 4, 7, 10], 0.5);
    let guess = Pose2::new(0.02, 0.0, 0.0);
    let result = matcher(8).match_with_prior(&reference(), &scan, guess, None);
    assert_eq!(result.fallback, None, "{result:?}");
    assert_eq!(result.correspondences, 8);
    // The wall fixes x: the 2 cm error is gone.
    assert!(result.pose.x.abs() < 0.005, "{result:?}");
}
