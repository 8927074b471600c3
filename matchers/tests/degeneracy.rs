//! Along a corridor whose walls run past the laser's reach, the walls tell nothing of how far
//! the robot went. With `[matcher.motion] hold_unobserved` a match keeps odometry's estimate
//! along the axis and the scan's across it and in heading; where the scan sees a wall that
//! faces the axis, the match is left exactly as it was.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{Pose2, Record};
use qicp_matchers::{Estimate, MatcherConfig, MatcherKind};

/// The laser pose at scan `k`: zigzagging along a corridor's axis (world x), 0.15 m a scan.
fn zigzag(k: usize) -> Pose2 {
    let s = (0.4 * k as f64).sin();
    Pose2::new(-10.0 + 0.15 * k as f64, 0.4 * s, 0.3 * s)
}

/// 60 scans of `world` along the zigzag, odometry exact, matched by `kind` holding the
/// directions the scan does not fix or not.
fn run(world: &SyntheticWorld, kind: MatcherKind, hold: bool) -> Vec<Estimate> {
    run_with_beams(world, kind, hold, 181)
}

/// [`run`] with a laser of `beams` beams over 180°.
fn run_with_beams(
    world: &SyntheticWorld,
    kind: MatcherKind,
    hold: bool,
    beams: usize,
) -> Vec<Estimate> {
    let mut config = MatcherConfig::defaults(kind);
    config.motion.hold_unobserved = hold;
    let mut pipeline = config.build().expect("builds");
    (0..60)
        .map(|k| {
            let mut scan = world.scan_with_beams(&zigzag(k), beams, 0.01, k as u64 + 1);
            scan.timestamp = k as f64;
            pipeline.process(&Record {
                scan,
                odometry: zigzag(k),
                truth: Some(zigzag(k)),
                laser_offset: Pose2::IDENTITY,
            })
        })
        .collect()
}

/// The worst error along x and across it (m).
fn worst(estimates: &[Estimate]) -> (f64, f64) {
    estimates
        .iter()
        .enumerate()
        .fold((0.0f64, 0.0f64), |(along, across), (k, e)| {
            let truth = zigzag(k);
            (
                along.max((e.pose.x - truth.x).abs()),
                across.max((e.pose.y - truth.y).abs()),
            )
        })
}

#[test]
fn along_a_corridor_past_the_lasers_reach_the_match_keeps_odometry() {
    // Walls 100 m long, a 30 m laser: the scan's far ends pair with the ends of the walls
    // the reference holds. Measured: q-wsm 1.61 m along the axis without the hold, 0.0003 m
    // with it; q-idc 0.20 and 0.0004 m; wsm 0.61 and 0.014 m; idc 0.041 and 0.0012 m.
    let corridor = SyntheticWorld::featureless_corridor();
    for (kind, bound) in [
        (MatcherKind::QWsm, 0.005),
        (MatcherKind::QIdc, 0.005),
        (MatcherKind::Wsm, 0.03),
        (MatcherKind::Idc, 0.005),
    ] {
        let (free, _) = worst(&run(&corridor, kind, false));
        let (held, across) = worst(&run(&corridor, kind, true));
        assert!(
            held < bound,
            "{kind}: {held:.4} m along the axis with the hold"
        );
        assert!(
            free > 3.0 * held,
            "{kind}: {free:.4} m without, {held:.4} m with"
        );
        // Across the axis the scan's estimate stands.
        assert!(across < 0.02, "{kind}: {across:.4} m across");
    }
}

#[test]
fn a_dense_lasers_noisy_normals_do_not_face_the_corridors_axis() {
    // 721 beams (0.25°): the side walls, 1.2 m away, are sampled every 5-10 mm where they
    // pass the robot, and lines fitted through five such samples turn by tens of degrees at
    // random, enough for a few to face the axis. Counted as surfaces facing it, they said
    // the scan fixed the axis and the matches crept along it. Measured along the axis, with
    // the hold and noise's turn counted / discounted / without the hold: q-wsm 0.1466 /
    // 0.0038 / 0.2464 m, q-idc 0.0290 / 0.0009 / 0.0276 m.
    let corridor = SyntheticWorld::featureless_corridor();
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
        let (held, across) = worst(&run_with_beams(&corridor, kind, true, 721));
        let (free, _) = worst(&run_with_beams(&corridor, kind, false, 721));
        assert!(
            held < 0.005 && free > 3.0 * held,
            "{kind}: {held:.4} m along the axis with the hold, {free:.4} m without"
        );
        assert!(across < 0.02, "{kind}: {across:.4} m across");
    }
}

#[test]
fn where_walls_face_the_axis_the_matches_stay_as_they_were() {
    // The corridor's end wall (13-22 m ahead) and its door recess face the axis: the boosted
    // matchers' poses are the same with the hold as without it. Scan to scan, wsm holds a
    // few matches where the reference scan saw the end wall too sparsely, and its worst error
    // along the axis stays where it was (measured 0.0592 m without, 0.0575 m with).
    let corridor = SyntheticWorld::corridor();
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
        let (free, held) = (run(&corridor, kind, false), run(&corridor, kind, true));
        for (k, (a, b)) in free.iter().zip(&held).enumerate() {
            assert_eq!(a.pose, b.pose, "{kind}: scan {k}");
        }
    }
    let (free, _) = worst(&run(&corridor, MatcherKind::Wsm, false));
    let (held, _) = worst(&run(&corridor, MatcherKind::Wsm, true));
    assert!(
        held < free + 0.005,
        "wsm: {free:.4} m without, {held:.4} m with"
    );
}

#[test]
fn a_recovered_match_holds_the_prediction_not_the_searchs_start() {
    // Odometry's heading is 20° off at scan 30 alone: the match from that prediction is
    // poor, and the correlative search's best pose gives ICP a new start. Along the
    // featureless corridor the search's scores tie, and its start lies wherever they did;
    // the re-match keeps the prediction along the axis, which the glitch left true. Measured
    // for q-idc, which searches there: 0.25 m along the axis held at the search's start,
    // 0.0001 m at the prediction.
    let corridor = SyntheticWorld::featureless_corridor();
    let mut recovered = 0;
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
        let mut pipeline = MatcherConfig::defaults(kind).build().expect("builds");
        for k in 0..=30 {
            let mut scan = corridor.scan(&zigzag(k), 0.01, k as u64 + 1);
            scan.timestamp = k as f64;
            let glitch = if k == 30 { 20f64.to_radians() } else { 0.0 };
            let e = pipeline.process(&Record {
                scan,
                odometry: zigzag(k) * Pose2::new(0.0, 0.0, glitch),
                truth: Some(zigzag(k)),
                laser_offset: Pose2::IDENTITY,
            });
            let truth = zigzag(k);
            let (along, across) = ((e.pose.x - truth.x).abs(), (e.pose.y - truth.y).abs());
            assert!(
                along < 0.01 && across < 0.01,
                "{kind}, scan {k}: {along:.4} m along, {across:.4} m across ({:?})",
                e.check
            );
            recovered += usize::from(k == 30 && e.check.recovered && e.check.held);
        }
    }
    assert!(
        recovered > 0,
        "no held re-match at the glitch: the case is not tested"
    );
}
