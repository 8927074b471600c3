//! The checks around paper Alg. 1, each on a synthetic case made to break the plain form:
//! a start 20° off is recovered by the correlative search, and a wrong match does not enter
//! the map.

use qicp_core::testdata::{SplitMix, SyntheticWorld};
use qicp_core::{
    Fallback, FullCell, LaserNoise, MatchResult, Matrix3, Merge, MutualNearest, Point2, Pose2,
    QuadTree, Record, Reference, Scan, ScanMatcher, SpatialIndex,
};
use qicp_matchers::degeneracy::weak_direction;
use qicp_matchers::{
    CorrelativeParams, Estimate, FieldOfView, IcpParams, Idc, IdcParams, MatcherConfig,
    MatcherKind, MotionModel, Odometry, Pipeline, Placed, Policy, Relevance, ValidationParams,
    Validator, Wsm, WsmParams,
};

/// The boosted matchers and the scan-to-scan ones they boost.
const BOOSTED_AND_PLAIN: [MatcherKind; 4] = [
    MatcherKind::QWsm,
    MatcherKind::QIdc,
    MatcherKind::Wsm,
    MatcherKind::Idc,
];

/// Asserts that each of [`BOOSTED_AND_PLAIN`] at its defaults keeps the worst heading error
/// `heading_error` measures after a stall below `bound_deg`.
fn each_stays_within(bound_deg: f64, heading_error: impl Fn(MatcherConfig) -> f64) {
    for kind in BOOSTED_AND_PLAIN {
        let worst = heading_error(MatcherConfig::defaults(kind));
        assert!(
            worst < bound_deg,
            "{kind}: worst heading error {worst:.2}° after the stall"
        );
    }
}

/// The robot's pose at scan `k`: along the room, turning slowly.
fn truth(k: usize) -> Pose2 {
    Pose2::new(
        -3.0 + 0.12 * k as f64,
        -1.0 + 0.03 * k as f64,
        0.02 * k as f64,
    )
}

fn record(k: usize, odometry: Pose2) -> Record {
    record_in(&SyntheticWorld::room(), k, odometry)
}

fn record_in(world: &SyntheticWorld, k: usize, odometry: Pose2) -> Record {
    record_at(world, &truth(k), k, odometry)
}

/// Scan `k` of the room seen from `pose` (its noise seeded by `k`), read with `odometry`.
fn room_record_at(pose: &Pose2, k: usize, odometry: Pose2) -> Record {
    record_at(&SyntheticWorld::room(), pose, k, odometry)
}

/// Scan `k` of `world` seen from `pose` (its noise seeded by `k`), read with `odometry`.
fn record_at(world: &SyntheticWorld, pose: &Pose2, k: usize, odometry: Pose2) -> Record {
    let mut scan = world.scan(pose, 0.005, k as u64 + 1);
    scan.timestamp = k as f64;
    Record {
        scan,
        odometry,
        truth: Some(*pose),
        laser_offset: Pose2::IDENTITY,
    }
}

/// Odometry that follows the truth until scan `at`, where the wheels slip and it turns by
/// `slip` at once; its increments are right again after.
fn slipping_odometry(k: usize, at: usize, slip: Pose2) -> Pose2 {
    if k < at { truth(k) } else { truth(k) * slip }
}

fn error(estimate: &Pose2, k: usize) -> (f64, f64) {
    let t = truth(k);
    (
        estimate.distance(&t),
        qicp_core::normalize_angle(estimate.theta - t.theta)
            .abs()
            .to_degrees(),
    )
}

/// `kind`'s defaults with the checks on or off (`checked`) and, for WSM, its face gate on or
/// off (`faces`, `[matcher.wsm] face_angle_deg`). Both off is the unchecked form that a 20°
/// start breaks.
fn config(kind: MatcherKind, checked: bool, faces: bool) -> MatcherConfig {
    let defaults = MatcherConfig::defaults(kind);
    let mut c = if faces || defaults.algorithm() != "wsm" {
        defaults
    } else {
        MatcherConfig::from_toml(&format!(
            "[matcher]\nkind = \"{kind}\"\n[matcher.wsm]\nface_angle_deg = 0.0\n"
        ))
        .expect("a valid config")
    };
    c.validation.enabled = checked;
    // The paper's plain form holds nothing either (README, Configuration).
    c.motion.hold_unobserved &= checked;
    c
}

/// Runs `config` over 30 scans whose odometry slips by `slip` at scan 15: the worst position
/// (m) and heading (deg) errors, and how often it searched.
fn slip_run(world: &SyntheticWorld, config: &MatcherConfig, slip: Pose2) -> (f64, f64, usize) {
    let mut pipeline = config.build().expect("builds");
    let (mut dist, mut deg, mut searched) = (0.0f64, 0.0f64, 0);
    for k in 0..30 {
        let e = pipeline.process(&record_in(world, k, slipping_odometry(k, 15, slip)));
        searched += usize::from(e.check.searched);
        let (d, g) = error(&e.pose, k);
        (dist, deg) = (dist.max(d), deg.max(g));
    }
    (dist, deg, searched)
}

#[test]
fn a_start_twenty_degrees_off_is_recovered() {
    // Sparse posts and a corridor: worlds where ICP from a start 20° off settles in a wrong
    // basin, and the plain Alg. 1 writes it into its map.
    for (name, world) in [
        ("posts", SyntheticWorld::posts()),
        ("corridor", SyntheticWorld::corridor()),
    ] {
        for slip_deg in [20.0f64, -20.0] {
            let slip = Pose2::new(0.0, 0.0, slip_deg.to_radians());
            for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
                let case = format!("{name}, {kind}, slip {slip_deg}°");
                let (plain, _, _) = slip_run(&world, &config(kind, false, false), slip);
                assert!(
                    plain > 0.3,
                    "{case}: the plain form must break ({plain:.2} m)"
                );
                // The correlative search recovers it. WSM's face gate is off here: in the
                // corridor it alone can keep q-wsm out of the wrong basin, whose pairs join
                // walls that face apart, and the search is never asked.
                let (dist, deg, searched) = slip_run(&world, &config(kind, true, false), slip);
                assert!(searched >= 1, "{case}: the slip must trigger the search");
                assert!(
                    dist < 0.06 && deg < 1.5,
                    "{case}: worst {dist:.3} m, {deg:.2}° (plain {plain:.2} m)"
                );
                let (dist, deg, _) = slip_run(&world, &config(kind, true, true), slip);
                assert!(
                    dist < 0.06 && deg < 1.5,
                    "{case}, defaults: worst {dist:.3} m, {deg:.2}°"
                );
            }
        }
    }
}

/// A matcher that returns a wrong pose on its calls `at` to `until` (`at` 0: never), as a
/// match that converged into the wrong basin would: `wrong` turns the right pose into the
/// wrong one. It keeps the prior of each call in `priors`.
#[derive(Debug)]
struct Sabotaged<M> {
    inner: M,
    calls: usize,
    at: usize,
    until: usize,
    wrong: fn(&Pose2) -> Pose2,
    priors: Priors,
}

/// The priors a [`Sabotaged`] matcher was given, one per call.
type Priors = std::sync::Arc<std::sync::Mutex<Vec<Option<Matrix3<f64>>>>>;

/// Off by 0.4 m and 0.3 m in the scan's frame, and turned by 15°.
fn turned(p: &Pose2) -> Pose2 {
    *p * Pose2::new(0.4, 0.3, 15f64.to_radians())
}

impl<M: ScanMatcher> ScanMatcher for Sabotaged<M> {
    fn name(&self) -> &'static str {
        "sabotaged"
    }

    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        self.priors.lock().expect("not poisoned").push(prior);
        let mut result = self.inner.match_with_prior(reference, scan, guess, prior);
        self.calls += 1;
        if self.at > 0 && (self.at..=self.until.max(self.at)).contains(&self.calls) {
            result.pose = (self.wrong)(&result.pose);
        }
        result
    }
}

type Plain = Wsm<MutualNearest<QuadTree>>;

fn sabotaged(at: usize, validation: ValidationParams) -> Pipeline<Sabotaged<Plain>, QuadTree> {
    sabotaged_with(at, turned, validation)
}

fn sabotaged_with(
    at: usize,
    wrong: fn(&Pose2) -> Pose2,
    validation: ValidationParams,
) -> Pipeline<Sabotaged<Plain>, QuadTree> {
    sabotaged_over(at, at, wrong, validation)
}

/// The sabotaged WSM wrong on its calls `at` to `until`, every scan relevant.
fn sabotaged_over(
    at: usize,
    until: usize,
    wrong: fn(&Pose2) -> Pose2,
    validation: ValidationParams,
) -> Pipeline<Sabotaged<Plain>, QuadTree> {
    boosted_every_scan(
        Sabotaged {
            inner: Plain::new(IcpParams::default(), WsmParams::default()),
            calls: 0,
            at,
            until,
            wrong,
            priors: Priors::default(),
        },
        validation,
    )
}

/// `matcher` against a quad-tree map that every scan enters, checked as `validation` says.
fn boosted_every_scan<M: ScanMatcher>(
    matcher: M,
    validation: ValidationParams,
) -> Pipeline<M, QuadTree> {
    let every_scan = Relevance {
        tau_max: 0.0,
        rho_max_deg: 0.0,
        map_resolution: Some(0.0),
        ..Relevance::default()
    };
    Pipeline::new(
        matcher.name(),
        matcher,
        QuadTree::default(),
        Policy::Boosted(every_scan),
        LaserNoise::default(),
    )
    .with_validation(validation, CorrelativeParams::default())
}

#[test]
fn a_wrong_match_does_not_enter_the_map() {
    let no_search = ValidationParams {
        search: false,
        ..ValidationParams::default()
    };
    let mut pipeline = sabotaged(12, no_search);
    for k in 0..20 {
        let before = pipeline.reference().len();
        let e = pipeline.process(&record(k, truth(k)));
        if k == 11 {
            // The 12th call matches scan 11.
            assert!(e.check.refused, "{e:?}");
            assert!(!e.inserted);
            assert_eq!(
                pipeline.reference().len(),
                before,
                "nothing of it in the map"
            );
        } else {
            assert!(!e.check.refused, "scan {k}: {e:?}");
            let (dist, deg) = error(&e.pose, k);
            assert!(dist < 0.03 && deg < 0.5, "scan {k}: {dist:.3} m, {deg:.2}°");
        }
    }
    // The paper's plain form takes it in.
    let plain = ValidationParams {
        enabled: false,
        ..ValidationParams::default()
    };
    let mut pipeline = sabotaged(12, plain);
    for k in 0..12 {
        let e = pipeline.process(&record(k, truth(k)));
        assert!(e.inserted, "scan {k}");
    }
}

#[test]
fn a_match_after_a_run_of_refusals_is_not_followed_where_the_prediction_explains_more() {
    // Scans 11-14 are matched wrong. The first three are refused, and the third refusal in a
    // row starts the level afresh; scan 14's match then has no level to be judged by. With
    // odometry's veto off, only the prediction's share can tell it went astray.
    let unvetoed = ValidationParams {
        search: false,
        max_odometry_chi2: 0.0,
        ..ValidationParams::default()
    };
    let mut pipeline = sabotaged_over(12, 15, turned, unvetoed);
    for k in 0..20 {
        let before = pipeline.reference().len();
        let e = pipeline.process(&record(k, truth(k)));
        let (dist, deg) = error(&e.pose, k);
        assert!(dist < 0.03 && deg < 0.5, "scan {k}: {dist:.3} m, {deg:.2}°");
        if (11..=13).contains(&k) {
            assert!(e.check.refused, "scan {k}: {e:?}");
        }
        if (11..=14).contains(&k) {
            assert_eq!(e.result.fallback, Some(Fallback::Refused), "scan {k}");
            assert!(!e.inserted, "scan {k}");
            assert_eq!(pipeline.reference().len(), before, "scan {k}");
        }
    }
}

/// WSM matched wrong (`turned`) on every call for scans 11-13, so that three refusals in a row
/// clear the level, and left at its start on its first call for scan 14: ICP stopped in a
/// local minimum short of where the scan belongs, as after a fast turn into new ground. Its
/// later calls (the search's re-match) are right.
#[derive(Debug)]
struct StuckAfterRefusals {
    inner: Plain,
    last_scan: Option<f64>,
}

impl ScanMatcher for StuckAfterRefusals {
    fn name(&self) -> &'static str {
        "stuck after refusals"
    }

    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        let first_call = self.last_scan != Some(scan.timestamp);
        self.last_scan = Some(scan.timestamp);
        let mut result = self.inner.match_with_prior(reference, scan, guess, prior);
        // The records' timestamps are their numbers.
        match scan.timestamp as usize {
            11..=13 => result.pose = turned(&result.pose),
            14 if first_call => result.pose = guess,
            _ => {}
        }
        result
    }
}

/// The checked WSM of [`StuckAfterRefusals`] against a map that takes every scan.
fn stuck_after_refusals(validation: ValidationParams) -> Pipeline<StuckAfterRefusals, QuadTree> {
    boosted_every_scan(
        StuckAfterRefusals {
            inner: Plain::new(IcpParams::default(), WsmParams::default()),
            last_scan: None,
        },
        validation,
    )
}

/// The room's twenty scans as [`stuck_after_refusals`] matches them (scans 11-13 refused,
/// scan 14 stuck), odometry slipping by 4° and 0.1 m at scan 14 (within its χ² test): each
/// scan's position and heading errors, and whether it entered the map.
fn stuck_after_refusals_run(validation: ValidationParams) -> Vec<(f64, f64, bool)> {
    let slip = Pose2::new(0.1, 0.0, 4f64.to_radians());
    let mut pipeline = stuck_after_refusals(validation);
    (0..20)
        .map(|k| {
            let e = pipeline.process(&record(k, slipping_odometry(k, 14, slip)));
            if (11..=13).contains(&k) {
                assert!(e.check.refused, "scan {k}: {e:?}");
            }
            let (dist, deg) = error(&e.pose, k);
            (dist, deg, e.inserted)
        })
        .collect()
}

#[test]
fn a_match_stuck_short_after_a_run_of_refusals_is_searched_again() {
    // With no level after the refusals, scan 14's match sits at odometry's slipped
    // prediction, which explains as much of the scan as the match: nothing marks it poor.
    // Searched all the same, it is re-matched where it belongs.
    for (k, (dist, deg, _)) in stuck_after_refusals_run(ValidationParams::default())
        .into_iter()
        .enumerate()
    {
        assert!(dist < 0.03 && deg < 0.5, "scan {k}: {dist:.3} m, {deg:.2}°");
    }
    // Searching only poor matches, the stuck match enters the map 4° off.
    let poor_only = ValidationParams {
        search_after_refusals: false,
        ..ValidationParams::default()
    };
    let (_, deg, inserted) = stuck_after_refusals_run(poor_only)[14];
    assert!(
        deg > 3.5 && inserted,
        "scan 14: {deg:.2}°, inserted {inserted}"
    );
}

/// Slid 0.4 m along the corridor's axis (world x): every point still lies on a wall.
fn slid(p: &Pose2) -> Pose2 {
    Pose2::new(0.4, 0.0, 0.0) * *p
}

#[test]
fn a_slide_odometry_never_made_does_not_enter_the_map() {
    // In a featureless corridor a slide along the axis keeps every point on a wall, so the
    // share and residual checks pass it; only odometry (a 0.12 m step, σ 7.5 cm) can tell.
    let corridor = SyntheticWorld::featureless_corridor();
    let run = |chi2: f64, falls_back: bool| {
        let gate = ValidationParams {
            max_odometry_chi2: chi2,
            veto_falls_back: falls_back,
            ..ValidationParams::default()
        };
        // The hold would keep odometry along the axis before the veto saw the slide (below).
        let mut pipeline = sabotaged_with(12, slid, gate).with_motion_model(MotionModel {
            hold_unobserved: false,
            ..MotionModel::default()
        });
        (0..20)
            .map(|k| {
                let before = pipeline.reference().len();
                let e = pipeline.process(&record_in(&corridor, k, truth(k)));
                (e, pipeline.reference().len() - before)
            })
            .collect::<Vec<_>>()
    };
    let chi2 = ValidationParams::default().max_odometry_chi2;
    for falls_back in [true, false] {
        let mut drift = 0.0;
        for (k, (e, added)) in run(chi2, falls_back).into_iter().enumerate() {
            assert!(!e.check.refused && !e.check.searched, "scan {k}: {e:?}");
            // Along a featureless axis only odometry holds x, so even right matches drift by
            // centimetres there: the slide is measured against the previous scan's drift.
            let slide = e.pose.x - truth(k).x - drift;
            drift = e.pose.x - truth(k).x;
            if k == 11 {
                // The 12th call matches scan 11: withheld, kept out of the map.
                assert!(e.check.withheld && !e.inserted && added == 0, "{e:?}");
                if falls_back {
                    // The prediction explains the corridor as well: odometry's pose stands.
                    assert_eq!(e.result.fallback, Some(Fallback::Refused), "{e:?}");
                    assert!(slide.abs() < 1e-6, "slid {slide:.3} m: {e:?}");
                } else {
                    // Reported as matched, and followed.
                    assert!(e.result.fallback.is_none() && slide > 0.3, "{e:?}");
                }
            } else {
                // Good matches, and those that follow the slide as odometry does, go in.
                assert!(!e.check.withheld && e.inserted, "scan {k}: {e:?}");
            }
        }
    }
    // With the gate off the slide enters the map.
    let (e, added) = run(0.0, true).swap_remove(11);
    assert!(!e.check.withheld && e.inserted && added > 0, "{e:?}");
    // With the hold (the default) the slide along the featureless axis never happens: the
    // match keeps odometry's x, and enters the map as a right match.
    let mut pipeline = sabotaged_with(12, slid, ValidationParams::default());
    for k in 0..12 {
        let e = pipeline.process(&record_in(&corridor, k, truth(k)));
        if k == 11 {
            assert!(e.check.held && !e.check.withheld && e.inserted, "{e:?}");
            assert!((e.pose.x - truth(k).x).abs() < 0.01, "{e:?}");
        }
    }
}

#[test]
fn a_wrong_match_is_searched_again_and_recovered() {
    let mut pipeline = sabotaged(12, ValidationParams::default());
    for k in 0..20 {
        let e = pipeline.process(&record(k, truth(k)));
        assert_eq!(e.check.recovered, k == 11, "scan {k}: {e:?}");
        assert!(!e.check.refused, "scan {k}: {e:?}");
        let (dist, deg) = error(&e.pose, k);
        assert!(dist < 0.03 && deg < 0.5, "scan {k}: {dist:.3} m, {deg:.2}°");
    }
}

/// q-idc built as a typed pipeline with every default, not through the registry.
fn typed_q_idc() -> Pipeline<Idc<MutualNearest<QuadTree>>, QuadTree> {
    Pipeline::new(
        "q-idc",
        Idc::<MutualNearest<QuadTree>>::new(IcpParams::default(), IdcParams::default()),
        QuadTree::default(),
        Policy::Boosted(Relevance::default()),
        LaserNoise::default(),
    )
}

#[test]
fn idc_is_checked_the_same_way() {
    let mut pipeline = typed_q_idc();
    for k in 0..20 {
        let e = pipeline.process(&record(k, truth(k)));
        let (dist, deg) = error(&e.pose, k);
        assert!(dist < 0.03 && deg < 0.5, "scan {k}: {dist:.3} m, {deg:.2}°");
        assert!(!e.check.refused, "scan {k}: {e:?}");
        if k > 6 {
            assert!(e.check.inlier_share > 0.8, "scan {k}: {e:?}");
        }
    }
}

/// The laser pose at step `k` of a loop of 40 steps, radius 2 m, in the room.
fn on_loop(k: usize) -> Pose2 {
    let a = std::f64::consts::TAU * (k % 40) as f64 / 40.0;
    Pose2::new(
        0.5 + 2.0 * a.cos(),
        -0.5 + 2.0 * a.sin(),
        a + std::f64::consts::FRAC_PI_2,
    )
}

/// The record of step `k` of the loop, with perfect odometry.
fn loop_record(world: &SyntheticWorld, k: usize) -> Record {
    let truth = on_loop(k);
    let mut scan = world.scan(&truth, 0.005, k as u64 + 1);
    scan.timestamp = k as f64;
    Record {
        scan,
        odometry: truth,
        truth: Some(truth),
        laser_offset: Pose2::IDENTITY,
    }
}

#[test]
fn the_map_stays_under_its_density_cap_over_ten_loops() {
    let world = SyntheticWorld::room();
    // The default spacing (WSM's 1 cm, IDC's 2 cm) and a full cell replacing its stalest
    // point, without the surface band and the novelty gate, which would keep most of the
    // revisits' points out before the cell cap sees them. The room's walls, 2 m off, are
    // sampled every few centimetres: a look puts two or three points into a 10 cm cell, so
    // the default caps (29 and 15) would bind only after many more loops; a cap of 6 binds
    // within three.
    for (kind, cap) in [(MatcherKind::QWsm, 0.01), (MatcherKind::QIdc, 0.02)] {
        let mut config = MatcherConfig::defaults(kind);
        config.relevance.surface_band_sigmas = Some(0.0);
        config.relevance.min_novelty = Some(0.0);
        assert_eq!(config.relevance.full_cell, FullCell::EvictStalest);
        config.relevance.max_cell_points = Some(6);
        let mut pipeline = config.build().expect("builds");
        let mut after_loop = Vec::new();
        for k in 0..400 {
            let e = pipeline.process(&loop_record(&world, k));
            assert!(
                e.pose.distance(&on_loop(k)) < 0.05,
                "{kind} step {k}: {e:?}"
            );
            if k % 40 == 39 {
                after_loop.push(pipeline.live_points().len());
            }
        }
        let (first, last) = (after_loop[0], after_loop[9]);
        assert!(
            last as f64 <= 1.5 * first as f64,
            "{kind}: {first} points after one loop, {last} after ten ({after_loop:?})"
        );
        // The cap itself: no two live map points closer than the resolution (brute force).
        let points = pipeline.live_points();
        assert!(
            points.len() * 8 >= pipeline.reference_points().len() * 7,
            "{kind}: replaced points leave the map"
        );
        let points = &points;
        for (i, p) in points.iter().enumerate() {
            for q in &points[i + 1..] {
                assert!(
                    (p - q).norm() >= cap,
                    "{kind}: {p} and {q} closer than {cap}"
                );
            }
        }
        // And the cell cap: no cell holds more than its share (counted one by one).
        let fullest = fullest_cell(points, config.relevance.cell_size);
        assert!(
            Some(fullest) <= config.relevance.max_cell_points,
            "{kind}: a cell holds {fullest} points"
        );
        if kind == MatcherKind::QWsm {
            assert_eq!(fullest, 6, "the revisits must fill cells to mean anything");
        }
        println!("{kind}: map points after each loop {after_loop:?}");
    }
    // Without the caps the map grows with every loop.
    let mut config = MatcherConfig::defaults(MatcherKind::QWsm);
    config.relevance.map_resolution = Some(0.0);
    config.relevance.surface_band_sigmas = Some(0.0);
    config.relevance.min_novelty = Some(0.0);
    config.relevance.max_cell_points = Some(0);
    let mut pipeline = config.build().expect("builds");
    let mut sizes = Vec::new();
    for k in 0..120 {
        pipeline.process(&loop_record(&world, k));
        if k % 40 == 39 {
            sizes.push(pipeline.reference_points().len());
        }
    }
    println!("full density: {sizes:?}");
    assert!(sizes[2] as f64 > 2.5 * sizes[0] as f64, "{sizes:?}");
}

/// The room with a bush at scan `k`: its 60 leaves (posts of 1 cm radius) lie each scan
/// somewhere else within 0.4 m of the bush's centre, as a laser's returns from foliage do.
fn room_with_bush(k: usize) -> SyntheticWorld {
    let mut world = SyntheticWorld::room();
    let mut rng = SplitMix::new(k as u64 + 1);
    for _ in 0..60 {
        let (r, a) = (
            0.4 * rng.unit().sqrt(),
            rng.range(0.0, std::f64::consts::TAU),
        );
        world
            .posts
            .push((-3.3 + r * a.cos(), -2.4 + r * a.sin(), 0.01));
    }
    world
}

/// The room on loop `lap`: three carts stand each loop somewhere else within 0.4 m of their
/// places, as furniture moved between visits does.
fn room_with_carts_moved(lap: usize) -> SyntheticWorld {
    let mut world = SyntheticWorld::room();
    let mut rng = SplitMix::new(lap as u64 + 1);
    for (x, y) in [(-3.3, -2.6), (-3.6, 2.6), (3.8, 1.6)] {
        world
            .posts
            .push((x + rng.range(-0.4, 0.4), y + rng.range(-0.4, 0.4), 0.3));
    }
    world
}

#[test]
fn clutter_that_moves_stops_growing_the_default_maps_once_its_ground_is_covered() {
    // Clutter puts points off every surface the map holds, so the surface band lets them
    // all in. With the defaults the novelty gate still stops the map: once the ground the
    // clutter moves over holds points within the novelty distance (5 cm) of its returns, a
    // scan adds nothing there. Without the gate every relevant scan adds its leaves.
    const LAPS: usize = 30;
    let bush = |_lap: usize, k: usize| room_with_bush(k);
    let carts = |lap: usize, _k: usize| room_with_carts_moved(lap);
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
        let config = MatcherConfig::defaults(kind);
        // Foliage changes on every scan: covered within a few loops.
        let foliage = loop_sizes_in(&config, LAPS, bush);
        assert!(
            foliage[LAPS - 1] as f64 <= 1.02 * foliage[9] as f64,
            "{kind}: the map grows after ten loops by the bush ({foliage:?})"
        );
        let mut ungated = config.clone();
        ungated.relevance.min_novelty = Some(0.0);
        let ungated = loop_sizes_in(&ungated, LAPS, bush);
        assert!(
            ungated[LAPS - 1] as f64 > 1.1 * ungated[9] as f64,
            "{kind}: without the gate the bush must keep growing the map ({ungated:?})"
        );
        // Carts moved between loops, within 0.4 m: covered in about twenty loops.
        let moved = loop_sizes_in(&config, LAPS, carts);
        assert!(
            moved[LAPS - 1] as f64 <= 1.02 * moved[LAPS - 6] as f64,
            "{kind}: the carts grow the map in the last five loops ({moved:?})"
        );
        assert!(
            moved[LAPS - 1] as f64 > 1.3 * moved[0] as f64,
            "{kind}: the carts' new places must enter the map to mean anything ({moved:?})"
        );
    }
}

#[test]
fn the_maps_size_counts_only_its_live_points() {
    // A full cell's replaced points stay in the index until a rebuild drops them; the map's
    // size (`qicp match`'s `map_points`, the Python package's `map_points()`) leaves them out.
    let mut config = MatcherConfig::defaults(MatcherKind::QWsm);
    config.relevance.min_novelty = Some(0.0);
    config.relevance.max_cell_points = Some(3);
    let mut pipeline = config.build().expect("builds");
    let mut stale_seen = false;
    for k in 0..80 {
        pipeline.process(&loop_record(&SyntheticWorld::room(), k));
        let live = pipeline.live_points().len();
        assert_eq!(pipeline.live_len(), live, "step {k}");
        stale_seen |= pipeline.reference_points().len() > live;
    }
    assert!(stale_seen, "no replaced point waited for a rebuild");
}

/// The most points any square cell of side `size` holds, counted one by one.
fn fullest_cell(points: &[Point2<f64>], size: f64) -> u32 {
    let mut cells = std::collections::HashMap::new();
    for p in points {
        *cells
            .entry(((p.x / size).floor() as i64, (p.y / size).floor() as i64))
            .or_insert(0u32) += 1;
    }
    cells.values().copied().max().unwrap_or(0)
}

#[test]
fn the_default_cell_cap_holds_a_bush_the_novelty_gate_lets_in() {
    // With the novelty gate off, every relevant scan adds the leaves it sees: they lie off
    // every surface the map holds, so neither the spacing nor the surface band keeps them
    // out, and over thirty loops the bush's cells fill past two surfaces' worth of samples. The default cell
    // cap (two surfaces' samples per 10 cm cell at the map's spacing) holds every cell to
    // it, replacing the stalest points.
    const LAPS: usize = 30;
    let bush = |_lap: usize, k: usize| room_with_bush(k);
    for (kind, cap) in [(MatcherKind::QWsm, 29), (MatcherKind::QIdc, 15)] {
        let mut config = MatcherConfig::defaults(kind);
        config.relevance.min_novelty = Some(0.0);
        let mut filled = config.clone();
        filled.fill_defaults();
        assert_eq!(filled.relevance.max_cell_points, Some(cap), "{kind}");
        let mut uncapped = config.clone();
        uncapped.relevance.max_cell_points = Some(0);
        let [capped, uncapped] = [config, uncapped].map(|c| {
            let mut pipeline = c.build().expect("builds");
            drive_loops(pipeline.as_mut(), LAPS, bush);
            let live = pipeline.live_points();
            (live.len(), fullest_cell(&live, c.relevance.cell_size))
        });
        println!("{kind}: (live points, fullest cell) capped {capped:?}, uncapped {uncapped:?}");
        assert!(capped.1 <= cap, "{kind}: a cell holds {} points", capped.1);
        assert!(
            uncapped.1 > cap,
            "{kind}: without the cap the bush must fill a cell past it ({uncapped:?})"
        );
        assert!(capped.0 <= uncapped.0, "{kind}: {capped:?} {uncapped:?}");
    }
}

/// Map points after each of `loops` loops of the room, with `config`.
fn loop_sizes(config: MatcherConfig, loops: usize) -> Vec<usize> {
    loop_sizes_in(&config, loops, |_, _| SyntheticWorld::room())
}

/// Map points after each of `loops` loops, with `config`, the world at scan `k` of loop `lap`
/// being `world(lap, k)`.
fn loop_sizes_in(
    config: &MatcherConfig,
    loops: usize,
    world: impl Fn(usize, usize) -> SyntheticWorld,
) -> Vec<usize> {
    let mut pipeline = config.build().expect("builds");
    drive_loops(pipeline.as_mut(), loops, world)
}

/// Map points after each of `loops` loops driven through `pipeline`, the world at scan `k`
/// of loop `lap` being `world(lap, k)`.
fn drive_loops(
    pipeline: &mut dyn Odometry,
    loops: usize,
    world: impl Fn(usize, usize) -> SyntheticWorld,
) -> Vec<usize> {
    let mut sizes = Vec::new();
    for k in 0..40 * loops {
        let e = pipeline.process(&loop_record(&world(k / 40, k), k));
        assert!(e.pose.distance(&on_loop(k)) < 0.05, "step {k}: {e:?}");
        if k % 40 == 39 {
            sizes.push(pipeline.reference_points().len());
        }
    }
    sizes
}

#[test]
fn the_default_surface_band_slows_the_growth_of_a_map_driven_ten_times() {
    // IDC's default has no band (its range rule needs every sample); it is checked on.
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
        // Without the novelty gate, which keeps most revisits out of the map whole.
        let mut banded = MatcherConfig::defaults(kind);
        banded.relevance.surface_band_sigmas = Some(1.0);
        banded.relevance.min_novelty = Some(0.0);
        let banded = loop_sizes(banded, 10);
        let mut plain = MatcherConfig::defaults(kind);
        plain.relevance.surface_band_sigmas = Some(0.0);
        plain.relevance.min_novelty = Some(0.0);
        let plain = loop_sizes(plain, 10);
        println!("{kind}: with the band {banded:?}, without {plain:?}");
        // The band keeps out what lands on the walls held (q-wsm: 2,918 points after ten
        // loops against 4,265; q-idc with the band, whose map is sparser by its 2 cm
        // spacing: 1,398 against 1,522); what lands farther off still enters, so the map
        // grows more slowly, it does not stop.
        assert!(
            (banded[9] as f64) < 0.95 * plain[9] as f64,
            "{kind}: with the band {banded:?}, without {plain:?}"
        );
    }
    // The defaults: on for WSM, off for IDC.
    assert_eq!(effective(MatcherKind::QWsm).surface_band_sigmas, Some(1.0));
    assert_eq!(effective(MatcherKind::QIdc).surface_band_sigmas, Some(0.0));
}

/// The relevance section of `kind`'s defaults, with the matcher's own defaults filled in.
fn effective(kind: MatcherKind) -> Relevance {
    let mut c = MatcherConfig::defaults(kind);
    c.fill_defaults();
    c.relevance
}

#[test]
fn a_windowed_map_holds_only_its_recent_scans_over_ten_loops() {
    let world = SyntheticWorld::room();
    let run = |window_scans: usize| {
        let mut pipeline = Pipeline::new(
            "q-wsm",
            Plain::new(IcpParams::default(), WsmParams::default()),
            QuadTree::default(),
            Policy::Boosted(Relevance {
                window_scans,
                // Every relevant scan enters, so that the window is what bounds the map.
                min_novelty: Some(0.0),
                ..Relevance::default()
            }),
            LaserNoise::default(),
        );
        (0..400)
            .map(|k| {
                let e = pipeline.process(&loop_record(&world, k));
                assert!(e.pose.distance(&on_loop(k)) < 0.05, "step {k}: {e:?}");
                (pipeline.reference().scans(), pipeline.reference().len())
            })
            .collect::<Vec<_>>()
    };
    // Every step turns 9°, so every scan is relevant and enters the map.
    let windowed = run(20);
    for (k, &(scans, _)) in windowed.iter().enumerate() {
        assert!(scans <= 30, "step {k}: {scans} scans in the map");
        if k >= 20 {
            assert!(scans >= 20, "step {k}: only {scans} scans in the map");
        }
    }
    let most_points = windowed.iter().map(|w| w.1).max().unwrap_or(0);
    // Without the window every scan stays.
    let whole = run(0);
    assert_eq!(whole.last().map(|w| w.0), Some(400));
    println!("windowed map: at most {most_points} points");
}

#[test]
fn revisits_add_nothing_to_a_map_with_the_novelty_gate() {
    let laps = |min_novelty: f64| {
        let mut config = MatcherConfig::defaults(MatcherKind::QWsm);
        config.relevance.min_novelty = Some(min_novelty);
        loop_sizes(config, 10)
    };
    let gated = laps(0.02);
    let open = laps(0.0);
    println!("novelty gate 0.02: {gated:?}; without: {open:?}");
    // With the gate, nine more laps add almost nothing; without it the map keeps growing.
    assert!(gated[9] as f64 <= 1.05 * gated[0] as f64, "{gated:?}");
    assert!(open[9] as f64 > 1.2 * open[0] as f64, "{open:?}");
}

#[test]
fn the_map_matchers_gate_their_maps_by_novelty_by_default_and_stop_growing_over_ten_loops() {
    // The default: 5 % of a scan new, for IDC and WSM alike.
    for kind in [MatcherKind::QIdc, MatcherKind::QWsm] {
        assert_eq!(effective(kind).min_novelty, Some(0.05), "{kind:?}");
        let gated = loop_sizes(MatcherConfig::defaults(kind), 10);
        let mut open = MatcherConfig::defaults(kind);
        open.relevance.min_novelty = Some(0.0);
        let open = loop_sizes(open, 10);
        println!("{kind:?} by default: {gated:?}; min_novelty = 0: {open:?}");
        // Nine more laps: q-idc 985 → 1,025 points with the gate, 1,284 → 1,522 without;
        // q-wsm 1,083 → 1,083, and 1,529 → 2,918 without.
        assert!(
            gated[9] as f64 <= 1.05 * gated[0] as f64,
            "{kind:?} {gated:?}"
        );
        assert!(
            4 * gated[9].saturating_sub(gated[0]) < open[9].saturating_sub(open[0]),
            "{kind:?} {gated:?} {open:?}"
        );
    }
    // A typed pipeline takes the matcher's own default, as the registry's does.
    let mut typed = typed_q_idc();
    let sizes = drive_loops(&mut typed, 10, |_, _| SyntheticWorld::room());
    assert!(
        sizes[9] as f64 <= 1.05 * sizes[0] as f64,
        "typed: {sizes:?}"
    );
}

/// Posts along the first 5 m of the drive and nothing after: the scans fix the motion while
/// posts are ahead, and nothing at all once they are behind the 180° laser (every beam
/// returns nothing, as in an open field).
fn posts_at_the_start() -> SyntheticWorld {
    SyntheticWorld {
        walls: Vec::new(),
        posts: (0..6)
            .flat_map(|k| [(k as f64, 1.5, 0.1), (k as f64 + 0.5, -1.5, 0.1)])
            .collect(),
    }
}

/// Drives 12 m past the posts at 0.1 m a scan with odometry 6 % long (a slipping wheel's
/// encoder counts what the ground does not make); the final position error of q-wsm with
/// calibration over `calibration_m` metres (0: off).
fn slipping_drive_error(calibration_m: f64) -> f64 {
    let world = posts_at_the_start();
    let at = |k: usize| Pose2::new(-1.0 + 0.1 * k as f64, 0.0, 0.0);
    let mut c = MatcherConfig::defaults(MatcherKind::QWsm);
    c.motion.calibration_m = calibration_m;
    let mut pipeline = c.build().expect("builds");
    let mut last = Pose2::IDENTITY;
    for k in 0..120 {
        let mut scan = world.scan(&at(k), 0.005, k as u64 + 1);
        scan.timestamp = k as f64;
        let odometry = Pose2::new(-1.0 + 0.106 * k as f64, 0.0, 0.0);
        let e = pipeline.process(&Record {
            scan,
            odometry,
            truth: Some(at(k)),
            laser_offset: Pose2::IDENTITY,
        });
        last = e.pose;
    }
    last.distance(&at(119))
}

#[test]
fn a_slipping_wheel_is_calibrated_where_the_scans_see_it_and_corrected_where_they_cannot() {
    let plain = slipping_drive_error(0.0);
    let calibrated = slipping_drive_error(20.0);
    println!("final error: {plain:.3} m plain, {calibrated:.3} m calibrated");
    // Without calibration the empty stretch keeps odometry's 6 % (0.35 m over its 6 m).
    assert!(plain > 0.3, "plain {plain:.3} m");
    assert!(calibrated < plain / 3.0, "calibrated {calibrated:.3} m");
}

/// The robot's pose at scan `k` of a fast turn in the room: 0.05 m and 11.5° a scan.
fn turning(k: usize) -> Pose2 {
    Pose2::new(-1.0 + 0.05 * k as f64, 0.5, 0.2 * k as f64)
}

/// Runs `config` over 30 room records, the robot at `truth(k)` and odometry reading
/// `reading(k)`: the worst error (deg) from scan `from` on of the estimate's turn since scan 0
/// against the truth's.
fn worst_heading_error(
    config: MatcherConfig,
    truth: impl Fn(usize) -> Pose2,
    reading: impl Fn(usize) -> Pose2,
    from: usize,
) -> f64 {
    let record = |k| room_record_at(&truth(k), k, reading(k));
    worst_heading_error_of(config, &truth, record, from, |_, _| {})
}

/// [`worst_heading_error`] over 30 records built by `record(k)`, the robot at `truth(k)`;
/// `each` sees every record's estimate.
fn worst_heading_error_of(
    config: MatcherConfig,
    truth: impl Fn(usize) -> Pose2,
    record: impl Fn(usize) -> Record,
    from: usize,
    mut each: impl FnMut(usize, &Estimate),
) -> f64 {
    let mut odometry = config.build().expect("builds");
    let mut first = None;
    let mut worst = 0.0f64;
    for k in 0..30 {
        let e = odometry.process(&record(k));
        each(k, &e);
        let first = *first.get_or_insert(e.pose.theta);
        if k >= from {
            let turned = truth(k).theta - truth(0).theta;
            let off = qicp_core::normalize_angle(e.pose.theta - first - turned);
            worst = worst.max(off.abs().to_degrees());
        }
    }
    worst
}

/// The fast turn whose odometry repeats its reading of scan 9 for scans 10 to 13 and then
/// reads the truth again (a stalled reading that catches up, as the MIT CSAIL log's does three
/// times): the worst heading error (deg) from scan 14 on.
fn stalled_turn_heading_error(config: MatcherConfig) -> f64 {
    let read = |k| if (10..14).contains(&k) { 9 } else { k };
    worst_heading_error(config, turning, |k| turning(read(k)), 14)
}

#[test]
fn a_stalled_odometry_reading_that_catches_up_is_not_counted_twice() {
    // Applied to the previous pose, the first new reading turns q-wsm's estimate by the 46°
    // the four stalled scans have turned already, and its map with it. (With the stall's
    // records predicted at the matched velocity, `stall_velocity`, this room's correlative
    // search happens to find the turn again; the restart must not need it.)
    let mut plain = MatcherConfig::defaults(MatcherKind::QWsm);
    plain.motion.stall_restart = false;
    plain.motion.stall_velocity = false;
    let counted_twice = stalled_turn_heading_error(plain);
    assert!(
        counted_twice > 10.0,
        "q-wsm: applied to the previous pose the catch-up must break the heading ({counted_twice:.1}°)"
    );
    // IDC drops a prior that explains the scan badly, and a scan-to-scan reference is
    // replaced by the stalled scans: they recover either way, and must with the restart too.
    each_stays_within(1.0, stalled_turn_heading_error);
}

#[test]
fn a_stalled_reading_that_carries_rounding_noise_is_still_a_stall() {
    // The sweep's perturbed odometry recomposes every increment, and a stall's zero
    // increments came out as readings a few 1e-13 m apart: read as motion, the catch-up
    // was applied to the previous pose and MIT CSAIL's `odom-noise` and `odom-bias` runs of
    // q-wsm lost 44° at its first stall (4.3 and 4.1 m on relations along q-plicp's run with
    // its revisits, against 0.017 m).
    let read = |k: usize| {
        if (10..14).contains(&k) {
            let e = 1e-13 * k as f64;
            turning(9) * Pose2::new(3.0 * e, -2.0 * e, e)
        } else {
            turning(k)
        }
    };
    each_stays_within(1.0, |config| worst_heading_error(config, turning, read, 14));
}

/// `config` over the fast turn of [`turning`] through the corridor, whose odometry jumps
/// ahead at scan 10 to its reading of scan 15 and repeats it until then, reading the truth
/// again after (a catch-up that comes before its stall, as the MIT CSAIL log's do played
/// backwards): the worst heading error (deg) from scan 16 on.
fn jumped_ahead_heading_error(config: MatcherConfig) -> f64 {
    let world = SyntheticWorld::corridor();
    let read = |k| if (10..15).contains(&k) { 15 } else { k };
    let record = |k| record_at(&world, &turning(k), k, turning(read(k)));
    worst_heading_error_of(config, turning, record, 16, |_, _| {})
}

#[test]
fn a_reading_that_jumped_ahead_before_its_stall_is_applied_to_the_previous_pose() {
    // Applied from where the stall began, as a reading that stalled and then caught up must
    // be, the first new reading counts the turn the stall's matches followed as undone: the
    // prediction lay four scans (46°) behind, and q-wsm, q-idc and idc ended 57°, 31° and 33°
    // off (MIT CSAIL played backwards lost 45° and 40° so). The matches over the stall tell
    // which reading it was.
    each_stays_within(3.0, jumped_ahead_heading_error);
}

/// The robot's pose at scan `k` of a drive in the room that turns right at 15° a scan until
/// scan 12 and then left at 15° a scan, 0.05 m a scan.
fn turning_back(k: usize) -> Pose2 {
    let deg = if k <= 12 {
        -15.0 * k as f64
    } else {
        15.0 * (k as f64 - 24.0)
    };
    Pose2::new(-1.0 + 0.05 * k as f64, 0.5, deg.to_radians())
}

/// `config` over the drive of [`turning_back`], whose scans from 13 on see no returns over
/// the right 40 % of their view, so that their matches stand (what they pair fits) but keep
/// too few pairs for the check's running level, and whose odometry repeats its reading of
/// scan 19 for scans 20 to 23 and then reads the truth again: the worst heading error (deg)
/// from scan 20 on against the truth's turn, and how many matches of the left turn before
/// the stall stood without passing the check (searched, neither recovered nor refused).
fn stall_after_a_turn_no_match_passed(config: MatcherConfig) -> (f64, usize) {
    let record = |k: usize| {
        let truth = turning_back(k);
        let full = SyntheticWorld::room().scan(&truth, 0.005, k as u64 + 1);
        let mut ranges = full.ranges().to_vec();
        if k > 12 {
            // Something close by hides the right 40 % of the view: no returns there.
            ranges[..72].fill(f64::NAN);
        }
        let read = if (20..24).contains(&k) { 19 } else { k };
        Record {
            scan: Scan::new(k as f64, full.geometry, ranges).expect("a valid scan"),
            odometry: turning_back(read),
            truth: Some(truth),
            laser_offset: Pose2::IDENTITY,
        }
    };
    let mut unchecked = 0;
    let worst = worst_heading_error_of(config, turning_back, record, 20, |k, e| {
        let check = &e.check;
        if (13..20).contains(&k) && check.searched && !check.recovered && !check.refused {
            unchecked += 1;
        }
    });
    (worst, unchecked)
}

#[test]
fn a_stall_after_a_turn_whose_matches_stood_unchecked_is_predicted_at_that_turn() {
    // The MIT CSAIL log stalls during fast turns whose matches the check finds poor (they
    // keep 30-50 % fewer pairs) but does not refuse. Predicted at the motion of the last
    // match that passed, an earlier turn the other way, the stall's first record lay 21° off
    // the truth and q-wsm lost three records by 21-29°. Weighed against moving odometry and
    // not contradicted, those matches give the stall its velocity. Predicted at the right
    // turn's 15° a scan, this drive's stall lay 30° off: every matcher lost it (49-90° off)
    // before the rule.
    for kind in BOOSTED_AND_PLAIN {
        let (worst, unchecked) = stall_after_a_turn_no_match_passed(MatcherConfig::defaults(kind));
        println!("{kind}: worst heading error {worst:.2}° after {unchecked} unchecked matches");
        assert!(
            unchecked >= 4,
            "{kind}: the left turn's matches must stand unchecked ({unchecked})"
        );
        assert!(
            worst < 1.0,
            "{kind}: worst heading error {worst:.2}° over the stall"
        );
    }
}

/// The robot's pose at scan `k` of a turn in the room at `deg` a scan, 0.08 m a scan.
fn turning_at(deg: f64, k: usize) -> Pose2 {
    Pose2::new(-1.0 + 0.08 * k as f64, 0.5, (deg * k as f64).to_radians())
}

/// A turn at `deg` a scan with no odometry: every record reads the same pose, as a log
/// without odometry does. The worst heading error (deg).
fn turn_without_odometry(config: MatcherConfig, deg: f64) -> f64 {
    worst_heading_error(config, |k| turning_at(deg, k), |_| Pose2::IDENTITY, 0)
}

#[test]
fn a_log_without_odometry_is_followed_at_the_matched_velocity() {
    // Turning 15° a scan with the repeated reading as its prior, odometry's veto holds q-wsm
    // to a robot standing still and its map turns with the error.
    let mut held = MatcherConfig::defaults(MatcherKind::QWsm);
    held.motion.stall_velocity = false;
    let standing = turn_without_odometry(held, 15.0);
    assert!(
        standing > 10.0,
        "q-wsm held by the repeated reading: {standing:.1}°"
    );
    for kind in [MatcherKind::QWsm, MatcherKind::Wsm] {
        let error = turn_without_odometry(MatcherConfig::defaults(kind), 15.0);
        assert!(
            error < 1.0,
            "{kind}: worst heading error {error:.2}° at 15° a scan"
        );
    }
    // IDC's matching-range rule does not reach 15° from a standing start (q-idc 50°, idc 21°
    // either way); at 8° a scan every matcher follows the turn.
    for kind in BOOSTED_AND_PLAIN {
        let error = turn_without_odometry(MatcherConfig::defaults(kind), 8.0);
        assert!(
            error < 1.0,
            "{kind}: worst heading error {error:.2}° at 8° a scan"
        );
    }
}

/// WSM with a narrow basin on the records in `wrong` (numbered by their stamps): there a
/// match that has to move more than 0.1 m from its start converges into the wrong basin
/// ([`turned`]); every other match is right.
#[derive(Debug)]
struct NarrowBasin {
    inner: Plain,
    wrong: std::ops::RangeInclusive<usize>,
}

impl ScanMatcher for NarrowBasin {
    fn name(&self) -> &'static str {
        "narrow basin"
    }

    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        let mut result = self.inner.match_with_prior(reference, scan, guess, prior);
        if self.wrong.contains(&(scan.timestamp as usize)) && guess.distance(&result.pose) > 0.1 {
            result.pose = turned(&result.pose);
        }
        result
    }
}

/// The robot's pose at scan `k` of a drive through the room whose speed changes every scan,
/// 0.05 and 0.25 m in turn, so that a constant velocity mispredicts each scan by 0.2 m.
fn jerky(k: usize) -> Pose2 {
    let x = (0..k)
        .map(|i| if i % 2 == 0 { 0.05 } else { 0.25 })
        .sum::<f64>();
    Pose2::new(-2.5 + x, 0.3, 0.01 * k as f64)
}

/// q-wsm's pipeline on the jerky drive without odometry, with a narrow basin at records 12
/// to 14 (the prediction is 0.2 m off there, the search's pose within its raster) and the
/// check's search off: the worst error (m) of the estimate's
/// motion since scan 0.
fn jerky_without_odometry(correlative_start: bool) -> f64 {
    let validation = ValidationParams {
        search: false,
        ..ValidationParams::default()
    };
    let correlative = CorrelativeParams {
        start_without_odometry: correlative_start,
        ..CorrelativeParams::default()
    };
    let mut pipeline = Pipeline::new(
        "q-wsm",
        NarrowBasin {
            inner: Plain::new(IcpParams::default(), WsmParams::default()),
            wrong: 12..=14,
        },
        QuadTree::default(),
        Policy::Boosted(Relevance::default()),
        LaserNoise::default(),
    )
    .with_validation(validation, correlative);
    let mut first = None;
    let mut worst = 0.0f64;
    for k in 0..25 {
        let e = pipeline.process(&room_record_at(&jerky(k), k, Pose2::IDENTITY));
        let first = *first.get_or_insert(e.pose);
        worst = worst.max(
            first
                .between(&e.pose)
                .distance(&jerky(0).between(&jerky(k))),
        );
    }
    worst
}

#[test]
fn without_odometry_icp_starts_again_from_the_correlative_search() {
    // Without the start, each wrong match is refused and the constant-velocity prediction
    // stands, 0.2-0.4 m off the jerky drive; with it, ICP started from the search's pose
    // finds the right one. (The check's search is off, so only the start can recover.)
    let without = jerky_without_odometry(false);
    assert!(without > 0.15, "without the start: {without:.3} m");
    let with = jerky_without_odometry(true);
    assert!(with < 0.02, "with the start: {with:.3} m");
}

#[test]
fn the_correlative_start_leaves_a_log_with_odometry_as_it_was() {
    // The room drive, its odometry slipping by 0.3 m and 6° at scan 12: every estimate the
    // same with the start on as off, for each boosted matcher.
    let slip = Pose2::new(0.3, 0.0, 6f64.to_radians());
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc] {
        let run = |start: bool| {
            let mut config = MatcherConfig::defaults(kind);
            config.correlative.start_without_odometry = start;
            let mut odometry = config.build().expect("builds");
            (0..30)
                .map(|k| {
                    let e = odometry.process(&record(k, slipping_odometry(k, 12, slip)));
                    (e.pose, e.inserted, e.check.withheld)
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(true), run(false), "{kind}");
    }
}

/// Twelve posts on a ring of 3 m about the origin, one every 30°: turned by 30° about the
/// centre, a scan from there lands on the posts again, point for point.
fn ring_of_posts() -> SyntheticWorld {
    SyntheticWorld {
        walls: Vec::new(),
        posts: (0..12)
            .map(|k| {
                let a = f64::from(k) * 30f64.to_radians();
                (3.0 * a.cos(), 3.0 * a.sin(), 0.1)
            })
            .collect(),
    }
}

/// Turning in place at the ring's centre, 2° a scan.
fn spinning(k: usize) -> Pose2 {
    Pose2::new(0.0, 0.0, (2.0 * k as f64).to_radians())
}

/// Turned by one post of the ring: every point still lies on a post.
fn one_post_on(p: &Pose2) -> Pose2 {
    *p * Pose2::new(0.0, 0.0, 30f64.to_radians())
}

/// Runs the sabotaged q-wsm (its 12th call turned by one post) through 20 scans at the ring's
/// centre, with odometry that slips by 4° at scan 11, and returns the heading errors (deg).
fn ring_heading_errors(point_evidence: f64) -> Vec<f64> {
    let world = ring_of_posts();
    let gate = ValidationParams {
        search: false,
        point_evidence,
        ..ValidationParams::default()
    };
    let mut pipeline = sabotaged_with(12, one_post_on, gate);
    let slip = Pose2::new(0.0, 0.0, 4f64.to_radians());
    (0..20)
        .map(|k| {
            let mut scan = world.scan(&spinning(k), 0.005, k as u64 + 1);
            scan.timestamp = k as f64;
            let odometry = if k < 11 {
                spinning(k)
            } else {
                spinning(k) * slip
            };
            let e = pipeline.process(&Record {
                scan,
                odometry,
                truth: Some(spinning(k)),
                laser_offset: Pose2::IDENTITY,
            });
            if k == 11 {
                assert!(e.check.withheld && !e.inserted, "{e:?}");
            }
            qicp_core::normalize_angle(e.pose.theta - spinning(k).theta)
                .abs()
                .to_degrees()
        })
        .collect()
}

#[test]
fn a_turn_odometry_never_made_is_not_followed_on_a_few_points_more() {
    // At scan 11 odometry is 4° off, too far for the posts 3 m away to explain its
    // prediction, while the match turned by one post explains every point: a few points
    // against a turn of 26° that odometry's σ of about 1° rules out.
    let weighed = ring_heading_errors(ValidationParams::default().point_evidence);
    // The prediction stands at scan 11 (4° off), and the matches from it turn back to within
    // about 1° (the sparse posts against odometry's prior, still centred 4° off).
    assert!((weighed[11] - 4.0).abs() < 0.5, "{weighed:.2?}");
    for (k, deg) in weighed.iter().enumerate().skip(12) {
        assert!(*deg < 1.5, "scan {k}: {deg:.2}° off: {weighed:.2?}");
    }
    // Where any point more decides (the fall-back's earlier test), the turn is followed and
    // the drive stays one post off for good.
    let any_point = ring_heading_errors(1e9);
    for (k, deg) in any_point.iter().enumerate().skip(11) {
        assert!(
            (deg - 30.0).abs() < 1.5,
            "scan {k}: {deg:.2}°: {any_point:.2?}"
        );
    }
}

/// A scan too sparse to be matched at all (fewer valid beams than `min_correspondences`) once
/// replaced a scan-to-scan reference, so that the next full scan found nothing to pair with
/// and fell back to odometry too.
#[test]
fn a_scan_too_sparse_to_match_does_not_replace_the_scan_to_scan_reference() {
    for kind in [MatcherKind::Idc, MatcherKind::Wsm] {
        let mut pipeline = MatcherConfig::defaults(kind).build().expect("builds");
        for k in 0..8 {
            let mut r = record(k, truth(k));
            if k == 5 {
                // Five returns left of 181: the rest read nothing.
                let ranges: Vec<f64> = r
                    .scan
                    .ranges()
                    .iter()
                    .enumerate()
                    .map(|(i, &range)| if i % 45 == 0 { range } else { f64::NAN })
                    .collect();
                r.scan = Scan::new(r.scan.timestamp, r.scan.geometry, ranges).expect("valid");
                assert!(r.scan.valid_count() < 12, "{}", r.scan.valid_count());
            }
            let e = pipeline.process(&r);
            if k == 5 {
                assert!(
                    matches!(e.result.fallback, Some(Fallback::TooFewPoints { .. })),
                    "{kind:?}: {e:?}"
                );
                assert!(!e.inserted, "{kind:?}");
            } else if k > 0 {
                assert_eq!(e.result.fallback, None, "{kind:?} scan {k}");
                let (d, g) = error(&e.pose, k);
                assert!(d < 0.05 && g < 0.5, "{kind:?} scan {k}: {d} m, {g}°");
            }
        }
    }
}

/// The robot's pose at scan `k` of a brisk drive through the room: 0.2 m and 4° a scan.
fn brisk(k: usize) -> Pose2 {
    Pose2::new(-3.0 + 0.2 * k as f64, -1.0, (4.0 * k as f64).to_radians())
}

/// WSM as `policy` says, with `motion`, through 25 records of the brisk drive, its odometry
/// reading `reading(k)` at scan `k`. For each record: the prior of the matcher's first call,
/// and the estimate's error (m) against the truth's motion since scan 0.
fn brisk_drive(
    policy: Policy,
    motion: MotionModel,
    reading: impl Fn(usize) -> Pose2,
) -> Vec<(Option<Matrix3<f64>>, f64)> {
    let priors = Priors::default();
    let mut pipeline = Pipeline::new(
        "recording",
        Sabotaged {
            inner: Plain::new(IcpParams::default(), WsmParams::default()),
            calls: 0,
            at: 0,
            until: 0,
            wrong: turned,
            priors: priors.clone(),
        },
        QuadTree::default(),
        policy,
        LaserNoise::default(),
    )
    .with_motion_model(motion);
    let mut first = None;
    (0..25)
        .map(|k| {
            let calls = priors.lock().expect("not poisoned").len();
            let e = pipeline.process(&room_record_at(&brisk(k), k, reading(k)));
            let first = *first.get_or_insert(e.pose);
            let error = first
                .between(&e.pose)
                .distance(&brisk(0).between(&brisk(k)));
            (priors.lock().expect("not poisoned")[calls], error)
        })
        .collect()
}

fn close_information(a: &Matrix3<f64>, b: &Matrix3<f64>) -> bool {
    (0..3).all(|i| (a[(i, i)] - b[(i, i)]).abs() <= 0.05 * b[(i, i)])
}

#[test]
fn without_odometry_a_map_weighs_the_velocity_prediction_as_a_looser_prior() {
    let motion = MotionModel::default();
    let step = brisk(0).between(&brisk(1));
    let stall = motion.stall_information(&step).expect("a stall prior");
    let k = motion.stall_prior_sigmas;
    assert!(close_information(
        &(motion.information(&step).expect("a prior") / (k * k)),
        &stall
    ));
    // No odometry: every record reads the same pose. Scan 1 contradicts it (0.2 m and 4°
    // against a robot standing still, χ² 32), and from the first checked match on the records
    // are predicted at its velocity, and weighed by it.
    let none = |_| Pose2::IDENTITY;
    let map = brisk_drive(Policy::Boosted(Relevance::default()), motion, none);
    for (scan, (prior, error)) in map.iter().enumerate().skip(12) {
        let prior = prior.unwrap_or_else(|| panic!("scan {scan}: no prior"));
        assert!(
            close_information(&prior, &stall),
            "scan {scan}: {prior} against {stall}"
        );
        // It vetoes nothing: the drive is followed.
        assert!(*error < 0.03, "scan {scan}: {error:.3} m off");
    }
    // No prior scan to scan, nor with `stall_prior_sigmas = 0`, nor where a log's odometry
    // stalls (reading the truth up to scan 9, then repeating it: a burst of records with one
    // reading, whose velocity is no such prediction); each drive is followed as well.
    let off = MotionModel {
        stall_prior_sigmas: 0.0,
        ..motion
    };
    let stalls = |k: usize| brisk(k.min(9));
    for (name, drive) in [
        (
            "scan to scan",
            brisk_drive(Policy::Incremental(Relevance::default()), motion, none),
        ),
        (
            "prior off",
            brisk_drive(Policy::Boosted(Relevance::default()), off, none),
        ),
        (
            "odometry that stalls",
            brisk_drive(Policy::Boosted(Relevance::default()), motion, stalls),
        ),
    ] {
        for (scan, (prior, error)) in drive.iter().enumerate().skip(12) {
            assert!(prior.is_none(), "{name}, scan {scan}: {prior:?}");
            assert!(*error < 0.03, "{name}, scan {scan}: {error:.3} m off");
        }
    }
}

/// Scan `k` of a robot in the corridor, facing its end wall from 4 m before it: standing for
/// 15 scans, then backing at 0.3 m a scan.
fn backing(k: usize) -> Pose2 {
    Pose2::new(8.0 - 0.3 * k.saturating_sub(15) as f64, 0.1, 0.0)
}

#[test]
fn new_ground_outside_what_the_map_saw_does_not_lower_the_share() {
    let world = SyntheticWorld::corridor();
    let seen_from = backing(0);
    let mut reference = Reference::new(QuadTree::default());
    let first = world.scan(&seen_from, 0.005, 1);
    reference
        .insert_scan(&first, &seen_from, Some(Merge::spacing(0.01)))
        .expect("finite");
    let view = FieldOfView::of(&first, seen_from);
    let validator = Validator::new(ValidationParams::default());
    // 2.1 m back, about two thirds of the scan's beams fall on wall beside the robot, behind
    // where the first scan looked.
    let now = backing(22);
    let scan = world.scan(&now, 0.005, 2);
    let local = scan.points();
    let every = validator.inlier_share(&reference, local, &now);
    let seen = validator.seen_share(&reference, local, &now, Some(&view));
    assert!(every < 0.5, "every point: {every:.2}");
    assert!(seen > 0.95, "the points the map could have seen: {seen:.2}");
    // A wrong match still moves points off the surfaces the map holds within the view.
    for wrong in [
        now * Pose2::new(0.0, 0.0, 8f64.to_radians()),
        now * Pose2::new(0.0, 0.4, 0.0),
    ] {
        let share = validator.seen_share(&reference, local, &wrong, Some(&view));
        assert!(share < 0.6, "{wrong:?}: {share:.2}");
    }
}

/// The share the check computes from a placement, looked up once for the check and the hold,
/// against its brute-force twin: every point's surface distance looked up on its own.
#[test]
fn a_placement_gives_the_share_and_weak_direction_of_its_own_look_ups_at_any_reach() {
    let world = SyntheticWorld::corridor();
    let mut reference = Reference::new(QuadTree::default());
    for k in 0..4 {
        let pose = backing(20 + 3 * k);
        let scan = world.scan(&pose, 0.005, k as u64);
        reference
            .insert_scan(&scan, &pose, Some(Merge::spacing(0.01)))
            .expect("finite");
    }
    let validator = Validator::new(ValidationParams::default());
    let d = validator.params.inlier_distance;
    let mut rng = SplitMix::new(62);
    let (mut judged, mut shares) = (0, Vec::new());
    for trial in 0..40 {
        let truth = backing(20 + (trial % 12));
        let pose = truth
            * Pose2::new(
                rng.range(-0.15, 0.15),
                rng.range(-0.15, 0.15),
                rng.range(-0.1, 0.1),
            );
        let scan = world.scan(&truth, 0.005, 100 + trial as u64);
        let local = scan.points();
        let view = FieldOfView::of(&scan, backing(20));
        for view in [None, Some(&view)] {
            let (mut explained, mut seen) = (0usize, 0usize);
            for q in local {
                let p = pose.transform_point(q);
                let surface = reference.surface_distance_sq(&p, 4.0 * d * d);
                if surface.is_none() && view.is_some_and(|v| !v.contains(&p)) {
                    continue;
                }
                seen += 1;
                explained += usize::from(surface.is_some_and(|e| e.sqrt() <= d));
            }
            let twin = if seen == 0 {
                0.0
            } else {
                explained as f64 / seen as f64
            };
            assert_eq!(validator.seen_share(&reference, local, &pose, view), twin);
            shares.push(twin);
            for reach in [0.5 * d, 2.0 * d, 10.0 * d] {
                let placed = Placed::new(&reference, local, &pose, reach);
                let share = validator.placed_share(&reference, &placed, view);
                assert_eq!(share, twin, "trial {trial}, reach {reach}");
            }
        }
        // The hold reads the look-ups within the inlier distance, whatever the placement's
        // reach beyond it.
        let own = Placed::new(&reference, local, &pose, d);
        let wide = Placed::new(&reference, local, &pose, 2.0 * d);
        let weak = weak_direction(&reference, &own, d);
        assert_eq!(weak, weak_direction(&reference, &wide, d), "trial {trial}");
        judged += usize::from(weak.is_some());
    }
    // The poses tried range from a match to a poor one, and most are judged.
    shares.sort_by(f64::total_cmp);
    assert!(
        shares[0] < 0.5 && shares[shares.len() - 1] > 0.9,
        "{shares:?}"
    );
    assert!(judged > 20, "{judged} of 40 judged");
}

/// Drives `backing` for `scans` scans with odometry read true, the checks at a level
/// `max_share_drop` below the median: the worst position error (m) and the refusals.
fn backing_run(skip_unseen: bool, scans: usize) -> (f64, usize) {
    let mut config = MatcherConfig::defaults(MatcherKind::QWsm);
    config.validation.max_share_drop = 0.1;
    config.validation.skip_unseen = skip_unseen;
    let mut pipeline = config.build().expect("builds");
    let world = SyntheticWorld::corridor();
    let (mut worst, mut refused) = (0.0f64, 0);
    for k in 0..scans {
        let mut scan = world.scan(&backing(k), 0.005, k as u64 + 1);
        scan.timestamp = k as f64;
        let e = pipeline.process(&Record {
            scan,
            odometry: backing(k),
            truth: Some(backing(k)),
            laser_offset: Pose2::IDENTITY,
        });
        refused += usize::from(e.check.refused);
        worst = worst.max(e.pose.distance(&backing(k)));
    }
    (worst, refused)
}

#[test]
fn backing_along_a_corridor_is_not_refused_for_the_wall_it_had_not_seen() {
    // Each step back shows 0.3 m of new wall on either side, where the map has none and the
    // last inserted scan did not look: counted, it drops the share below a level set while
    // the robot stood, and right matches are refused (kept out of the map, and searched
    // again: on Intel played backwards the search then slid them back onto the mapped walls).
    let (off, refused_off) = backing_run(false, 40);
    let (on, refused_on) = backing_run(true, 40);
    assert_eq!(refused_on, 0, "{on:.3} m");
    assert!(on < 0.02, "{on:.3} m");
    assert!(
        refused_off >= 3,
        "counting every point: {refused_off} refused, {off:.3} m"
    );
}

/// `kind`'s defaults, with a residual level of 1.2 times the running median, over 30 scans of
/// the posts whose odometry turns 20° too far at scan 15, where every third return lies 9 cm
/// beyond its post (the scan fits with a larger residual than the running level, each point
/// still within the check's inlier distance): the heading error (deg) at scan 15, and whether
/// its match was recovered by the search.
fn slip_onto_a_scan_that_fits_loosely(kind: MatcherKind) -> (f64, bool) {
    let world = SyntheticWorld::posts();
    let mut config = MatcherConfig::defaults(kind);
    config.validation.max_residual_ratio = 1.2;
    let mut pipeline = config.build().expect("builds");
    let slip = Pose2::new(0.0, 0.0, 20f64.to_radians());
    let mut at_slip = (f64::NAN, false);
    for k in 0..30 {
        let mut record = record_in(&world, k, slipping_odometry(k, 15, slip));
        if k == 15 {
            let mut ranges = record.scan.ranges().to_vec();
            for r in ranges.iter_mut().step_by(3) {
                *r += 0.09;
            }
            record.scan = Scan::new(record.scan.timestamp, record.scan.geometry, ranges)
                .expect("a valid scan");
        }
        let e = pipeline.process(&record);
        if k == 15 {
            at_slip = (error(&e.pose, k).1, e.check.recovered);
        }
    }
    at_slip
}

#[test]
fn a_refused_match_is_replaced_by_a_recovery_whose_only_fault_is_its_residual() {
    // On the MIT CSAIL log odometry caught up after a stall 16° beyond the turn the scans
    // saw; q-wsm's match from there explained 0.19 of the scan and was refused, and the
    // search's re-match explained 0.99 of it, but with a residual of about twice the running
    // median (a fast turn skews the scan). A residual above the level makes a match suspect,
    // never refused; the re-match was thrown away for it all the same, and the record kept
    // the prediction, 16° off. Here every matcher kept the prediction, 20° off, before the
    // rule.
    for kind in BOOSTED_AND_PLAIN {
        let (off, recovered) = slip_onto_a_scan_that_fits_loosely(kind);
        assert!(
            recovered,
            "{kind}: the search's re-match must replace the refused match"
        );
        assert!(off < 1.0, "{kind}: heading {off:.2}° off at the slip");
    }
}
