//! End to end: `qicp match` on a short simulated corridor drive writes the trajectory, the
//! per-scan CSV, a summary with every key and the effective config, and scores relations; a
//! malformed log is refused with its line number, or skipped and counted with --lenient.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn qicp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(args)
        .output()
        .expect("runs qicp")
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-match-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn text(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A short corridor drive as a CARMEN log with ground truth, in a directory of its own per
/// `test` (the tests run in parallel, and each clears its directory first).
fn corridor_log(test: &str) -> PathBuf {
    let dir = temp(&format!("sim-{test}"));
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/worlds/corridor.toml");
    let o = qicp(&[
        "sim",
        config,
        "--out",
        dir.to_str().expect("temporary paths are UTF-8"),
        "--max-scans",
        "60",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    dir
}

#[test]
fn match_writes_every_output() {
    let sim = corridor_log("outputs");
    let out = temp("out");
    let log = sim.join("sim.log");
    let o = qicp(&[
        "match",
        log.to_str().unwrap(),
        "--matcher",
        "q-wsm",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    for key in [
        "matcher",
        "scans",
        "ms_per_scan_median",
        "ms_per_scan_p99",
        "map_points",
        "residual_mean_mm",
        "certainty_mean",
        "sigma_mean_mm",
        "fallbacks",
    ] {
        assert!(summary.get(key).is_some(), "summary lacks {key}: {summary}");
    }
    assert_eq!(summary["matcher"], "q-wsm");
    assert_eq!(summary["scans"], 60);
    assert_eq!(
        summary["fallbacks"], 1,
        "only the first scan has nothing to match"
    );
    let on_disk: serde_json::Value =
        serde_json::from_str(&text(&out.join("summary.json"))).expect("summary.json");
    assert_eq!(on_disk, summary);
    // One pose per laser record, TUM format.
    let traj = text(&out.join("trajectory.tum"));
    let poses: Vec<&str> = traj.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(poses.len(), 60);
    assert!(poses.iter().all(|l| l.split_whitespace().count() == 8));
    let csv = text(&out.join("matches.csv"));
    assert_eq!(
        csv.lines().next(),
        Some(
            "timestamp,iterations,correspondences,residual_mm,certainty,ms,inserted,fallback,sigma_mm,inlier_share,check,held"
        )
    );
    assert_eq!(csv.lines().count(), 61);
    // certainty = sqrt(σxx² + σyy²) (m²) and σ = sqrt(σxx + σyy) (mm) of the same covariance:
    // σ²/√2 ≤ certainty ≤ σ² for non-negative σxx, σyy.
    let mut matched = 0;
    for row in csv.lines().skip(1) {
        let cells: Vec<&str> = row.split(',').collect();
        let certainty: f64 = cells[4].parse().expect("certainty");
        let sigma_m = cells[8].parse::<f64>().expect("sigma_mm") / 1e3;
        if certainty.is_nan() {
            assert!(sigma_m.is_nan(), "{row}");
            continue;
        }
        let var = sigma_m * sigma_m;
        assert!(
            certainty <= var * (1.0 + 1e-3) && certainty >= var / 2f64.sqrt() * (1.0 - 1e-3),
            "{row}"
        );
        matched += 1;
    }
    assert_eq!(matched, 59);
    // Each held match is marked where summary.json counts them.
    let held = csv
        .lines()
        .skip(1)
        .filter(|row| row.ends_with(",1"))
        .count();
    assert_eq!(summary["held"], held, "{summary}");
    // The effective config is complete and loads again.
    let config = text(&out.join("config.toml"));
    assert!(config.contains("[matcher.wsm]") && config.contains("[matcher.relevance]"));
    let again = qicp(&[
        "match",
        log.to_str().unwrap(),
        "--config",
        out.join("config.toml").to_str().unwrap(),
        "--out",
        temp("again").to_str().unwrap(),
        "--json",
    ]);
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    let twice: serde_json::Value = serde_json::from_slice(&again.stdout).expect("JSON");
    assert_eq!(
        twice["residual_mean_mm"], summary["residual_mean_mm"],
        "same config, same run"
    );
}

#[test]
fn malformed_lines_name_the_line_or_are_counted() {
    let sim = corridor_log("malformed");
    let log = text(&sim.join("sim.log"));
    let mut lines: Vec<&str> = log.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.starts_with("FLASER"))
        .expect("a FLASER line")
        + 3;
    lines.insert(at, "FLASER 181 1.0 2.0 oops");
    let bad = temp("bad");
    std::fs::create_dir_all(&bad).unwrap();
    let path = bad.join("bad.log");
    std::fs::write(&path, lines.join("\n")).unwrap();
    let out = temp("bad-out");
    let o = qicp(&[
        "match",
        path.to_str().unwrap(),
        "--matcher",
        "wsm",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!("bad.log:{}", at + 1)),
        "error names file and line: {err}"
    );
    let o = qicp(&[
        "match",
        path.to_str().unwrap(),
        "--matcher",
        "wsm",
        "--out",
        out.to_str().unwrap(),
        "--lenient",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["skipped_lines"], 1);
    assert_eq!(summary["scans"], 60);
}

#[test]
fn bad_matcher_choices_are_refused() {
    let out = temp("refused");
    let o = qicp(&[
        "match",
        "nonexistent.log",
        "--matcher",
        "q-icp",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("q-icp"));
    let o = qicp(&["match", "nonexistent.log", "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--matcher"));
}

/// A room of 180 beams over 30 scans, the robot still, every fifth beam reading 29.5 m: a
/// no-return code below the 30 m the log declares.
fn coded_log(test: &str) -> PathBuf {
    let dir = temp(test);
    std::fs::create_dir_all(&dir).expect("a scratch directory");
    let mut text = String::from("PARAM robot_front_laser_max 30 nohost 0\n");
    for scan in 0..30 {
        let ranges: Vec<String> = (0..180)
            .map(|i| {
                let r = if i % 5 == 0 {
                    29.5
                } else {
                    2.0 + f64::from(i % 45) * 0.05
                };
                r.to_string()
            })
            .collect();
        let t = f64::from(scan) * 0.2;
        text += &format!("FLASER 180 {} 0 0 0 0 0 0 {t} host {t}\n", ranges.join(" "));
    }
    let log = dir.join("coded.clf");
    std::fs::write(&log, text).expect("the log written");
    log
}

#[test]
fn a_no_return_code_is_named_and_the_laser_options_drop_it() {
    let log = coded_log("coded");
    let log = log.to_str().unwrap();
    let out = temp("coded-out");
    let run = |extra: &[&str]| {
        let _ = std::fs::remove_dir_all(&out);
        let mut args = vec![
            "match",
            log,
            "--matcher",
            "wsm",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        qicp(&args)
    };
    let o = run(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("1080 readings")
            && err.contains("29.50 m")
            && err.contains("--max-range 29.495"),
        "{err}"
    );
    let o = run(&["--max-range", "29.495"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("no-return code"), "{err}");
    // Values no laser has are refused by their flag's name, before any matching.
    for (flag, value) in [
        ("--fov-deg", "0"),
        ("--max-range", "inf"),
        ("--min-range", "-1"),
    ] {
        let o = run(&[&format!("{flag}={value}")]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(flag), "{err}");
        assert!(!out.exists(), "{flag}: no output for a refused run");
    }
    // The options describe a log: not a bridge's scans.
    let o = qicp(&["match", "--subscribe", "--max-range", "20"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--subscribe"));
}

/// In the paper's sparse park (`configs/worlds/park-sparse.toml`, world 10 of `qicp run
/// --worlds`: layout seed 10, noise seed 4) a look-up at scan 752 finds the old map explaining
/// a scan of seven points, on two or three trunks, far better elsewhere in its window. Re-anchored on that one
/// look-up (`revisit.confirmations = 1`, the sweep's `confirmations*0.7`), q-wsm's match held
/// a position σ of 0.2 m, the pose turned and the drive ended 10.4 m ATE off (0.81 m without
/// the re-anchoring). A re-anchoring whose σ exceeds the tolerance its correction is compared
/// with is not taken. With WSM's stages ending early against a map (`[matcher.wsm]
/// stage_tolerance = 0.1`, off by default), the look-up at scan 752 proposes a σ of 227 mm and
/// one at scan 592 a σ of 95 mm (six pairs), within the tolerance: that one is taken and the
/// drive ends 0.77 m ATE off (0.80 m without it); with the check removed both are taken.
#[test]
fn a_reanchoring_on_a_few_far_trunks_is_not_taken() {
    let dir = temp("sparse-park");
    let path = |name: &str| dir.join(name).display().to_string();
    let world = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/configs/worlds/park-sparse.toml"
    );
    let o = qicp(&[
        "sim",
        world,
        "--world-seed",
        "10",
        "--seed",
        "4",
        "--out",
        &path("sim"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let config = path("one-look-up.toml");
    std::fs::write(
        &config,
        "[matcher.icp]\nmin_correspondences = 5\n[matcher.revisit]\nconfirmations = 1\n",
    )
    .expect("config");
    let o = qicp(&[
        "match",
        &path("sim/sim.log"),
        "--matcher",
        "q-wsm",
        "--config",
        &config,
        "--out",
        &path("q-wsm"),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Every re-anchored match is determined within the tolerance (σ ≤ 0.1 m).
    let matches = std::fs::read_to_string(path("q-wsm/matches.csv")).expect("matches.csv");
    let mut rows = matches.lines();
    let header: Vec<&str> = rows.next().expect("a header").split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (sigma, check) = (column("sigma_mm"), column("check"));
    for (k, row) in rows.enumerate() {
        let fields: Vec<&str> = row.split(',').collect();
        if fields[check] == "reanchored" {
            let s: f64 = fields[sigma].parse().expect("a σ");
            assert!(s <= 100.0, "scan {k} re-anchored with σ {s} mm");
        }
    }
    let o = qicp(&[
        "eval",
        "ate",
        &path("q-wsm/trajectory.tum"),
        &path("sim/groundtruth.tum"),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ate: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let rmse = ate["ate_rmse_m"].as_f64().expect("ATE");
    assert!(rmse < 1.5, "ATE {rmse} m");
    let _ = std::fs::remove_dir_all(&dir);
}
