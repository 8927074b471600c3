//! Every matcher, over every index, recovers a known displacement on synthetic scans of known
//! geometry (room, corridor, sparse posts) from initial errors up to 0.3 m and 10°.
//! Written once over `M: ScanMatcher`, instantiated per matcher by a macro.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{
    BruteForce, ClosestPoint, KdTree, Merge, MutualNearest, Pose2, QuadTree, Reference,
    ScanMatcher, SpatialIndex, normalize_angle,
};
use qicp_matchers::{IcpParams, Idc, IdcParams, Wsm, WsmParams};

/// Initial-guess errors: up to 0.3 m and 10° (some combined).
fn guess_errors() -> Vec<Pose2> {
    let d = 10f64.to_radians();
    vec![
        Pose2::new(0.0, 0.0, 0.0),
        Pose2::new(0.3, 0.0, 0.0),
        Pose2::new(0.0, -0.3, 0.0),
        Pose2::new(0.0, 0.0, d),
        Pose2::new(0.0, 0.0, -d),
        Pose2::new(0.2, 0.2, 0.5 * d),
        Pose2::new(-0.2, 0.15, -d),
    ]
}

struct Case {
    name: &'static str,
    world: SyntheticWorld,
    from: Pose2,
    motion: Pose2,
}

fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "room",
            world: SyntheticWorld::room(),
            from: Pose2::new(-1.0, -1.0, 0.3),
            motion: Pose2::new(0.4, 0.1, 0.08),
        },
        Case {
            name: "corridor",
            world: SyntheticWorld::corridor(),
            from: Pose2::new(-1.0, 0.1, 0.05),
            motion: Pose2::new(0.5, -0.05, -0.05),
        },
        Case {
            name: "posts",
            world: SyntheticWorld::posts(),
            from: Pose2::new(0.0, 0.0, 0.2),
            motion: Pose2::new(0.5, 0.1, 0.1),
        },
    ]
}

/// Matches a scan taken after `motion` against the scan before it, from perturbed guesses.
fn recovers_known_motion<M: ScanMatcher, I: SpatialIndex + Default>(mut matcher: M) {
    for case in cases() {
        let before = case.world.scan(&case.from, 0.005, 1);
        let after = case.world.scan(&(case.from * case.motion), 0.005, 2);
        let mut reference = Reference::new(I::default());
        reference
            .insert_scan(&before, &Pose2::IDENTITY, None)
            .expect("finite scan");
        for error in guess_errors() {
            let guess = case.motion * error;
            let r = matcher.match_scan(&reference, &after, guess);
            let dt = r.pose.distance(&case.motion);
            let dr = normalize_angle(r.pose.theta - case.motion.theta)
                .abs()
                .to_degrees();
            assert!(
                r.fallback.is_none() && dt < 0.03 && dr < 0.5,
                "{} on {} from error {:?}: off by {dt:.4} m, {dr:.3}° ({r:?})",
                matcher.name(),
                case.name,
                error
            );
            assert!(r.correspondences >= 12 && r.residual < 0.05);
        }
    }
}

/// The same, against a map holding several scans in a world frame (boosted matching).
fn recovers_pose_in_map<M: ScanMatcher, I: SpatialIndex + Default>(mut matcher: M) {
    for case in cases() {
        let mut map = Reference::new(I::default());
        let mut pose = case.from;
        for k in 0..4 {
            map.insert_scan(
                &case.world.scan(&pose, 0.005, 10 + k),
                &pose,
                Some(Merge::spacing(0.02)),
            )
            .expect("finite scan");
            pose = pose * Pose2::new(0.2, 0.0, 0.03);
        }
        let truth = pose * case.motion;
        let scan = case.world.scan(&truth, 0.005, 99);
        for error in guess_errors() {
            let r = matcher.match_scan(&map, &scan, truth * error);
            let dt = r.pose.distance(&truth);
            let dr = normalize_angle(r.pose.theta - truth.theta)
                .abs()
                .to_degrees();
            assert!(
                dt < 0.03 && dr < 0.5,
                "{} in map of {} from error {:?}: off by {dt:.4} m, {dr:.3}°",
                matcher.name(),
                case.name,
                error
            );
        }
    }
}

macro_rules! conformance {
    ($($name:ident: $matcher:expr),* $(,)?) => {$(
        mod $name {
            use super::*;
            #[test] fn scan_to_scan_quadtree() { recovers_known_motion::<_, QuadTree>($matcher) }
            #[test] fn scan_to_scan_kdtree() { recovers_known_motion::<_, KdTree>($matcher) }
            #[test] fn scan_to_scan_brute_force() { recovers_known_motion::<_, BruteForce>($matcher) }
            #[test] fn scan_to_map_quadtree() { recovers_pose_in_map::<_, QuadTree>($matcher) }
            #[test] fn scan_to_map_kdtree() { recovers_pose_in_map::<_, KdTree>($matcher) }
        }
    )*};
}

conformance! {
    idc: Idc::<ClosestPoint>::new(IcpParams::default(), IdcParams::default()),
    wsm: Wsm::<ClosestPoint>::new(IcpParams::default(), WsmParams::default()),
    idc_mutual: Idc::<MutualNearest<QuadTree>>::new(IcpParams::default(), IdcParams::default()),
    wsm_mutual: Wsm::<MutualNearest<QuadTree>>::new(IcpParams::default(), WsmParams::default()),
    wsm_mutual_kd: Wsm::<MutualNearest<KdTree>>::new(IcpParams::default(), WsmParams::default()),
}
