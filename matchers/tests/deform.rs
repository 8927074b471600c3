//! Spreading a re-anchoring's correction over the stretch that drifted
//! ([`qicp_matchers::trail`]): a move that lays a drifted copy of the room back onto the old
//! map fits, the same move of a copy laid right does not.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{Merge, Pose2, QuadTree, Reference};
use qicp_matchers::trail::moves_fit;
use std::collections::HashMap;

/// The room laid from ten poses: scans 0-4 at their poses (the old map), scans 5-9 `drift`
/// off them.
fn laid(drift: Pose2) -> Reference<QuadTree> {
    let room = SyntheticWorld::room();
    let mut map = Reference::new(QuadTree::default());
    for k in 0..10 {
        let pose = Pose2::new(-1.0 + 0.2 * k as f64, 0.1 * k as f64, 0.15 * k as f64);
        let at = if k < 5 { pose } else { drift * pose };
        map.insert_scan(
            &room.scan(&pose, 0.005, k + 1),
            &at,
            Some(Merge::spacing(0.01)),
        )
        .expect("finite points");
    }
    map
}

/// Scans 5-9 moved by `by`.
fn stretch_moved(by: Pose2) -> HashMap<u32, Pose2> {
    (5..10).map(|k| (k, by)).collect()
}

#[test]
fn a_move_that_lays_a_drifted_stretch_onto_the_old_map_fits() {
    let drift = Pose2::new(0.35, -0.2, 2f64.to_radians());
    assert!(moves_fit(&laid(drift), &stretch_moved(drift.inverse())));
    // Half of it fits too: the stretch comes nearer.
    let half = Pose2::new(-0.175, 0.1, -1f64.to_radians());
    assert!(moves_fit(&laid(drift), &stretch_moved(half)));
}

#[test]
fn a_move_that_pulls_a_stretch_laid_right_off_the_old_map_does_not_fit() {
    let wrong = Pose2::new(0.35, -0.2, 2f64.to_radians());
    assert!(!moves_fit(&laid(Pose2::IDENTITY), &stretch_moved(wrong)));
    // Nor does the opposite move of a drifted stretch, which doubles the drift.
    assert!(!moves_fit(&laid(wrong), &stretch_moved(wrong)));
    // Nothing to move fits trivially.
    assert!(moves_fit(&laid(wrong), &HashMap::new()));
}
