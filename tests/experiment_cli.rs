//! End to end: `qicp run CONFIG --out DIR` on a short park drive runs every matcher on the same
//! scans and writes a complete summary, every trajectory and per-scan CSV, the effective
//! config (which runs again as is) and every picture; bad experiment configs are refused with
//! the key named.

mod common_csv;
use common_csv::lines;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const KINDS: [&str; 5] = ["idc", "q-idc", "wsm", "q-wsm", "kd-wsm"];

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-run-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn qicp_run(config: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .arg("run")
        .arg(config)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("runs qicp")
}

fn assert_success(o: &Output) {
    assert!(
        o.status.success(),
        "qicp run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A PNG signature, an IHDR of plausible size, and more than a blank picture's bytes.
fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is not a PNG",
        path.display()
    );
    assert_eq!(&bytes[12..16], b"IHDR");
    let width = u32::from_be_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]);
    let height = u32::from_be_bytes([bytes[20], bytes[21], bytes[22], bytes[23]]);
    assert!(
        (300..=5000).contains(&width) && (300..=5000).contains(&height),
        "{}: {width}x{height}",
        path.display()
    );
    assert!(
        bytes.len() > 10_000,
        "{}: only {} bytes",
        path.display(),
        bytes.len()
    );
}

#[test]
fn run_writes_summary_trajectories_csvs_config_and_pictures() {
    let out = out_dir("park");
    let o = qicp_run(
        &repo().join("tests/fixtures/park_short.toml"),
        &out,
        &["--json"],
    );
    assert_success(&o);
    let printed: Value = serde_json::from_slice(&o.stdout).expect("--json prints the summary");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("summary.json parses");
    assert_eq!(printed["scans"], summary["scans"]);
    assert_eq!(summary["scans"], 60);
    assert!(
        summary["source"]
            .as_str()
            .is_some_and(|s| s.starts_with("sim:"))
    );
    assert!(summary["wall_seconds"].as_f64().is_some_and(|s| s > 0.0));

    for kind in KINDS {
        let m = &summary["matchers"][kind];
        for key in [
            "ate_rmse_m",
            "rpe_trans_per_m",
            "final_error_m",
            "residual_mean_mm",
            "certainty_mean",
            "sigma_mean_mm",
            "ms_per_scan_median",
            "ms_per_scan_p99",
            "map_points",
            "fallbacks",
        ] {
            assert!(m.get(key).is_some(), "{kind}: no `{key}` in {m}");
        }
        assert!(
            m["ate_rmse_m"].as_f64().is_some_and(f64::is_finite),
            "{kind}: {m}"
        );
        assert!(m.get("relations").is_none(), "no relations file was given");
        let traj = lines(&out.join(kind).join("trajectory.tum"));
        assert_eq!(traj.len(), 60, "{kind}: one pose per scan");
        assert_eq!(
            traj[0].split_whitespace().count(),
            8,
            "TUM: t x y z qx qy qz qw"
        );
        let csv = lines(&out.join(kind).join("matches.csv"));
        assert_eq!(csv.len(), 61, "{kind}: header and one row per scan");
        assert!(csv[0].starts_with("timestamp,"));
        assert_png(&out.join(format!("map_{kind}.png")));
    }
    for key in ["ate_rmse_m", "rpe_trans_per_m", "final_error_m"] {
        assert!(
            summary["odometry"].get(key).is_some(),
            "odometry: no `{key}`"
        );
    }
    for pair in ["q-idc/idc", "q-wsm/wsm", "kd-wsm/wsm"] {
        for key in ["ate", "residual", "certainty", "sigma"] {
            assert!(
                summary["ratios"][pair].get(key).is_some(),
                "ratios.{pair}: no `{key}`"
            );
        }
    }
    assert_eq!(lines(&out.join("groundtruth.tum")).len(), 60);
    assert_eq!(lines(&out.join("odometry.tum")).len(), 60);
    for picture in ["trajectories.png", "residual.png", "certainty.png"] {
        assert_png(&out.join(picture));
    }

    // The effective config spells out every matcher and runs again to the same trajectories.
    let effective = std::fs::read_to_string(out.join("config.toml")).expect("config.toml");
    for kind in KINDS {
        assert!(
            effective.contains(&format!("[matchers.{kind}")),
            "{effective}"
        );
    }
    assert!(
        effective.contains("max_iterations = 30"),
        "the override is kept"
    );
    let again = out_dir("park-again");
    assert_success(&qicp_run(&out.join("config.toml"), &again, &["--quiet"]));
    for kind in KINDS {
        assert_eq!(
            lines(&out.join(kind).join("trajectory.tum")),
            lines(&again.join(kind).join("trajectory.tum")),
            "{kind}: the effective config reproduces the run"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&again);
}

#[test]
fn run_prints_a_table_and_quiet_silences_it() {
    let config = repo().join("tests/fixtures/park_short.toml");
    let out = out_dir("table");
    let o = qicp_run(&config, &out, &["--max-scans", "30"]);
    assert_success(&o);
    let table = String::from_utf8_lossy(&o.stdout);
    for word in [
        "matcher",
        "ATE m",
        "odometry",
        "q-wsm",
        "boosted / incremental",
        "wall time",
    ] {
        assert!(table.contains(word), "no `{word}` in\n{table}");
    }
    let o = qicp_run(&config, &out, &["--max-scans", "30", "--quiet"]);
    assert_success(&o);
    assert!(o.stdout.is_empty(), "--quiet prints nothing");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn bad_experiment_configs_name_the_key() {
    let dir = out_dir("bad");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let park = repo().join("configs/worlds/park.toml");
    let park = park.display();
    for (text, key) in [
        (
            format!("[source]\nsim = \"{park}\"\ncolour = 3\n"),
            "colour",
        ),
        (
            format!("[source]\nsim = \"{park}\"\nlog = \"x.clf\"\n"),
            "source",
        ),
        ("[source]\n".to_string(), "source"),
        (
            format!("[source]\nsim = \"{park}\"\nmax_scans = 0\n"),
            "source.max_scans",
        ),
        (
            format!("[source]\nsim = \"{park}\"\nrelations = \"r\"\n"),
            "source.relations",
        ),
        (
            "[source]\nlog = \"x.clf\"\nworld_seed = 3\n".to_string(),
            "source.world_seed",
        ),
        (
            format!("[source]\nsim = \"{park}\"\norder = \"time\"\n"),
            "source.order",
        ),
        (
            format!("[source]\nsim = \"{park}\"\nmax_range = 20.0\n"),
            "source.max_range",
        ),
        (
            "[source]\nlog = \"x.clf\"\nfov_deg = 0.0\n".to_string(),
            "source.fov_deg",
        ),
        (
            "[source]\nlog = \"x.clf\"\nmin_range = -1.0\n".to_string(),
            "source.min_range",
        ),
        (
            format!("[source]\nsim = \"{park}\"\n[run]\nmatchers = []\n"),
            "run.matchers",
        ),
        (
            format!("[source]\nsim = \"{park}\"\n[run]\nmatchers = [\"icp\"]\n"),
            "icp",
        ),
        (
            format!("[source]\nsim = \"{park}\"\n[run]\nmatchers = [\"wsm\"]\n[matchers.idc]\n"),
            "matchers.idc",
        ),
        (
            format!(
                "[source]\nsim = \"{park}\"\n[run]\nmatchers = [\"wsm\"]\n[matchers.wsm]\nicp = {{ max_iterations = 0 }}\n"
            ),
            "max_iterations",
        ),
        (
            format!(
                "[source]\nsim = \"{park}\"\n[run]\nmatchers = [\"wsm\"]\n[matchers.wsm]\nidc = {{}}\n"
            ),
            "matcher.idc",
        ),
    ] {
        let path = dir.join("bad.toml");
        std::fs::write(&path, &text).expect("write config");
        let o = qicp_run(&path, &dir.join("out"), &["--quiet"]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "accepted:\n{text}");
        assert!(
            stderr.contains(key),
            "`{key}` not named for\n{text}\n{stderr}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--worlds 18446744073709551615` used to overflow a capacity and panic.
#[test]
fn worlds_beyond_the_bound_are_refused_not_a_crash() {
    let config = repo().join("tests/fixtures/park_short.toml");
    let out = out_dir("worlds-bound");
    for n in ["18446744073709551615", "10001"] {
        let o = qicp_run(&config, &out, &["--max-scans", "2", "--worlds", n]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{n}: {stderr}");
        assert!(stderr.contains("at most 10000 worlds"), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn worlds_repeats_the_experiment_on_other_layouts_and_reports_medians() {
    let config = repo().join("tests/fixtures/park_short.toml");
    let out = out_dir("worlds");
    let o = qicp_run(
        &config,
        &out,
        &["--max-scans", "30", "--worlds", "3", "--json"],
    );
    assert_success(&o);
    let report: Value = serde_json::from_slice(&o.stdout).expect("worlds.json on stdout");
    let seeds: Vec<u64> = report["world_seeds"]
        .as_array()
        .expect("world_seeds")
        .iter()
        .map(|s| s.as_u64().expect("seed"))
        .collect();
    assert_eq!(seeds.len(), 3);
    assert_eq!(seeds[1], seeds[0] + 1);
    assert_eq!(seeds[2], seeds[0] + 2);
    // Every world has its own complete run, on its own layout.
    let mut ates = Vec::new();
    for seed in &seeds {
        let dir = out.join(format!("world-{seed}"));
        let summary: Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("summary.json")).expect("world summary"),
        )
        .expect("json");
        assert_eq!(summary["scans"], 30);
        for kind in KINDS {
            assert!(dir.join(kind).join("trajectory.tum").is_file());
        }
        let config = std::fs::read_to_string(dir.join("config.toml")).expect("config");
        assert!(config.contains(&format!("world_seed = {seed}")), "{config}");
        assert!(
            config.contains("\nseed = "),
            "the noise seed advances too: {config}"
        );
        ates.push(
            summary["matchers"]["q-wsm"]["ate_rmse_m"]
                .as_f64()
                .expect("ate"),
        );
    }
    assert!(
        ates.iter().any(|a| *a != ates[0]),
        "three layouts gave the same q-wsm ATE {ates:?}"
    );
    // The report is the median, minimum and maximum of the worlds' figures.
    let ate = &report["matchers"]["q-wsm"]["ate_rmse_m"];
    ates.sort_by(f64::total_cmp);
    assert_eq!(ate["median"].as_f64(), Some(ates[1]));
    assert_eq!(ate["min"].as_f64(), Some(ates[0]));
    assert_eq!(ate["max"].as_f64(), Some(ates[2]));
    for pair in ["q-wsm/wsm", "q-idc/idc"] {
        let r = &report["ratios"][pair]["residual"];
        let (lo, med, hi) = (
            r["min"].as_f64().expect("min"),
            r["median"].as_f64().expect("median"),
            r["max"].as_f64().expect("max"),
        );
        assert!(lo <= med && med <= hi, "{pair}: {r}");
    }
    assert!(out.join("worlds.json").is_file());
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn worlds_needs_a_simulated_source() {
    let dir = out_dir("worlds-log");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let log = dir.join("tiny.clf");
    std::fs::write(&log, "ODOM 0 0 0 0 0 0 1.0 host 1.0\n").expect("write log");
    let config = dir.join("log.toml");
    std::fs::write(&config, format!("[source]\nlog = \"{}\"\n", log.display()))
        .expect("write config");
    let o = qicp_run(&config, &dir.join("out"), &["--worlds", "2", "--quiet"]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--worlds needs a `sim` source"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Matchers run concurrently give what they give one after another: every trajectory and
/// per-scan figure but the times, byte for byte, with PL-ICP (registered by the command line
/// from its own crate) among them.
#[test]
fn concurrent_matchers_give_the_sequential_results() {
    let kinds = ["wsm", "q-wsm", "q-idc", "q-plicp"];
    let dir = out_dir("jobs");
    std::fs::create_dir_all(&dir).expect("dir");
    let with_plicp = dir.join("park_plicp.toml");
    let park = repo().join("configs/worlds/park.toml");
    std::fs::write(
        &with_plicp,
        format!(
            "[source]\nsim = \"{}\"\nmax_scans = 40\n[run]\nmatchers = [{}]\n",
            park.display(),
            kinds.map(|k| format!("\"{k}\"")).join(", ")
        ),
    )
    .expect("config");
    let (one, three) = (dir.join("one"), dir.join("three"));
    assert_success(&qicp_run(&with_plicp, &one, &["--jobs", "1", "--quiet"]));
    assert_success(&qicp_run(&with_plicp, &three, &["--jobs", "3", "--quiet"]));
    for kind in kinds {
        let a = lines(&one.join(kind).join("trajectory.tum"));
        assert_eq!(a.len(), 40, "{kind}");
        assert_eq!(a, lines(&three.join(kind).join("trajectory.tum")), "{kind}");
        // Per-scan figures without the time column.
        let strip = |p: &Path| common_csv::without_times(&lines(p));
        assert_eq!(
            strip(&one.join(kind).join("matches.csv")),
            strip(&three.join(kind).join("matches.csv")),
            "{kind}"
        );
    }
}

/// A ground truth of one pose on a 40-scan log used to score ATE 0.000 m for every matcher,
/// without a word: a truth that pairs with fewer than half of the poses is warned about.
/// `qicp sim` of the corridor world into `dir`: `sim.log` and `groundtruth.tum`, `scans` long.
fn simulate_corridor(dir: &Path, scans: usize) {
    let sim = Command::new(env!("CARGO_BIN_EXE_qicp"))
        .arg("sim")
        .arg(repo().join("configs/worlds/corridor.toml"))
        .arg("--out")
        .arg(dir)
        .args(["--max-scans", &scans.to_string()])
        .output()
        .expect("runs qicp sim");
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
}

#[test]
fn a_ground_truth_covering_few_poses_is_warned_about() {
    let dir = out_dir("sparse-truth");
    simulate_corridor(&dir, 40);
    let truth = std::fs::read_to_string(dir.join("groundtruth.tum")).expect("truth");
    let first = truth.lines().find(|l| !l.starts_with('#')).expect("a pose");
    std::fs::write(dir.join("one.tum"), format!("{first}\n")).expect("one pose");
    let config = dir.join("experiment.toml");
    std::fs::write(
        &config,
        "[source]\nlog = \"sim.log\"\ngroundtruth = \"one.tum\"\n[run]\nmatchers = [\"wsm\"]\n",
    )
    .expect("config");
    let o = qicp_run(&config, &dir.join("out"), &["--quiet"]);
    assert_success(&o);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("warning: only 1 of the trajectory's 40 poses have a ground-truth pose"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_that_fails_after_reading_its_source_writes_no_summary() {
    let dir = out_dir("fails-late");
    simulate_corridor(&dir, 20);
    let config = dir.join("experiment.toml");
    std::fs::write(
        &config,
        "[source]\nlog = \"sim.log\"\n[run]\nmatchers = [\"wsm\"]\n",
    )
    .expect("config");
    // A directory where the odometry's trajectory goes: its write fails after the source is
    // read and config.toml is written.
    let out = dir.join("out");
    std::fs::create_dir_all(out.join("odometry.tum").join("blocker")).expect("blocker");
    let o = qicp_run(&config, &out, &["--quiet"]);
    assert!(!o.status.success(), "a failed write, yet exit 0");
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("odometry.tum"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.join("config.toml").exists(), "the completed file stays");
    assert!(
        !out.join("summary.json").exists(),
        "a summary marks a complete run"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn relations_of_another_log_stop_a_run_before_its_matchers() {
    let dir = out_dir("foreign-relations");
    simulate_corridor(&dir, 20);
    // The simulated drive starts near t = 0; these relations lie a day later.
    std::fs::write(
        dir.join("far.relations"),
        "86400 86401 0.1 0 0 0 0 0\n86402 86403 0.1 0 0 0 0 0\n",
    )
    .expect("relations");
    let config = dir.join("experiment.toml");
    std::fs::write(
        &config,
        "[source]\nlog = \"sim.log\"\nrelations = \"far.relations\"\n[run]\nmatchers = [\"wsm\"]\n",
    )
    .expect("config");
    let out = dir.join("out");
    let o = qicp_run(&config, &out, &["--quiet"]);
    // It used to warn and score every matcher on nothing, exit 0.
    assert!(!o.status.success(), "relations of another log, yet exit 0");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("none of the 2 relations"), "{stderr}");
    assert!(
        !out.join("wsm").exists(),
        "a matcher ran on unscorable relations"
    );
    assert!(!out.join("summary.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The shipped park among hedges: foliage returns another surface at every scan, and the
/// boosted matchers still follow the loop far better than scan to scan (measured: q-wsm
/// 0.29 m against wsm 5.85 m, q-idc 0.77 m against idc 2.92 m). q-idc scored 0.20 m here
/// before it matched a suspect odometry guess both ways, which moves the run of every hedged
/// park: over sixty its geometric mean ATE went 0.786 -> 0.779 m and its misses of the ATE
/// target 8 -> 5 (README, Among hedges), so this one world bounds the ratio, not the luck.
#[test]
fn among_hedges_the_boosted_matchers_still_beat_scan_to_scan() {
    let out = out_dir("park-hedges");
    let o = qicp_run(
        &repo().join("configs/park-hedges.toml"),
        &out,
        &["--json", "--quiet"],
    );
    assert_success(&o);
    let summary: Value = serde_json::from_slice(&o.stdout).expect("--json prints the summary");
    let ate = |kind: &str| {
        summary["matchers"][kind]["ate_rmse_m"]
            .as_f64()
            .unwrap_or_else(|| panic!("{kind}: no ATE in {summary}"))
    };
    for (boosted, incremental) in [("q-wsm", "wsm"), ("q-idc", "idc")] {
        let (b, i) = (ate(boosted), ate(incremental));
        assert!(b < 1.0, "{boosted}: ATE {b} m");
        assert!(
            b < 0.3 * i,
            "{boosted}: ATE {b} m against {incremental}'s {i} m"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// Office floors drawn from their seeds (`configs/office.toml`: doorways moved, some closed,
/// furniture in the rooms), every matcher with its defaults: on each of three floors every
/// boosted matcher follows the loop within 0.1 m ATE and beats its scan-to-scan twin
/// (measured over worlds 7-9: boosted at most 0.067 m, ATE ratios at most 0.55).
#[test]
fn on_office_floors_each_boosted_matcher_beats_its_scan_to_scan_twin() {
    let out = out_dir("office");
    let o = qicp_run(
        &repo().join("configs/office.toml"),
        &out,
        &["--worlds", "3", "--json", "--quiet"],
    );
    assert_success(&o);
    let report: Value = serde_json::from_slice(&o.stdout).expect("worlds.json on stdout");
    for (boosted, incremental) in [("q-wsm", "wsm"), ("q-idc", "idc"), ("q-plicp", "plicp")] {
        let worst = report["matchers"][boosted]["ate_rmse_m"]["max"]
            .as_f64()
            .unwrap_or_else(|| panic!("{boosted}: no ATE in {report}"));
        assert!(worst < 0.1, "{boosted}: ATE up to {worst} m");
        let ratio = report["ratios"][format!("{boosted}/{incremental}")]["ate"]["max"]
            .as_f64()
            .unwrap_or_else(|| panic!("{boosted}/{incremental}: no ratio in {report}"));
        assert!(
            ratio < 0.75,
            "{boosted}/{incremental}: ATE ratio up to {ratio}"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}
