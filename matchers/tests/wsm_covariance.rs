//! WSM's covariance says where a scan leaves the pose open: in a featureless corridor along its
//! axis, not across it.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{MutualNearest, Pose2, QuadTree, Reference, ScanMatcher};
use qicp_matchers::{IcpParams, Wsm, WsmParams};

#[test]
fn covariance_is_larger_along_a_corridor_than_across_it() {
    let world = SyntheticWorld::featureless_corridor();
    // The corridor runs along x; the robot drives along it, slightly turned.
    for heading in [0.0f64, 0.3, -0.4] {
        let from = Pose2::new(0.0, 0.2, heading);
        let motion = Pose2::new(0.3, 0.0, 0.02);
        let mut reference = Reference::new(QuadTree::default());
        reference
            .insert_scan(&world.scan(&from, 0.005, 1), &Pose2::IDENTITY, None)
            .unwrap();
        let scan = world.scan(&(from * motion), 0.005, 2);
        let mut wsm =
            Wsm::<MutualNearest<QuadTree>>::new(IcpParams::default(), WsmParams::default());
        let r = wsm.match_scan(&reference, &scan, motion);
        // The result is in the frame of the first scan: rotate the covariance into the
        // corridor's frame (x along the axis).
        let rot = Pose2::new(0.0, 0.0, heading).rotation();
        let c = r.covariance.fixed_view::<2, 2>(0, 0).into_owned();
        let world_cov = rot * c * rot.transpose();
        let (along, across) = (world_cov[(0, 0)], world_cov[(1, 1)]);
        assert!(
            along > 10.0 * across,
            "heading {heading}: σ² along {along:.3e} vs across {across:.3e}"
        );
        // Across the corridor the scan pins the pose down.
        let est_world = from * r.pose;
        let truth = from * motion;
        assert!((est_world.y - truth.y).abs() < 0.02, "lateral error");
    }
}
