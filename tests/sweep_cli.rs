//! End to end: `qicp sweep` on the first Intel scans reports the default run and every chosen
//! variant with consistent ratios, the same figures whatever `--jobs`, an invalid scaled
//! configuration as an error of its variant, and refuses an unknown variant or a missing
//! relations file before any matching; without relations it scores every variant against the
//! default run. Reads `../shared/data/intel/` (never copied).

mod intel_data;

use intel_data::data;
use std::process::{Command, Output};

fn qicp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(args)
        .output()
        .expect("runs qicp")
}

/// `qicp sweep` on the Intel log with q-wsm, the given extra arguments, JSON parsed.
fn sweep_json(extra: &[&str]) -> (serde_json::Value, String) {
    sweep_kind_json("q-wsm", extra)
}

/// `qicp sweep` on the Intel log with `kind`, the given extra arguments, JSON parsed.
fn sweep_kind_json(kind: &str, extra: &[&str]) -> (serde_json::Value, String) {
    let (log, relations) = (data("intel.clf.bz2"), data("intel.relations"));
    let mut args = vec![
        "sweep",
        &log,
        "--matcher",
        kind,
        "--relations",
        &relations,
        "--json",
    ];
    args.extend_from_slice(extra);
    let o = qicp(&args);
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{stderr}");
    let json = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    (json, stderr)
}

/// A drive of `configs/worlds/<world>` simulated into `sim/` of a scratch directory of its
/// own, `extra` given to `qicp sim`.
fn simulated(world: &str, extra: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::Builder::new()
        .prefix("qicp-sweep-sim-")
        .tempdir()
        .expect("scratch dir");
    let config = format!("{}/configs/worlds/{world}", env!("CARGO_MANIFEST_DIR"));
    let out = dir.path().join("sim").display().to_string();
    let o = qicp(&[&["sim", &config, "--out", &out], extra].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    dir
}

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

const FIGURES: [&str; 9] = [
    "trans_mean",
    "trans_max",
    "rot_mean_deg",
    "ms_per_scan_median",
    "map_points",
    "scans",
    "relations",
    "relations_missing",
    "relations_over_0_5_m",
];

#[test]
fn sweep_reports_the_default_and_each_variant_with_consistent_ratios() {
    let names = ["scans/2", "odom-noise", "icp.max_dist_start*0.7"];
    let (report, stderr) = sweep_json(&["--scans", "3000", "--variants", &names.join(",")]);
    for key in [
        "log",
        "matcher",
        "scans",
        "default",
        "variants",
        "worst_ratio",
        "median_ratio",
        "relations_over_0_5_m",
    ] {
        assert!(report.get(key).is_some(), "report lacks {key}: {report}");
    }
    assert_eq!(report["matcher"], "q-wsm");
    assert_eq!(report["scans"], 3000);
    let default = &report["default"];
    for key in FIGURES {
        assert!(default.get(key).is_some(), "default lacks {key}: {default}");
    }
    let base = f(&default["trans_mean"]);
    assert!(base > 0.0 && base < 0.1, "default trans_mean {base}");
    assert!(default["relations"].as_u64().unwrap_or(0) > 0);
    assert_eq!(default["scans"], 3000);
    assert_eq!(
        report["relations_over_0_5_m"],
        default["relations_over_0_5_m"]
    );

    let variants = report["variants"].as_array().expect("variants");
    let listed: Vec<&str> = variants.iter().filter_map(|v| v["name"].as_str()).collect();
    assert_eq!(listed, names);
    let mut ratios = Vec::new();
    for v in variants {
        assert!(v.get("error").is_none(), "{v}");
        for key in FIGURES.iter().chain(&["name", "ratio"]) {
            assert!(v.get(key).is_some(), "variant lacks {key}: {v}");
        }
        // Against the default's error on the same relations where the variant scored only
        // some (scans/2), against its whole mean otherwise.
        let against = v.get("default_trans_mean").map_or(base, f);
        let ratio = f(&v["ratio"]);
        assert!((ratio - f(&v["trans_mean"]) / against).abs() < 1e-12, "{v}");
        ratios.push(ratio);
        let name = v["name"].as_str().unwrap_or_default();
        assert!(
            stderr.contains(&format!("variant {name} done in")),
            "{stderr}"
        );
    }
    assert_eq!(
        variants[0]["scans"], 1500,
        "scans/2 keeps every second record"
    );
    // scans/2 is scored on the relations between records it kept, at their own times; the
    // others are missing, not scored with the pose of the record beside a dropped one, which
    // charged it for the motion in between (on these 3,000 scans 248 of 541 relations have
    // both ends on kept records, under half).
    let count = |v: &serde_json::Value, key: &str| v[key].as_u64().unwrap_or(0);
    let halved = &variants[0];
    assert_eq!(
        count(halved, "relations") + count(halved, "relations_missing"),
        count(default, "relations") + count(default, "relations_missing")
    );
    assert!(
        2 * count(halved, "relations") < count(default, "relations"),
        "{halved}"
    );
    // Its ratio is taken against the default on those same relations; the other variants,
    // which score all of them, have no such figure.
    let same = f(&halved["default_trans_mean"]);
    assert!(same > 0.0 && same != base, "{halved}");
    assert!(
        variants[1].get("default_trans_mean").is_none(),
        "{}",
        variants[1]
    );
    assert_eq!(
        count(&variants[1], "relations"),
        count(default, "relations")
    );
    ratios.sort_by(f64::total_cmp);
    assert_eq!(f(&report["worst_ratio"]), ratios[2]);
    assert_eq!(f(&report["median_ratio"]), ratios[1]);
    assert!(stderr.contains("variant default done in"), "{stderr}");
}

#[test]
fn sweep_figures_do_not_depend_on_jobs() {
    let args = [
        "--scans",
        "400",
        "--variants",
        "beams/2,odom-bias,range-noise,max-range-10",
    ];
    let strip = |mut report: serde_json::Value| {
        // Wall times are the only figures that vary from run to run.
        report["default"]["ms_per_scan_median"] = serde_json::Value::Null;
        for v in report["variants"].as_array_mut().expect("variants") {
            v["ms_per_scan_median"] = serde_json::Value::Null;
        }
        report
    };
    let one = strip(sweep_json(&[&args[..], &["--jobs", "1"]].concat()).0);
    let three = strip(sweep_json(&[&args[..], &["--jobs", "3"]].concat()).0);
    assert_eq!(one, three);
    assert_eq!(one["variants"].as_array().map(Vec::len), Some(4));
}

#[test]
fn sweep_reports_an_invalid_scaled_config_as_its_variants_error() {
    let dir = std::env::temp_dir().join(format!("qicp-sweep-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let config = dir.join("close-gates.toml");
    std::fs::write(
        &config,
        "[matcher]\nkind = \"q-wsm\"\n[matcher.icp]\nmax_dist_end = 0.8\n",
    )
    .expect("config written");
    let (report, _) = sweep_json(&[
        "--config",
        config.to_str().expect("utf-8 path"),
        "--scans",
        "400",
        "--variants",
        "icp.max_dist_end*1.4,odom-bias",
    ]);
    let variants = report["variants"].as_array().expect("variants");
    assert_eq!(variants.len(), 2);
    let bad = &variants[1];
    assert_eq!(bad["name"], "icp.max_dist_end*1.4");
    let error = bad["error"].as_str().expect("an error");
    assert!(error.contains("max_dist_end"), "{error}");
    assert!(bad["ratio"].is_null(), "{bad}");
    assert!(variants[0]["error"].is_null() && variants[0]["ratio"].is_number());
}

#[test]
fn sweep_refuses_an_unknown_variant_before_reading_the_log() {
    let relations = data("intel.relations");
    let o = qicp(&[
        "sweep",
        "/nonexistent/log.clf",
        "--matcher",
        "q-wsm",
        "--relations",
        &relations,
        "--variants",
        "scans/2,scans/3",
    ]);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("unknown variant scans/3"), "{stderr}");
    assert!(
        stderr.contains("odom-noise") && stderr.contains("icp.max_dist_start*0.7"),
        "the known variants are listed: {stderr}"
    );
}

/// `qicp sweep` of the Intel log with q-wsm and `relations`, which must fail before any
/// matching: its stderr.
fn refused_before_matching(relations: &str, extra: &[&str]) -> String {
    let log = data("intel.clf.bz2");
    let mut args = vec![
        "sweep",
        &log,
        "--matcher",
        "q-wsm",
        "--relations",
        relations,
    ];
    args.extend_from_slice(extra);
    let o = qicp(&args);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!stderr.contains("done in"), "nothing was matched: {stderr}");
    stderr
}

#[test]
fn sweep_refuses_a_missing_relations_file_before_matching() {
    let stderr = refused_before_matching("/nonexistent/intel.relations", &[]);
    assert!(
        stderr.contains("/nonexistent/intel.relations"),
        "names the file: {stderr}"
    );
}

#[test]
fn sweep_refuses_relations_of_another_time_span() {
    let dir = std::env::temp_dir().join(format!("qicp-sweep-cli-rel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let relations = dir.join("elsewhere.relations");
    std::fs::write(&relations, "1.0 2.0 0.1 0 0 0 0 0\n").expect("relations written");
    let stderr =
        refused_before_matching(relations.to_str().expect("utf-8 path"), &["--scans", "100"]);
    assert!(stderr.contains("do they belong to this log"), "{stderr}");
}

/// Issue 12's robustness bounds, on the first 3,000 Intel scans where they hold for these
/// variants (the whole log's sweep is in the README): every variant within
/// max(2 × default, 5 cm), the median ratio at most 1.3. Each list mixes input and parameter
/// variants. `max-range-10` failed for both matchers in every form measured until the
/// matches were re-anchored on revisits (q-wsm 0.134-0.154 m here before, 0.021 m with it).
/// No relation of either default run lies above 0.5 m (q-idc's had one, 0.54 m, across its
/// re-anchoring at 370 s, until its map took a scan only where 5 % of it was new: 0.33 m
/// at most then).
#[test]
fn sweep_bounds_hold_on_the_first_3000_intel_scans() {
    for (kind, names, over_half_metre) in [
        (
            "q-wsm",
            // scans/2 is scored on the relations between the records it keeps (0.171 m in
            // file order before re-anchoring, when it took a dropped record's neighbour).
            "scans/2,beams/2,odom-noise,range-noise,max-range-10,relevance.tau_max*0.7,\
             icp.max_dist_end*0.7,wsm.sigma_slide*0.7",
            0,
        ),
        (
            "q-idc",
            // beams/2 guards IDC's end window against a coarser laser (0.286 m when the
            // window stayed at 1° for 2° between beams).
            "scans/2,beams/2,odom-noise,max-range-10,icp.max_dist_start*0.7,\
             motion.sigma_xy_per_m*0.7,relevance.map_resolution*1.4",
            0,
        ),
    ] {
        let (report, _) = sweep_kind_json(kind, &["--scans", "3000", "--variants", names]);
        let base = f(&report["default"]["trans_mean"]);
        assert!(base < 0.05, "{kind}: default {base}");
        assert_eq!(
            report["relations_over_0_5_m"], over_half_metre,
            "{kind}: {report}"
        );
        assert!(f(&report["default"]["trans_max"]) < 0.6, "{kind}: {report}");
        let bound = (2.0 * base).max(0.05);
        for v in report["variants"].as_array().expect("variants") {
            let t = f(&v["trans_mean"]);
            assert!(t <= bound, "{kind} {}: {t} m over {bound} m", v["name"]);
        }
        assert!(f(&report["median_ratio"]) <= 1.3, "{kind}: {report}");
    }
}

/// A log nobody tuned on, scored against the truth: a simulated park (its default layout and
/// noise, 804 scans of trunks on slippery grass), every variant against the ground truth.
/// Every parameter variant and every input variant that keeps the scans' content (`scans/2`,
/// the odometry's noise, range noise) holds its bound for q-wsm and q-idc. The two that take
/// points away are reported, not bounded: with every second beam a trunk keeps one point or
/// none, and within 10 m a park scan often holds too few to match, so they cost two to three
/// times the default here, as they do scan to scan (wsm and idc alike). So is `odom-bias`:
/// the drive ends where it began, 800 s later, and that revisit's relation holds the whole
/// loop's drift, which odometry biased by 1° a metre drives further where no trunk is in
/// view (q-wsm: 5.4 m on that relation, 0.065 m on all 138 against a bound of 0.053 m; its
/// 137 segments alone 0.026 m, as the default's).
#[test]
fn sweep_bounds_hold_against_the_ground_truth_of_a_simulated_park() {
    let dir = simulated("park.toml", &[]);
    let path = |name: &str| dir.path().join(name).display().to_string();
    // As configs/park.toml: a park scan holds a few trunks of two to five points each.
    let config = path("park-matcher.toml");
    std::fs::write(&config, "[matcher.icp]\nmin_correspondences = 5\n").expect("config");
    let (log, truth) = (path("sim/sim.log"), path("sim/groundtruth.tum"));
    for kind in ["q-wsm", "q-idc"] {
        let o = qicp(&[
            "sweep",
            &log,
            "--matcher",
            kind,
            "--config",
            &config,
            "--reference",
            &truth,
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
        let base = f(&report["default"]["trans_mean"]);
        assert!(base < 0.05, "{kind}: default {base} m per segment");
        assert_eq!(report["relations_over_0_5_m"], 0, "{kind}: {report}");
        let bound = (2.0 * base).max(0.05);
        let variants = report["variants"].as_array().expect("variants");
        let parameters = variants
            .iter()
            .filter(|v| v["name"].as_str().is_some_and(|n| n.contains('*')));
        assert!(
            parameters.count() >= 50,
            "{kind}: every parameter variant runs"
        );
        for v in variants {
            let name = v["name"].as_str().expect("a name");
            let t = f(&v["trans_mean"]);
            if ["beams/2", "max-range-10", "odom-bias"].contains(&name) {
                assert!(t.is_finite() && t < 0.5, "{kind} {name}: {t} m");
            } else {
                assert!(t <= bound, "{kind} {name}: {t} m over {bound} m");
            }
        }
        assert!(f(&report["median_ratio"]) <= 1.3, "{kind}: {report}");
    }
}

#[test]
fn sweep_writes_each_runs_trajectory_which_scores_as_reported() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("runs");
    let out_arg = out.to_str().expect("utf-8 path");
    let (report, _) = sweep_json(&[
        "--scans",
        "400",
        "--variants",
        "beams/2,icp.max_dist_end*0.7",
        "--trajectories",
        out_arg,
    ]);
    let relations = data("intel.relations");
    for (file, figures) in [
        ("default.tum", &report["default"]),
        ("beams-2.tum", &report["variants"][0]),
        ("icp.max_dist_end-x0.7.tum", &report["variants"][1]),
    ] {
        let path = out.join(file);
        let lines = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .lines()
            .count();
        assert_eq!(
            lines as f64,
            f(&figures["scans"]),
            "{file}: one pose per scan"
        );
        let o = qicp(&[
            "eval",
            "relations",
            path.to_str().expect("utf-8 path"),
            &relations,
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let scored: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
        let (a, b) = (f(&scored["trans_mean"]), f(&figures["trans_mean"]));
        assert!((a - b).abs() < 1e-12, "{file}: scored {a}, reported {b}");
    }
    let names: Vec<_> = std::fs::read_dir(&out)
        .expect("listed")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names.len(), 3, "no temporary file is left: {names:?}");
}

#[test]
fn sweep_without_relations_scores_each_variant_against_the_default_run() {
    let log = data("intel.clf.bz2");
    let o = qicp(&[
        "sweep",
        &log,
        "--matcher",
        "q-wsm",
        "--scans",
        "3000",
        "--variants",
        "scans/2,beams/2,odom-bias",
        "--json",
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(report["scored_against"], "default run");
    // The default agrees with itself over every segment drawn along it (a metre or 30°: the
    // first 3,000 scans hold over a hundred).
    let segments = report["relations_total"].as_u64().expect("segments");
    assert!(segments > 100, "{report}");
    assert_eq!(f(&report["default"]["trans_mean"]), 0.0);
    assert_eq!(report["default"]["relations"].as_u64(), Some(segments));
    assert!(report["median_ratio"].is_null() && report["worst_ratio"].is_null());
    for v in report["variants"].as_array().expect("variants") {
        // Segments end on records every variant keeps: even scans/2 has them all.
        assert_eq!(v["relations"].as_u64(), Some(segments), "{v}");
        assert!(v["ratio"].is_null(), "{v}");
        // On these scans the variants' motion stays within a few centimetres of the
        // default's (measured: 0.019, 0.024 and 0.009 m).
        let t = f(&v["trans_mean"]);
        assert!(t > 0.0 && t < 0.05, "{}: {t} m", v["name"]);
    }
}

#[test]
fn sweep_without_relations_refuses_a_drive_too_short_to_compare() {
    let log = data("intel.clf.bz2");
    let o = qicp(&[
        "sweep",
        &log,
        "--matcher",
        "wsm",
        "--scans",
        "5",
        "--variants",
        "beams/2",
    ]);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("nothing to compare"), "{stderr}");
}

#[test]
fn sweep_against_a_reference_trajectory_scores_the_default_too() {
    let dir = simulated("corridor.toml", &["--max-scans", "120"]);
    let path = |name: &str| dir.path().join(name).display().to_string();
    let log = path("sim/sim.log");
    // idc's own trajectory as the reference: the default run agrees with it exactly.
    let o = qicp(&["match", &log, "--matcher", "idc", "--out", &path("idc")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let reference = path("idc/trajectory.tum");
    let args = [
        "sweep",
        &log,
        "--matcher",
        "idc",
        "--reference",
        &reference,
        "--variants",
        "scans/2,range-noise",
        "--json",
    ];
    let o = qicp(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(report["scored_against"], "reference trajectory");
    assert_eq!(
        report["reference"],
        reference.as_str(),
        "the report names its reference"
    );
    let segments = report["relations_total"].as_u64().expect("segments");
    assert!(segments > 10, "{report}");
    assert!(f(&report["default"]["trans_mean"]) < 1e-9, "{report}");
    for v in report["variants"].as_array().expect("variants") {
        // Segments end on records every variant keeps: scans/2 has them all.
        assert_eq!(v["relations"].as_u64(), Some(segments), "{v}");
        assert!(f(&v["trans_mean"]) > 0.0, "{v}");
    }
    // A reference stamped a few milliseconds off the records (another tool's clock or
    // rounding): segments are drawn at the records' own times, so it scores the same.
    let shifted = path("shifted.tum");
    let text = std::fs::read_to_string(&reference).expect("reference");
    let moved: String = text
        .lines()
        .map(|l| match l.split_once(' ') {
            Some((t, rest)) if !l.starts_with('#') => {
                let t: f64 = t.parse().expect("a time");
                format!("{} {rest}\n", t + 0.004)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    std::fs::write(&shifted, moved).expect("shifted reference");
    let mut shifted_args = args.to_vec();
    shifted_args[5] = &shifted;
    let o = qicp(&shifted_args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let again: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(again["relations_total"], report["relations_total"]);
    assert_eq!(
        again["default"]["relations"],
        report["default"]["relations"]
    );
    for (a, b) in again["variants"]
        .as_array()
        .expect("variants")
        .iter()
        .zip(report["variants"].as_array().expect("variants"))
    {
        assert_eq!(a["relations"], b["relations"], "{a}");
        assert_eq!(a["trans_mean"], b["trans_mean"], "{a}");
    }
    // A reference and a relations file at once are refused.
    let mut both = args.to_vec();
    both.extend(["--relations", &reference]);
    let o = qicp(&both);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("cannot be used with"));
}
