//! `qicp run` on a log source streams the log through every matcher: what it writes is what
//! `qicp match` writes for the same matcher on the same scans, and it does not depend on how
//! many matchers run at once. A log on a pipe, read once and held, gives what the file gives,
//! and a log with ground truth scores its ATE as `qicp eval ate` does, streamed or held.

mod common_csv;
use common_csv::lines;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn qicp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(args)
        .output()
        .expect("qicp runs")
}

fn assert_success(o: &Output, what: &str) {
    assert!(
        o.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn data(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/intel")
        .join(file)
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).expect("JSON")
}

/// `qicp run CONFIG --log /dev/stdin --out OUT --quiet` with `log` piped in: a pipe, which can
/// be read only once.
fn run_on_pipe(config: &Path, out: &Path, log: &[u8]) -> Output {
    use std::io::Write;
    let mut child = Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args([
            "run",
            config.to_str().expect("utf-8"),
            "--log",
            "/dev/stdin",
            "--out",
            out.to_str().expect("utf-8"),
            "--quiet",
        ])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("qicp runs");
    let mut stdin = child.stdin.take().expect("stdin");
    stdin.write_all(log).expect("piped");
    drop(stdin);
    child.wait_with_output().expect("qicp ends")
}

/// `matches.csv` without its wall-time column.
fn rows_without_times(path: &Path) -> Vec<String> {
    common_csv::without_times(&lines(path))
}

/// Writes an experiment on `log` (its first `scans`) with the Intel relations.
fn experiment(dir: &Path, log: &Path, scans: usize, matchers: &[&str]) -> PathBuf {
    let config = dir.join("experiment.toml");
    let kinds: Vec<String> = matchers.iter().map(|k| format!("{k:?}")).collect();
    std::fs::write(
        &config,
        format!(
            "[source]\nlog = {log:?}\nrelations = {:?}\nmax_scans = {scans}\n\n[run]\nmatchers = [{}]\n",
            data("intel.relations"),
            kinds.join(", ")
        ),
    )
    .expect("config");
    config
}

fn run(config: &Path, out: &Path, jobs: &str) {
    let o = qicp(&[
        "run",
        config.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "--jobs",
        jobs,
        "--quiet",
    ]);
    assert_success(&o, "qicp run");
}

/// The first 500 Intel scans as a ROS 2 bag: `qicp match` has no scan limit, and the shared
/// log is read, never copied.
fn first_scans_as_bag(dir: &Path, scans: usize) -> PathBuf {
    let bag = dir.join("intel-first.mcap");
    let o = qicp(&[
        "convert",
        data("intel.clf.bz2").to_str().expect("utf-8"),
        bag.to_str().expect("utf-8"),
        "--max-records",
        &scans.to_string(),
    ]);
    assert_success(&o, "qicp convert");
    bag
}

#[test]
fn a_log_experiment_writes_what_match_writes_for_any_jobs() {
    const SCANS: usize = 500;
    let kinds = ["wsm", "q-wsm"];
    let dir = tempfile::tempdir().expect("temp dir");
    let bag = first_scans_as_bag(dir.path(), SCANS);
    let config = experiment(dir.path(), &bag, SCANS, &kinds);
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    run(&config, &one, "1");
    run(&config, &two, "2");
    let summary = json(&one.join("summary.json"));
    assert_eq!(summary["scans"], SCANS);
    assert_eq!(lines(&one.join("odometry.tum")).len(), SCANS);
    for kind in kinds {
        let matched = dir.path().join(format!("match-{kind}"));
        let o = qicp(&[
            "match",
            bag.to_str().expect("utf-8"),
            "--matcher",
            kind,
            "--out",
            matched.to_str().expect("utf-8"),
            "--relations",
            data("intel.relations").to_str().expect("utf-8"),
        ]);
        assert_success(&o, "qicp match");
        let trajectory = lines(&one.join(kind).join("trajectory.tum"));
        assert_eq!(trajectory.len(), SCANS, "{kind}");
        assert_eq!(
            trajectory,
            lines(&matched.join("trajectory.tum")),
            "{kind}: qicp run and qicp match differ"
        );
        assert_eq!(
            trajectory,
            lines(&two.join(kind).join("trajectory.tum")),
            "{kind}: --jobs 1 and --jobs 2 differ"
        );
        let rows = rows_without_times(&one.join(kind).join("matches.csv"));
        assert_eq!(
            rows,
            rows_without_times(&matched.join("matches.csv")),
            "{kind}"
        );
        assert_eq!(
            rows,
            rows_without_times(&two.join(kind).join("matches.csv")),
            "{kind}"
        );
        // The relations, scored from the poses streamed past, as `qicp match` scores them.
        let run_relations = &summary["matchers"][kind]["relations"];
        let match_relations = &json(&matched.join("summary.json"))["relations"];
        assert!(run_relations["n"].as_u64().is_some_and(|n| n > 0), "{kind}");
        assert_eq!(run_relations, match_relations, "{kind}");
        assert_eq!(
            summary["matchers"][kind]["map_points"],
            json(&matched.join("summary.json"))["map_points"],
            "{kind}"
        );
    }
    for picture in [
        "map_wsm.png",
        "map_q-wsm.png",
        "trajectories.png",
        "certainty.png",
    ] {
        assert!(one.join(picture).is_file(), "{picture}");
    }
}

/// A CARMEN log streams too: the first scans of the experiment are the first poses of
/// `qicp match` over the whole log (matching is causal).
#[test]
fn a_carmen_experiment_starts_as_match_over_the_whole_log() {
    const SCANS: usize = 500;
    let dir = tempfile::tempdir().expect("temp dir");
    let config = experiment(dir.path(), &data("intel.clf.bz2"), SCANS, &["wsm"]);
    let out = dir.path().join("run");
    run(&config, &out, "2");
    let matched = dir.path().join("match");
    let o = qicp(&[
        "match",
        data("intel.clf.bz2").to_str().expect("utf-8"),
        "--matcher",
        "wsm",
        "--out",
        matched.to_str().expect("utf-8"),
    ]);
    assert_success(&o, "qicp match");
    let trajectory = lines(&out.join("wsm/trajectory.tum"));
    assert_eq!(trajectory.len(), SCANS);
    assert_eq!(
        trajectory[..],
        lines(&matched.join("trajectory.tum"))[..SCANS]
    );
}

#[test]
fn a_log_on_a_pipe_is_read_once_and_matched_as_the_same_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut text = String::new();
    for i in 0..60 {
        // A robot creeping along a corridor 2 m wide, walls at ±1 m.
        let ranges: Vec<String> = (0..181)
            .map(|b| {
                let a = (b as f64 - 90.0).to_radians();
                let r = if a.sin().abs() > 1e-6 {
                    1.0 / a.sin().abs()
                } else {
                    50.0
                };
                format!("{:.3}", r.min(50.0))
            })
            .collect();
        let (x, t) = (i as f64 * 0.05, i as f64 * 0.2);
        text.push_str(&format!(
            "FLASER 181 {} {x} 0 0 {x} 0 0 {t} host {t}\n",
            ranges.join(" ")
        ));
    }
    let file = dir.path().join("corridor.clf");
    std::fs::write(&file, &text).expect("log written");
    let config = dir.path().join("run.toml");
    std::fs::write(
        &config,
        "[source]\nlog = \"unused.clf\"\n\n[run]\nmatchers = [\"wsm\", \"q-wsm\"]\n",
    )
    .expect("config written");
    let out = |name: &str| dir.path().join(name);
    let o = qicp(&[
        "run",
        config.to_str().expect("utf-8"),
        "--log",
        file.to_str().expect("utf-8"),
        "--out",
        out("file").to_str().expect("utf-8"),
        "--quiet",
    ]);
    assert_success(&o, "run on the file");
    // The same bytes through a pipe, which can be read only once.
    let o = run_on_pipe(&config, &out("pipe"), text.as_bytes());
    assert_success(&o, "run on a pipe");
    for kind in ["wsm", "q-wsm"] {
        let (a, b) = (
            lines(&out("file").join(kind).join("trajectory.tum")),
            lines(&out("pipe").join(kind).join("trajectory.tum")),
        );
        assert_eq!(a.len(), 60, "{kind}: one pose a scan");
        assert_eq!(a, b, "{kind}: the pipe gives the file's trajectory");
    }
}

#[test]
fn a_log_with_ground_truth_scores_as_eval_and_as_when_held() {
    let dir = tempfile::tempdir().expect("temp dir");
    let park = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/park.toml");
    let sim = dir.path().join("sim");
    let o = qicp(&[
        "sim",
        park.to_str().expect("utf-8"),
        "--max-scans",
        "120",
        "--out",
        sim.to_str().expect("utf-8"),
    ]);
    assert_success(&o, "sim");
    let config = dir.path().join("run.toml");
    std::fs::write(
        &config,
        "[source]\nlog = \"sim/sim.log\"\ngroundtruth = \"sim/groundtruth.tum\"\n\n\
         [run]\nmatchers = [\"wsm\", \"q-wsm\"]\n",
    )
    .expect("config written");
    let out = |name: &str| dir.path().join(name);
    let o = qicp(&[
        "run",
        config.to_str().expect("utf-8"),
        "--out",
        out("file").to_str().expect("utf-8"),
        "--quiet",
    ]);
    assert_success(&o, "run on the log file");
    // The same log through a pipe is held in memory: the held and streamed paths must agree.
    let log = std::fs::read(sim.join("sim.log")).expect("log");
    let o = run_on_pipe(&config, &out("pipe"), &log);
    assert_success(&o, "run on a pipe");
    let (file, pipe) = (
        json(&out("file").join("summary.json")),
        json(&out("pipe").join("summary.json")),
    );
    assert_eq!(file["ratios"], pipe["ratios"], "ratios");
    for kind in ["wsm", "q-wsm"] {
        let ate = &file["matchers"][kind]["ate_rmse_m"];
        assert!(ate.as_f64().is_some_and(f64::is_finite), "{kind}: {ate}");
        assert_eq!(ate, &pipe["matchers"][kind]["ate_rmse_m"], "{kind}: held");
        let o = qicp(&[
            "eval",
            "ate",
            out("file")
                .join(kind)
                .join("trajectory.tum")
                .to_str()
                .expect("utf-8"),
            sim.join("groundtruth.tum").to_str().expect("utf-8"),
            "--json",
        ]);
        assert_success(&o, "eval ate");
        let eval: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
        let (a, b) = (
            ate.as_f64().unwrap_or(f64::NAN),
            eval["ate_rmse_m"].as_f64().unwrap_or(f64::NAN),
        );
        assert!((a - b).abs() < 1e-9, "{kind}: run {a}, eval {b}");
    }
}
