//! The whole Intel Research Lab log through the matchers, scored with the Freiburg benchmark
//! relations. Reads `../shared/data/intel/` (never copied into the project).
//!
//! Measured (mean translational error, records in file order): q-wsm 0.020 m, q-idc 0.017 m,
//! wsm 0.48 m, idc 0.18 m, raw odometry 7.37 m; published: scan matching 0.220 m, RBPF SLAM
//! 0.070 m, graph SLAM 0.031 m.

use qicp::eval::evaluate_relations;
use qicp::logs::carmen::{CarmenOptions, read_carmen};
use qicp::logs::relations::read_relations;
use qicp::matching::run_matcher;
use qicp_matchers::{MatcherConfig, MatcherKind};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn data(name: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/intel")).join(name)
}

/// Mean translational and rotational (deg) relation error of `kind` with its defaults.
fn score(kind: MatcherKind) -> (f64, f64, usize, BTreeMap<String, usize>) {
    score_config(&MatcherConfig::defaults(kind))
}

/// The same for any config.
fn score_config(config: &MatcherConfig) -> (f64, f64, usize, BTreeMap<String, usize>) {
    let kind = config.kind();
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let relations = read_relations(&data("intel.relations")).expect("relations");
    let run = run_matcher(&log.records, config, false).expect("run");
    assert_eq!(run.trajectory.len(), 13_631);
    let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
    assert_eq!(report.missing, 0);
    println!("{kind}: {report:?} ({} fallbacks)", run.summary.fallbacks);
    (
        report.trans_mean,
        report.rot_mean_deg,
        run.summary.fallbacks,
        run.summary.fallback_reasons,
    )
}

#[test]
fn q_wsm_on_intel_beats_rbpf_slam() {
    let (trans, rot, fallbacks, reasons) = score(MatcherKind::QWsm);
    // RBPF SLAM scores 0.070 m, graph SLAM 0.031 m; boosted scan matching alone scores
    // 0.027 m and must stay below 0.05 m.
    assert!(trans < 0.05, "q-wsm mean translational error {trans:.4} m");
    assert!(rot < 1.0, "q-wsm mean rotational error {rot:.3}°");
    // Besides the first scan, only matches the validation refused, and those odometry's
    // veto withheld that the scan did not weigh up (6 of 13,631 in all), keep the
    // prediction.
    let refused = reasons.get("refused").copied().unwrap_or(0);
    assert!(
        fallbacks - refused <= 1,
        "only the first scan has nothing to match"
    );
    assert!(refused <= 10, "{refused} matches refused");
}

/// With `rho_max_deg` at 3.5° (the sweep's `relevance.rho_max_deg*0.7`) q-wsm re-anchored
/// 1 m off at 2,372 s, on a match of 51 pairs where recent matches held about 140, and scored
/// 0.148 m. A re-anchored match now passes the check every match passes. The case was found
/// with every relevant scan entering the map (`min_novelty = 0`), and is kept so.
#[test]
fn a_reanchoring_on_a_fraction_of_the_usual_pairs_is_not_taken() {
    let config = MatcherConfig::from_toml(
        "[matcher]\nkind = \"q-wsm\"\n[matcher.relevance]\nrho_max_deg = 3.5\nmin_novelty = 0\n",
    )
    .expect("a valid config");
    let (trans, _, _, _) = score_config(&config);
    assert!(trans < 0.05, "q-wsm mean translational error {trans:.4} m");
}

/// Intel's first loop drifts by some 0.3-0.45 m before the robot comes back to its start,
/// where a re-anchoring (record 1,835 for q-wsm; 1,865 before its novelty gate) corrects it. As a jump, it left relations
/// across it off by the jump (largest 0.43 m for q-wsm, 0.33 m for q-idc within the first
/// 2,500 records); spread over the loop, with the map laid on it (`deform`), the largest is
/// 0.09 and 0.05 m.
#[test]
fn a_reanchoring_spread_over_the_first_loop_leaves_no_relation_off_by_its_jump() {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let relations = read_relations(&data("intel.relations")).expect("relations");
    let records = &log.records[..2_500];
    for kind in ["q-wsm", "q-idc"] {
        let largest = |deform: bool| {
            let config = MatcherConfig::from_toml(&format!(
                "[matcher]\nkind = \"{kind}\"\nrevisit = {{ deform = {deform} }}\n"
            ))
            .expect("a valid config");
            let run = run_matcher(records, &config, false).expect("run");
            assert_eq!(run.summary.reanchored, 1, "{kind}, deform {deform}");
            let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
            assert_eq!(report.n, 401);
            report.trans_max
        };
        let (jump, spread) = (largest(false), largest(true));
        assert!(jump > 0.3, "{kind}: {jump:.3} m, the jump");
        assert!(spread < 0.15, "{kind}: {spread:.3} m spread over the loop");
    }
}

/// Intel played backwards, as `python/benchmarks/derived_logs.py reverse` writes it: the
/// records in reverse order, each stamp t mapped to t_first + t_last − t, and the relations'
/// stamps mapped the same way (their values kept).
fn played_backwards() -> (Vec<qicp_core::Record>, Vec<qicp::logs::relations::Relation>) {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let mut records = log.records;
    let stamps = records.iter().map(qicp_core::Record::timestamp);
    let (first, last) = stamps.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
        (lo.min(t), hi.max(t))
    });
    records.reverse();
    for r in &mut records {
        r.scan.timestamp = first + last - r.scan.timestamp;
    }
    let mut relations = read_relations(&data("intel.relations")).expect("relations");
    for rel in &mut relations {
        rel.t1 = first + last - rel.t1;
        rel.t2 = first + last - rel.t2;
    }
    (records, relations)
}

/// A pose reflected across the x axis: (x, y, θ) → (x, −y, −θ).
fn reflected(p: &qicp_core::Pose2) -> qicp_core::Pose2 {
    qicp_core::Pose2::new(p.x, -p.y, -p.theta)
}

/// Intel reflected across the x axis of its odometry frame, as `python/benchmarks/
/// derived_logs.py mirror` writes it: every scan read right to left (its beams reversed and
/// laid at the negated bearings), every pose and relation (x, y, θ) as (x, −y, −θ).
fn mirrored() -> (Vec<qicp_core::Record>, Vec<qicp::logs::relations::Relation>) {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let records = log
        .records
        .into_iter()
        .map(|mut r| {
            let g = r.scan.geometry;
            let last = g.angle(r.scan.beams() - 1);
            let geometry = qicp_core::BeamGeometry {
                angle_min: -last,
                ..g
            };
            let ranges = r.scan.ranges().iter().rev().copied().collect();
            r.scan = qicp_core::Scan::new(r.scan.timestamp, geometry, ranges).expect("a scan");
            r.odometry = reflected(&r.odometry);
            r.laser_offset = reflected(&r.laser_offset);
            r
        })
        .collect();
    let mut relations = read_relations(&data("intel.relations")).expect("relations");
    for rel in &mut relations {
        rel.delta = reflected(&rel.delta);
    }
    (records, relations)
}

/// Intel with its laser mounted off the robot's origin, as most robots carry one: the scans
/// as logged, each record's odometry the robot's pose (the logged pose, which is the laser's,
/// composed with the inverse of `mount`), `laser_offset` the mount, and every relation
/// conjugated by it (inv(P1·M⁻¹)·P2·M⁻¹ = M·R·M⁻¹). The laser sees and moves as logged.
fn mounted(
    records: &[qicp_core::Record],
    mount: qicp_core::Pose2,
) -> (Vec<qicp_core::Record>, Vec<qicp::logs::relations::Relation>) {
    let unmount = mount.inverse();
    let records = records
        .iter()
        .map(|r| {
            let mut r = r.clone();
            r.odometry = r.odometry * unmount;
            r.laser_offset = mount;
            r
        })
        .collect();
    let mut relations = read_relations(&data("intel.relations")).expect("relations");
    for rel in &mut relations {
        rel.delta = mount * rel.delta * unmount;
    }
    (records, relations)
}

/// A laser 0.3 m ahead of the robot's origin, 0.1 m to its left and turned by 3°: the
/// odometry reads the robot's motion, which the pipeline turns into the laser's through the
/// mount (the clinic log's laser sits 0.22 m ahead; Intel's and MIT CSAIL's at the origin).
/// Each matcher must place the laser where it does with the laser at the origin, and score
/// the same on the relations, which now hold the robot's motion (the mount turns the errors
/// too: q-wsm 0.0194 → 0.0199 m, wsm 0.2990 → 0.3006 m). A mount applied wrongly predicts
/// every turn's laser motion wrong by the mount's swing, and odometry's veto then holds right
/// matches at the wrong prediction: with its forward offset lost q-wsm scores 0.0428 m here,
/// with the mount inverted 0.0946 m. Only rounding tells the runs apart: q-wsm's and wsm's
/// laser poses agree to 1e-14 m; q-idc's first part at record 160, by 0.14 mm where they had
/// agreed to 1e-16 m (a last-bit change of the prediction flips one of its discrete
/// decisions), and a map laid a little differently then leaves them 4 cm apart at the median
/// (0.0170 and 0.0184 m), the matcher's spread under any change.
#[test]
fn a_laser_mounted_off_the_robots_origin_is_placed_as_at_the_origin() {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let records = &log.records[..3_000];
    let at_origin = read_relations(&data("intel.relations")).expect("relations");
    let mount = qicp_core::Pose2::new(0.3, 0.1, 3f64.to_radians());
    let (mounted_records, mounted_relations) = mounted(records, mount);
    for kind in [MatcherKind::QWsm, MatcherKind::QIdc, MatcherKind::Wsm] {
        let config = MatcherConfig::defaults(kind);
        let a = run_matcher(records, &config, false).expect("run");
        let b = run_matcher(&mounted_records, &config, false).expect("run");
        // Where each run puts the laser: the robot's pose composed with its mount.
        let apart = a
            .trajectory
            .iter()
            .zip(&b.trajectory)
            .map(|(p, q)| p.1.distance(&(q.1 * mount)))
            .fold(0.0, f64::max);
        let score = |run: &qicp::matching::MatchRun, relations| {
            let report = evaluate_relations(&run.trajectory, relations, 0.1).expect("relations");
            assert_eq!(report.n, 541, "{kind}");
            report.trans_mean
        };
        let (origin, off) = (score(&a, &at_origin), score(&b, &mounted_relations));
        println!(
            "{kind}: laser poses at most {apart:.2e} m apart; {origin:.4} m, mounted {off:.4} m"
        );
        // WSM's matches settle at the same pose from starts a last bit apart; IDC's runs part
        // (see above).
        if kind != MatcherKind::QIdc {
            assert!(apart < 1e-6, "{kind}: laser poses {apart:.2e} m apart");
        }
        assert!(
            (origin - off).abs() < 0.003,
            "{kind}: {origin:.4} m, mounted {off:.4} m"
        );
    }
}

/// A 50 m laser's `FLASER` lines with no `PARAM robot_front_laser_max` are read with the
/// default 81 m, and where the laser writes its no-returns as 50 m, every beam that found
/// nothing leaves a phantom point on a circle that moves with the robot and pulls each match
/// towards standing still. Intel's first 3,000 records with every no-return written as 50 m,
/// in a log that does not say its maximum range: read by path, the head of the log is probed,
/// the code found and read as no-returns, and q-wsm scores as on Intel (0.0194 m); read with
/// 81 m given, every beam that found nothing (about 3 % of Intel's readings) is a phantom, and
/// q-wsm scores 1.70 m (3.36 m on the whole log).
#[test]
fn a_no_return_code_below_a_guessed_range_is_read_as_no_returns() {
    use qicp::logs::carmen::write_carmen;
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let relations = read_relations(&data("intel.relations")).expect("relations");
    let records = &log.records[..3_000];
    let coded: Vec<qicp_core::Record> = records
        .iter()
        .map(|r| {
            let ranges = r
                .scan
                .ranges()
                .iter()
                .zip(r.scan.status())
                .map(|(&range, status)| match status {
                    qicp_core::BeamStatus::MaxRange => 50.0,
                    _ => range,
                })
                .collect();
            let mut r = r.clone();
            r.scan =
                qicp_core::Scan::new(r.scan.timestamp, r.scan.geometry, ranges).expect("a scan");
            r
        })
        .collect();
    // Written as a log that does not say its maximum range.
    let mut text = Vec::new();
    write_carmen(&mut text, &coded).expect("the log written");
    let text: String = String::from_utf8(text)
        .expect("text")
        .lines()
        .filter(|l| !l.starts_with("PARAM robot_front_laser_max"))
        .map(|l| format!("{l}\n"))
        .collect();
    let dir = tempfile::tempdir().expect("a scratch directory");
    let path = dir.path().join("coded.clf");
    std::fs::write(&path, text).expect("the log written");
    let score = |records: &[qicp_core::Record]| {
        let config = MatcherConfig::defaults(MatcherKind::QWsm);
        let run = run_matcher(records, &config, false).expect("run");
        let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
        report.trans_mean
    };
    let probed = read_carmen(&path, &CarmenOptions::default()).expect("the coded log");
    let code = probed.info.no_return_code.expect("a code found");
    assert!((code.range - 50.0).abs() < 1e-9, "{code:?}");
    let declared = CarmenOptions {
        max_range: Some(81.0),
        ..CarmenOptions::default()
    };
    let phantoms = read_carmen(&path, &declared).expect("the coded log");
    let (intel, read, kept) = (
        score(records),
        score(&probed.records),
        score(&phantoms.records),
    );
    println!("Intel {intel:.4} m; coded, probed {read:.4} m; coded, read as points {kept:.4} m");
    assert!(
        (read - intel).abs() < 1e-3,
        "{read:.4} m against {intel:.4} m"
    );
    assert!(
        kept > 0.5,
        "{kept:.4} m: the phantoms should have held the matches"
    );
}

/// Mirrored, q-plicp comes back to the start of its first loop (record 1,846) by matches
/// that creep onto the old map, each within the look-ups' gain of the last, so no look-up
/// re-anchors: odometry's veto held some of them at the prediction, and a later one followed
/// the scan's points against the veto. Left there, the stretch since the robot left old
/// ground kept its drift, and relations across it were off by up to 0.57 m (22 above 0.5 m
/// in the whole log as the Python script mirrors it). The followed match's correction is now
/// spread over that stretch as a re-anchoring's is. Over the first 2,500 records as mirrored
/// here (401 relations): largest error 0.48 m left, 0.27 m spread (means 0.0190 and
/// 0.0184 m).
#[test]
fn a_loop_closed_by_the_ordinary_match_is_spread_over_the_stretch_that_drifted() {
    let (mut records, relations) = mirrored();
    records.truncate(2_500);
    let largest = |deform_followed: bool| {
        let config = qicp::registry()
            .parse(&format!(
                "[matcher]\nkind = \"q-plicp\"\nrevisit = {{ deform_followed = {deform_followed} }}\n"
            ))
            .expect("a valid config");
        let run = run_matcher(&records, &config, false).expect("run");
        let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
        println!("deform_followed {deform_followed}: {report:?}");
        (report.trans_max, report.trans_mean)
    };
    let (left, spread) = (largest(false), largest(true));
    assert!(left.0 > 0.4, "{left:?}: the creep left the drift in");
    assert!(
        spread.0 < 0.35 && spread.1 < left.1,
        "{spread:?} spread, {left:?} left"
    );
}

/// Played backwards, q-plicp with `min_gain` 0.14 (the sweep's `revisit.min_gain*0.7`)
/// re-anchors after long runs back on old ground. Spread over each whole run (142 records at
/// record 3,738; 929 at 10,953, by 2°), the corrections bent stretches the old map had
/// vouched for, and relations across them came out off by up to 0.7 m: 0.063 m mean, 47
/// above 0.5 m, against 0.026 m as jumps. The spread now starts after the last match the old
/// map explained nearly whole and pinned: 0.024 m.
#[test]
fn a_drift_on_old_ground_is_not_spread_over_the_matches_the_old_map_vouched_for() {
    let (records, relations) = played_backwards();
    let config = qicp::registry()
        .parse("[matcher]\nkind = \"q-plicp\"\nrevisit = { min_gain = 0.14 }\n")
        .expect("a valid config");
    let run = run_matcher(&records, &config, false).expect("run");
    let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
    assert_eq!(report.missing, 0);
    println!("{report:?}");
    assert!(report.trans_mean < 0.04, "{:.4} m", report.trans_mean);
}

/// With returns beyond 10 m dropped (the sweep's `max-range-10`), q-wsm re-anchors by 0.5 m
/// at record 3,144, after 1,342 records back on old ground. The old map had explained the
/// match of record 3,129 nearly whole, but it does not pin it: a pose 0.1 m beside it
/// explains the scan nearly as well, as along a corridor. Spread from that match, the
/// correction bent 14 records and the map they laid: 0.0467 m, 65 relations above 0.5 m,
/// against 0.0315 m as a jump. A match the old map does not pin vouches for nothing. The
/// case was found with every relevant scan entering the map (`min_novelty = 0`, q-wsm's
/// default then) and before matches held odometry along a corridor they do not pin
/// (`hold_unobserved`), and is kept so. (With the hold this configuration scores 0.034 m,
/// 90 matches held.)
#[test]
fn a_match_the_old_map_does_not_pin_along_a_corridor_does_not_start_a_spread() {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let relations = read_relations(&data("intel.relations")).expect("relations");
    let records: Vec<_> = log
        .records
        .into_iter()
        .map(|mut r| {
            r.scan = qicp::sweep::capped_range(&r.scan, 10.0).expect("a valid range");
            r
        })
        .collect();
    let mut config = MatcherConfig::defaults(MatcherKind::QWsm);
    config.relevance.min_novelty = Some(0.0);
    config.motion.hold_unobserved = false;
    let run = run_matcher(&records, &config, false).expect("run");
    let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
    println!("{report:?}");
    assert!(report.trans_mean < 0.04, "{:.4} m", report.trans_mean);
}

#[test]
fn wsm_on_intel_beats_a_c_scan_matcher() {
    let (trans, _, _, _) = score(MatcherKind::Wsm);
    // CSM (point-to-line ICP, scan-to-scan, defaults) scores 0.82 m on this log.
    assert!(trans < 0.82, "wsm mean translational error {trans:.4} m");
}

/// Scan to scan, IDC meets the robustness issue's 0.30 m with the records in the order the
/// laser took them (0.183 m); sorted by their jittered timestamps it scored 0.440 m.
#[test]
fn idc_scan_to_scan_on_intel_in_file_order_stays_under_0_3_m() {
    let (trans, rot, _, _) = score(MatcherKind::Idc);
    assert!(trans < 0.30, "idc mean translational error {trans:.4} m");
    assert!(rot < 1.5, "idc mean rotational error {rot:.3}°");
}

/// Against a map, IDC can end a wide stage once its step turns less than two standard errors
/// of the range rule's rotation (`[matcher.idc] stage_sigmas = 2`; off by default, as Intel's
/// whole run scores worse with it, docs/robustness.md): the turns below that are pairs
/// switching between the map's overlapping samples. On Intel's first 3,000 records q-idc
/// then runs fewer iterations than iterating each wide stage until its step is a fiftieth of
/// the window (the default), and scores within a few millimetres of it. Measured:
/// 22,861 iterations against 27,907 (0.82), 541 relations at 0.0181 against 0.0170 m mean,
/// largest 0.085 against 0.060 m.
#[test]
fn q_idc_ending_a_wide_stage_within_the_range_rules_noise_runs_fewer_iterations() {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let relations = read_relations(&data("intel.relations")).expect("relations");
    let records = &log.records[..3_000];
    let run = |sigmas: f64| {
        let config = MatcherConfig::from_toml(&format!(
            "[matcher]\nkind = \"q-idc\"\nidc = {{ stage_sigmas = {sigmas:?} }}\n"
        ))
        .expect("a valid config");
        let run = run_matcher(records, &config, false).expect("run");
        let iterations: u32 = run.rows.iter().map(|r| r.iterations).sum();
        let report = evaluate_relations(&run.trajectory, &relations, 0.1).expect("relations");
        assert_eq!(report.n, 541);
        println!("stage_sigmas {sigmas}: {iterations} iterations, {report:?}");
        (iterations, report.trans_mean, report.trans_max)
    };
    let (within_noise, to_a_fiftieth) = (run(2.0), run(0.0));
    assert!(
        f64::from(within_noise.0) < 0.85 * f64::from(to_a_fiftieth.0),
        "{} iterations against {}",
        within_noise.0,
        to_a_fiftieth.0
    );
    assert!(
        within_noise.1 < to_a_fiftieth.1 + 0.005 && within_noise.2 < 0.2,
        "mean {:.4} m against {:.4} m, largest {:.3} m",
        within_noise.1,
        to_a_fiftieth.1,
        within_noise.2
    );
}

#[test]
fn q_idc_on_intel_beats_rbpf_slam() {
    let (trans, rot, _, _) = score(MatcherKind::QIdc);
    // Scores 0.029 m; parameters near the defaults have given up to 0.71 m (README, Known
    // limits), so the bound is the target rather than a tight one.
    assert!(trans < 0.10, "q-idc mean translational error {trans:.4} m");
    assert!(rot < 1.0, "q-idc mean rotational error {rot:.3}°");
}

/// The map's index is a plug-in: a kd-tree map must give exactly the quad tree's trajectory.
/// The log's ranges are quantized to 1 cm, so equal-range candidates of IDC's range rule are
/// common from the second scan on; the rule's tie-break, not the index's search order, must
/// decide them.
#[test]
fn kd_tree_maps_match_quad_tree_maps_exactly() {
    let log = read_carmen(&data("intel.clf.bz2"), &CarmenOptions::default()).expect("Intel log");
    let records = &log.records[..3_000];
    for (quad, kd) in [
        (MatcherKind::QIdc, MatcherKind::KdIdc),
        (MatcherKind::QWsm, MatcherKind::KdWsm),
    ] {
        let a = run_matcher(records, &MatcherConfig::defaults(quad), false).expect("run");
        let b = run_matcher(records, &MatcherConfig::defaults(kd), false).expect("run");
        assert_eq!(a.trajectory.len(), records.len());
        let first_difference = a
            .trajectory
            .iter()
            .zip(&b.trajectory)
            .position(|(p, q)| p != q);
        assert_eq!(first_difference, None, "{quad} and {kd} part at this scan");
    }
}
