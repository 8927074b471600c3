//! `qicp match` on bad input: empty logs and unscored relations are errors, bad paths fail
//! before matching, a failed run leaves no partial output, and the streaming run gives the
//! trajectory of the in-memory one.

use qicp::logs::carmen::{CarmenOptions, read_carmen};
use qicp::logs::tum::write_tum;
use qicp::matching::run_matcher;
use qicp_matchers::{MatcherConfig, MatcherKind};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn qicp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(args)
        .output()
        .expect("runs qicp")
}

/// `qicp match LOG --matcher wsm --out OUT EXTRA…`.
fn match_wsm(log: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["match", s(log), "--matcher", "wsm", "--out", s(out)];
    args.extend_from_slice(extra);
    qicp(&args)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn scratch() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("qicp-match-reliability-")
        .tempdir()
        .expect("scratch dir")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// A `FLASER` line of 181 beams at 2 m at time `t`.
fn flaser(t: f64) -> String {
    let ranges = vec!["2.0"; 181].join(" ");
    format!("FLASER 181 {ranges} 0 0 0 0 0 0 {t} host {t}\n")
}

/// Writes `text` to `name` in `dir`.
fn file(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("writes fixture");
    path
}

/// A short simulated corridor drive (60 scans) as a CARMEN log.
fn corridor_log(dir: &Path) -> PathBuf {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/worlds/corridor.toml");
    let o = qicp(&["sim", config, "--out", s(dir), "--max-scans", "60"]);
    assert!(o.status.success(), "{}", stderr(&o));
    dir.join("sim.log")
}

#[test]
fn logs_without_laser_records_are_an_error() {
    let dir = scratch();
    for (name, text) in [
        ("empty.clf", String::new()),
        (
            "odom-only.clf",
            "ODOM 0 0 0 0 0 0 1.0 host 1.0\nODOM 1 0 0 0 0 0 2.0 host 2.0\n".to_string(),
        ),
        ("comments.clf", "# nothing but a comment\n".to_string()),
    ] {
        let log = file(dir.path(), name, &text);
        let out = dir.path().join(format!("out-{name}"));
        let o = match_wsm(&log, &out, &[]);
        assert!(!o.status.success(), "{name} accepted");
        assert!(
            stderr(&o).contains("no laser records"),
            "{name}: {}",
            stderr(&o)
        );
        assert!(
            !out.join("trajectory.tum").exists(),
            "{name}: output written"
        );
    }
}

#[test]
fn bad_out_fails_before_the_log_is_matched() {
    let dir = scratch();
    // The log is malformed at its end: an error about it would mean the log was read first.
    let log = file(
        dir.path(),
        "log.clf",
        &format!("{}{}FLASER 3 1\n", flaser(1.0), flaser(2.0)),
    );
    let blocker = file(dir.path(), "a-file", "");
    let out = blocker.join("out");
    let o = match_wsm(&log, &out, &[]);
    assert!(!o.status.success());
    let why = stderr(&o);
    assert!(why.contains(s(&out)) && !why.contains("log.clf"), "{why}");
}

#[test]
fn bad_relations_fail_before_the_log_is_matched() {
    let dir = scratch();
    let log = file(
        dir.path(),
        "log.clf",
        &format!("{}{}FLASER 3 1\n", flaser(1.0), flaser(2.0)),
    );
    let out = dir.path().join("out");
    let missing = dir.path().join("absent.relations");
    let o = match_wsm(&log, &out, &["--relations", s(&missing)]);
    assert!(!o.status.success());
    let why = stderr(&o);
    assert!(
        why.contains("absent.relations") && !why.contains("log.clf"),
        "{why}"
    );
}

#[test]
fn a_failed_run_leaves_no_partial_output() {
    let dir = scratch();
    let mut text = String::new();
    for i in 0..20 {
        text += &flaser(i as f64 * 0.1);
    }
    text += "FLASER 3 1\n";
    let log = file(dir.path(), "log.clf", &text);
    let out = dir.path().join("out");
    let o = match_wsm(&log, &out, &[]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("log.clf:21"), "{}", stderr(&o));
    // The directory the run made is gone too (it used to stay behind, empty)…
    assert!(!out.exists(), "an empty --out was left behind");
    // … and one that was there before stays, empty.
    std::fs::create_dir(&out).expect("out dir");
    let o = match_wsm(&log, &out, &[]);
    assert!(!o.status.success());
    let left: Vec<_> = std::fs::read_dir(&out)
        .expect("out dir")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn relations_outside_the_log_are_an_error() {
    let dir = scratch();
    let log = corridor_log(&dir.path().join("sim"));
    let relations = file(
        dir.path(),
        "far.relations",
        "1000000 1000001 0.1 0 0 0 0 0\n1000002 1000003 0.1 0 0 0 0 0\n",
    );
    let out = dir.path().join("out");
    let o = match_wsm(&log, &out, &["--relations", s(&relations)]);
    assert!(!o.status.success(), "no relation scored, yet exit 0");
    assert!(stderr(&o).contains("no relation of"), "{}", stderr(&o));
    // The run itself is complete and kept.
    assert!(out.join("trajectory.tum").exists());
}

#[test]
fn relations_that_all_lie_before_the_log_are_refused_before_matching() {
    let dir = scratch();
    let mut text = String::new();
    for i in 0..20 {
        text += &flaser(1000.0 + f64::from(i) * 0.1);
    }
    let log = file(dir.path(), "log.clf", &text);
    let relations = file(
        dir.path(),
        "early.relations",
        "10 11 0.1 0 0 0 0 0\n12 13 0.1 0 0 0 0 0\n",
    );
    let out = dir.path().join("out");
    let o = match_wsm(&log, &out, &["--relations", s(&relations)]);
    assert!(!o.status.success(), "relations of another log, yet exit 0");
    let err = stderr(&o);
    assert!(
        err.contains("early.relations") && err.contains("before"),
        "{err}"
    );
    // Nothing was matched, so nothing is written.
    assert!(!out.exists(), "outputs written for an unscorable run");
}

#[test]
fn iteration_counts_without_an_upper_bound_are_refused() {
    let dir = scratch();
    let config = file(
        dir.path(),
        "c.toml",
        "[matcher]\nkind = \"wsm\"\n[matcher.icp]\nmax_iterations = 4294967295\n",
    );
    let log = file(dir.path(), "log.clf", &flaser(1.0));
    let out = dir.path().join("out");
    let o = qicp(&["match", s(&log), "--config", s(&config), "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("max_iterations"), "{}", stderr(&o));
}

/// The streaming command and the in-memory loop are twins: same log, same trajectory.
#[test]
fn streaming_match_gives_the_in_memory_trajectory() {
    let dir = scratch();
    let log = corridor_log(&dir.path().join("sim"));
    let out = dir.path().join("out");
    let o = qicp(&["match", s(&log), "--matcher", "q-wsm", "--out", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));

    let records = read_carmen(&log, &CarmenOptions::default())
        .expect("log")
        .records;
    let mut config = MatcherConfig::defaults(MatcherKind::QWsm);
    config.fill_defaults();
    let run = run_matcher(&records, &config, false).expect("run");
    let mut expected = Vec::new();
    write_tum(&mut expected, &run.trajectory).expect("TUM");
    let streamed = std::fs::read(out.join("trajectory.tum")).expect("trajectory");
    assert_eq!(streamed, expected);
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary"))
            .expect("JSON");
    assert_eq!(summary["scans"], records.len());
    assert_eq!(summary["map_points"], run.summary.map_points);
}

#[test]
fn eval_relations_with_none_inside_the_trajectory_is_an_error() {
    let dir = scratch();
    let traj = file(
        dir.path(),
        "t.tum",
        "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n3.0 2 0 0 0 0 0 1\n",
    );
    let relations = file(dir.path(), "far.relations", "500 501 1 0 0 0 0 0\n");
    let o = qicp(&["eval", "relations", s(&traj), s(&relations), "--json"]);
    assert!(!o.status.success(), "n = 0 yet exit 0");
    assert!(stderr(&o).contains("no relation of"), "{}", stderr(&o));
    // The figures still go to stdout, with n = 0 for all to see.
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(v["n"], 0);
    // The table form prints no table of NaNs above the error.
    let o = qicp(&["eval", "relations", s(&traj), s(&relations)]);
    assert!(!o.status.success(), "n = 0 yet exit 0");
    assert!(
        o.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}

#[test]
fn eval_ate_of_a_trajectory_with_repeated_times_against_itself_is_zero() {
    let dir = scratch();
    let mut text = String::new();
    for i in 0..40 {
        text += &format!("{} {} {} 0 0 0 0 1\n", i / 4, i, i % 3);
    }
    let traj = file(dir.path(), "t.tum", &text);
    let o = qicp(&["eval", "ate", s(&traj), s(&traj), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(v["ate_max_m"], 0.0);
}

#[test]
fn scans_above_max_beams_are_refused_at_once() {
    let dir = scratch();
    let log = file(dir.path(), "wide.clf", &flaser(1.0));
    let out = dir.path().join("out");
    let o = match_wsm(&log, &out, &["--max-beams", "100"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("181 readings announced"),
        "{}",
        stderr(&o)
    );
    let o = match_wsm(&log, &out, &["--max-beams", "0"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("max_beams"), "{}", stderr(&o));
}

#[test]
fn subscriber_with_a_bad_out_fails_before_it_waits_for_scans() {
    let dir = scratch();
    let blocker = file(dir.path(), "a-file", "");
    let out = blocker.join("out");
    let prefix = format!("qicp-bad-out-{}", std::process::id());
    let o = qicp(&[
        "match",
        "--subscribe",
        "--matcher",
        "wsm",
        "--out",
        s(&out),
        "--service-prefix",
        &prefix,
        "--connect-timeout",
        "3",
    ]);
    assert!(!o.status.success());
    let why = stderr(&o);
    assert!(why.contains(s(&out)) && !why.contains("publisher"), "{why}");
}

#[test]
fn replaying_a_log_without_laser_records_is_an_error() {
    let dir = scratch();
    let log = file(
        dir.path(),
        "odom-only.clf",
        "ODOM 0 0 0 0 0 0 1.0 host 1.0\n",
    );
    let prefix = format!("qicp-empty-replay-{}", std::process::id());
    let o = qicp(&["replay", s(&log), "--publish", "--service-prefix", &prefix]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no laser records"), "{}", stderr(&o));
}

/// Starts `qicp ARGS`, waits until `dir` holds `files` hidden temporary files, sends it
/// `signal` (by name, through `kill`) and returns what is left in `dir` with how it ended.
fn stop_when_writing(
    args: &[&str],
    dir: &Path,
    files: usize,
    signal: &str,
) -> (Vec<String>, Option<i32>) {
    stop_when_writing_ignoring(&[], args, dir, files, signal)
}

/// [`stop_when_writing`] with the signals `ignored` (by name) inherited as ignored, as `nohup`
/// or a shell's background job leaves them: each is sent first, and the run must go on.
fn stop_when_writing_ignoring(
    ignored: &[&str],
    args: &[&str],
    dir: &Path,
    files: usize,
    signal: &str,
) -> (Vec<String>, Option<i32>) {
    use std::os::unix::process::ExitStatusExt;
    let qicp = env!("CARGO_BIN_EXE_qicp");
    let mut command = if ignored.is_empty() {
        Command::new(qicp)
    } else {
        // The shell sets them to ignored and becomes qicp (same process).
        let mut sh = Command::new("sh");
        sh.arg("-c")
            .arg(format!("trap '' {}; exec \"$0\" \"$@\"", ignored.join(" ")))
            .arg(qicp);
        sh
    };
    let mut child = command
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("runs qicp");
    let kill = |signal: &str, pid: u32| {
        let sent = Command::new("kill")
            .args([&format!("-{signal}"), &pid.to_string()])
            .status()
            .expect("kill");
        assert!(sent.success());
    };
    let listing = || -> Vec<String> {
        std::fs::read_dir(dir)
            .map(|d| {
                d.map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default()
    };
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while listing().iter().filter(|n| n.starts_with('.')).count() < files {
        assert!(
            std::time::Instant::now() < deadline,
            "no temporary files: {:?}",
            listing()
        );
        assert!(
            child.try_wait().expect("status").is_none(),
            "qicp ended before the signal"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    for s in ignored {
        kill(s, child.id());
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert!(
            child.try_wait().expect("status").is_none(),
            "qicp ended on SIG{s}, which it inherited as ignored"
        );
    }
    kill(signal, child.id());
    let status = child.wait().expect("status");
    (listing(), status.signal())
}

/// Whether this test process inherited `signal` as ignored (its children inherit it too, and
/// qicp keeps it ignored): Linux's `SigIgn` mask of `/proc/self/status`.
fn inherited_as_ignored(signal: i32) -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let mask = status.lines().find_map(|l| l.strip_prefix("SigIgn:"))?;
            u64::from_str_radix(mask.trim(), 16).ok()
        })
        .is_some_and(|mask| mask & (1 << (signal - 1)) != 0)
}

/// Before the fix a run stopped by SIGTERM or SIGINT left `.trajectory.tum.XXXXXX` and
/// `.matches.csv.XXXXXX` behind (a signal ends the process without running drops).
#[test]
fn a_run_stopped_by_a_signal_leaves_no_temporary_file() {
    let dir = scratch();
    let out = dir.path().join("out");
    let intel = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/intel/intel.clf.bz2");
    let args = ["match", s(&intel), "--matcher", "wsm", "--out", s(&out)];
    let (left, signal) = stop_when_writing(&args, &out, 2, "TERM");
    assert_eq!(
        signal,
        Some(15),
        "ended by the signal, as without the clean-up"
    );
    assert!(left.is_empty(), "left behind: {left:?}");

    // The sweep writes its runs' trajectories from worker threads.
    let relations = intel.with_extension("").with_extension("relations");
    let trajectories = dir.path().join("trajectories");
    let args = [
        "sweep",
        s(&intel),
        "--matcher",
        "wsm",
        "--relations",
        s(&relations),
        "--trajectories",
        s(&trajectories),
        "--jobs",
        "2",
    ];
    // SIGINT, as Ctrl-C sends it, unless this process inherited it as ignored (a shell's
    // background job), which qicp then ignores too: SIGHUP, else SIGTERM.
    let (name, number) = [("INT", 2), ("HUP", 1), ("TERM", 15)]
        .into_iter()
        .find(|(_, n)| !inherited_as_ignored(*n))
        .expect("a signal this process may be stopped by");
    let (left, signal) = stop_when_writing(&args, &trajectories, 2, name);
    assert_eq!(signal, Some(number));
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Under `nohup` (SIGHUP ignored) or as a shell's background job (SIGINT ignored) a run must
/// not die of those signals because qicp watches for them to remove its temporary files.
#[test]
fn signals_inherited_as_ignored_stay_ignored() {
    let dir = scratch();
    let out = dir.path().join("out");
    let intel = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/intel/intel.clf.bz2");
    let args = ["match", s(&intel), "--matcher", "wsm", "--out", s(&out)];
    let (left, signal) = stop_when_writing_ignoring(&["HUP", "INT"], &args, &out, 2, "TERM");
    assert_eq!(
        signal,
        Some(15),
        "ended by SIGTERM, not by SIGHUP or SIGINT"
    );
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// The times of `trajectory.tum`'s poses, in the file's order.
fn trajectory_times(out: &Path) -> Vec<f64> {
    std::fs::read_to_string(out.join("trajectory.tum"))
        .expect("trajectory written")
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            l.split_whitespace()
                .next()
                .and_then(|t| t.parse().ok())
                .expect("a time")
        })
        .collect()
}

#[test]
fn match_keeps_file_order_unless_told_to_sort_by_time() {
    let dir = scratch();
    let log = file(
        dir.path(),
        "jitter.clf",
        &[1.0, 1.2, 1.6, 1.4, 1.8, 2.0]
            .iter()
            .map(|&t| flaser(t))
            .collect::<String>(),
    );
    let (in_file, by_time) = (dir.path().join("file"), dir.path().join("time"));
    let o = match_wsm(&log, &in_file, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("1 laser lines of") && stderr(&o).contains("matched in file order"),
        "{}",
        stderr(&o)
    );
    let summary = std::fs::read_to_string(in_file.join("summary.json")).expect("summary");
    assert!(summary.contains("\"out_of_order_lines\": 1"), "{summary}");
    assert_eq!(trajectory_times(&in_file), [1.0, 1.2, 1.6, 1.4, 1.8, 2.0]);
    let o = match_wsm(&log, &by_time, &["--order", "time"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(trajectory_times(&by_time), [1.0, 1.2, 1.4, 1.6, 1.8, 2.0]);
    let o = match_wsm(&log, &dir.path().join("bad"), &["--order", "sideways"]);
    assert!(!o.status.success());
}

/// `qicp convert LOG LOG` used to replace the log with the bag made from it, and `match
/// --out-mcap LOG` or a log named `matches.csv` inside `--out` likewise: an output that is
/// the input (by any path or link) is refused before anything is written.
#[test]
fn outputs_that_are_the_input_log_are_refused_and_the_log_survives() {
    let dir = scratch();
    let text: String = (0..5).map(|k| flaser(f64::from(k))).collect();
    let log = file(dir.path(), "in.clf", &text);
    let link = dir.path().join("link.clf");
    std::os::unix::fs::symlink(&log, &link).expect("symlink");
    let out = dir.path().join("out");
    std::fs::create_dir(&out).expect("out dir");
    let inside = file(&out, "matches.csv", &text);
    for args in [
        vec!["convert", s(&log), s(&log)],
        vec!["convert", s(&log), s(&link)],
        vec![
            "match",
            s(&link),
            "--matcher",
            "wsm",
            "--out",
            s(&out),
            "--out-mcap",
            s(&log),
        ],
        vec!["match", s(&inside), "--matcher", "wsm", "--out", s(&out)],
    ] {
        let o = qicp(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(
            stderr(&o).contains("refusing to overwrite"),
            "{}",
            stderr(&o)
        );
    }
    assert_eq!(std::fs::read_to_string(&log).expect("log"), text);
    assert_eq!(std::fs::read_to_string(&inside).expect("log"), text);
    assert!(!out.join("trajectory.tum").exists());
}

/// A log whose ranges are all 0 (no returns) used to put every point at the laser, and q-wsm
/// then held the robot where it started, with a tiny residual and no fallback, while
/// odometry drove it 0.5 m: now every scan falls back, the trajectory follows odometry, and
/// the run warns that it is mostly odometry.
#[test]
fn zero_ranges_follow_odometry_and_a_run_of_fallbacks_is_warned_about() {
    let dir = scratch();
    let zeros = vec!["0"; 181].join(" ");
    let text: String = (0..6)
        .map(|k| {
            let (t, x) = (f64::from(k), 0.1 * f64::from(k));
            format!("FLASER 181 {zeros} {x} 0 0 {x} 0 0 {t} host {t}\n")
        })
        .collect();
    let log = file(dir.path(), "zeros.clf", &text);
    let out = dir.path().join("out");
    let o = qicp(&["match", s(&log), "--matcher", "q-wsm", "--out", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: 6 of 6 scans fell back to odometry"),
        "{}",
        stderr(&o)
    );
    let last = std::fs::read_to_string(out.join("trajectory.tum")).expect("trajectory");
    let x: f64 = last
        .lines()
        .last()
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .expect("a pose");
    assert!((x - 0.5).abs() < 1e-9, "the robot was held at x = {x}");
}

/// Records of a type qicp does not read (here a misspelt tag) are named in a note, not
/// dropped unseen.
#[test]
fn records_of_unknown_types_are_named_on_stderr() {
    let dir = scratch();
    let text = format!(
        "{}{}{}",
        flaser(1.0),
        flaser(2.0).replacen("FLASER", "FLASR", 1),
        flaser(3.0)
    );
    let log = file(dir.path(), "typo.clf", &text);
    let o = match_wsm(&log, &dir.path().join("out"), &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("of types qicp does not read: 1 FLASR"),
        "{}",
        stderr(&o)
    );
}

/// `eval ate` used to answer "no pose pairs within 0.1 s: do the trajectories share a time
/// base?" for an empty TUM file, a truth log without TRUEPOS, and a TUM file opening with a
/// byte-order mark (read as a CARMEN log); `eval relations` with an empty relations file
/// asked whether it was the trajectory's. Each now says what is wrong.
#[test]
fn eval_names_what_a_trajectory_or_relations_file_lacks() {
    let dir = scratch();
    let poses = "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n3.0 2 0 0 0 0 0 1\n";
    let traj = file(dir.path(), "t.tum", poses);
    let bom = file(dir.path(), "bom.tum", &format!("\u{feff}{poses}"));
    let empty = file(dir.path(), "empty.tum", "# no poses\n");
    let log = file(
        dir.path(),
        "no-truth.clf",
        &format!("{}{}", flaser(1.0), flaser(2.0)),
    );
    let no_relations = file(dir.path(), "empty.relations", "\n");
    for (args, expected) in [
        (vec!["eval", "ate", s(&traj), s(&empty)], "holds no poses"),
        (vec!["eval", "ate", s(&empty), s(&traj)], "holds no poses"),
        (vec!["eval", "ate", s(&traj), s(&log)], "no TRUEPOS record"),
        (
            vec!["eval", "relations", s(&traj), s(&no_relations)],
            "holds no relations",
        ),
    ] {
        let o = qicp(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expected), "{args:?}: {}", stderr(&o));
    }
    let o = qicp(&["eval", "ate", s(&bom), s(&traj), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(v["n"], 3);
    assert_eq!(v["ate_rmse_m"], 0.0);
}

#[test]
fn the_cause_of_an_unreadable_log_is_printed_once() {
    let dir = scratch();
    let missing = dir.path().join("absent.clf");
    let o = match_wsm(&missing, &dir.path().join("out"), &[]);
    assert!(!o.status.success());
    let err = stderr(&o);
    // The error's message held its cause and its chain held it again: printed twice.
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
    assert!(err.contains("absent.clf"), "{err}");
}

#[test]
fn log_only_options_are_refused_with_subscribe_not_ignored() {
    // They were accepted and did nothing: no relations scored, no bag written.
    for extra in [
        &["--relations", "r.relations"][..],
        &["--out-mcap", "out.mcap"],
        &["--lenient"],
        &["--order", "time"],
        &["--odom-frame", "odom"],
    ] {
        let mut args = vec!["match", "--subscribe", "--matcher", "wsm"];
        args.extend_from_slice(extra);
        let o = qicp(&args);
        assert!(!o.status.success(), "{extra:?} accepted");
        assert!(
            stderr(&o).contains("cannot be used with"),
            "{extra:?}: {}",
            stderr(&o)
        );
    }
}
