//! WSM against a map that holds both faces of a thin wall: a scan of one face must not pair
//! with the other ([`WsmParams::face_angle_deg`]).

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{LaserNoise, Merge, MutualNearest, Pose2, QuadTree, Reference, ScanMatcher};
use qicp_matchers::{IcpParams, Wsm, WsmParams};

/// A 12 m × 10 m room split by a partition 10 cm thick (faces at y = 0 and y = 0.1, 3 m
/// long), with four posts.
fn room_with_partition() -> SyntheticWorld {
    SyntheticWorld {
        walls: vec![
            [-6.0, -5.0, 6.0, -5.0],
            [6.0, -5.0, 6.0, 5.0],
            [6.0, 5.0, -6.0, 5.0],
            [-6.0, 5.0, -6.0, -5.0],
            [-1.5, 0.0, 1.5, 0.0],
            [1.5, 0.0, 1.5, 0.1],
            [1.5, 0.1, -1.5, 0.1],
            [-1.5, 0.1, -1.5, 0.0],
        ],
        posts: vec![
            (-4.0, -3.0, 0.2),
            (4.0, -3.0, 0.2),
            (-4.0, 3.0, 0.2),
            (4.0, 3.0, 0.2),
        ],
    }
}

/// The map a robot lays from the partition's south side, looking north and south at
/// x = −2…2, and from its north side looking north only: the map holds the partition's
/// south face and no sample of its north face.
fn map_without_the_north_face(world: &SyntheticWorld) -> Reference<QuadTree> {
    let mut map = Reference::with_noise(QuadTree::default(), LaserNoise::default());
    let mut seed = 1;
    let mut lay = |map: &mut Reference<QuadTree>, pose: Pose2| {
        let scan = world.scan(&pose, 0.005, seed);
        seed += 1;
        map.insert_scan(&scan, &pose, Some(Merge::spacing(0.01)))
            .expect("finite points");
    };
    for k in 0..9 {
        let x = -2.0 + 0.5 * f64::from(k);
        lay(&mut map, Pose2::new(x, -2.5, std::f64::consts::FRAC_PI_2));
        lay(&mut map, Pose2::new(x, -2.5, -std::f64::consts::FRAC_PI_2));
        lay(&mut map, Pose2::new(x, 2.5, std::f64::consts::FRAC_PI_2));
    }
    map
}

/// The error (m) of WSM matching a scan of the partition's north face, taken from
/// (0.3, 2.0) looking south, against that map from a start 5 cm and 1° off.
fn north_face_error(face_angle_deg: f64) -> f64 {
    let world = room_with_partition();
    let map = map_without_the_north_face(&world);
    assert!(map.is_map());
    let truth = Pose2::new(0.3, 2.0, -std::f64::consts::FRAC_PI_2);
    let scan = world.scan(&truth, 0.005, 99);
    let mut wsm = Wsm::<MutualNearest<QuadTree>>::new(
        IcpParams::default(),
        WsmParams {
            face_angle_deg,
            ..WsmParams::default()
        },
    );
    let guess = Pose2::new(0.33, 2.04, truth.theta + 1f64.to_radians());
    let result = wsm.match_with_prior(&map, &scan, guess, None);
    assert!(result.fallback.is_none(), "{result:?}");
    truth.distance(&result.pose)
}

#[test]
fn a_scan_of_one_face_of_a_thin_wall_does_not_pair_with_the_other() {
    let gated = north_face_error(WsmParams::default().face_angle_deg);
    assert!(gated < 0.01, "gated: {gated:.4} m off");
    // The case breaks the ungated form: the north face's points pair with the south face's
    // samples 10 cm away and pull the pose towards them.
    let ungated = north_face_error(0.0);
    assert!(ungated > 0.03, "ungated: {ungated:.4} m off");
}
