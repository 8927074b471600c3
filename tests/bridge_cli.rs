//! The bridge end to end: `qicp sim --publish` and `qicp match --subscribe` as separate
//! processes. Each test uses its own service prefix (so tests run in parallel), every wait
//! has a timeout, and children are killed if a test fails.

use qicp::matching::{Matching, write_run};
use qicp_matchers::{MatcherConfig, MatcherKind};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

const QICP: &str = env!("CARGO_BIN_EXE_qicp");
const PARK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/worlds/park.toml");

/// A child process killed when dropped (a failing test leaves nothing running).
struct Proc {
    child: Child,
    name: &'static str,
}

impl Proc {
    fn spawn(name: &'static str, args: &[&str]) -> Self {
        let child = Command::new(QICP)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("spawning {name}: {e}"));
        Self { child, name }
    }

    /// Waits up to `timeout` for the exit; panics (killing it) on timeout.
    fn wait(mut self, timeout: Duration) -> (ExitStatus, String, String) {
        let deadline = Instant::now() + timeout;
        loop {
            match self.child.try_wait().expect("try_wait") {
                Some(status) => {
                    use std::io::Read;
                    let mut out = String::new();
                    let mut err = String::new();
                    if let Some(mut s) = self.child.stdout.take() {
                        let _ = s.read_to_string(&mut out);
                    }
                    if let Some(mut s) = self.child.stderr.take() {
                        let _ = s.read_to_string(&mut err);
                    }
                    return (status, out, err);
                }
                None if Instant::now() > deadline => {
                    let _ = self.child.kill();
                    panic!("{} did not exit within {timeout:?} (hang)", self.name);
                }
                None => std::thread::sleep(Duration::from_millis(20)),
            }
        }
    }

    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.kill();
        }
    }
}

fn prefix(test: &str) -> String {
    format!("qicp-it-{}-{test}", std::process::id())
}

fn tempdir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-bridge-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn summary(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary JSON")
}

fn bridge_u64(s: &serde_json::Value, key: &str) -> u64 {
    s["bridge"][key]
        .as_u64()
        .unwrap_or_else(|| panic!("bridge.{key} missing in {s}"))
}

fn publisher_report(out: &str) -> serde_json::Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("publisher report {out:?}: {e}"))
}

/// The in-process run of the same drive and matcher, written like `qicp match`.
fn in_process(max_scans: usize, kind: MatcherKind, dir: &Path) {
    let mut cfg = qicp_sim::SimConfig::load(Path::new(PARK)).expect("park config");
    cfg.drive.max_scans = Some(max_scans);
    let (records, _, _) = qicp_sim::Simulation::run(cfg).expect("simulate");
    let mut config = MatcherConfig::defaults(kind);
    config.validate().expect("config");
    config.fill_defaults();
    let mut matching = Matching::new(&config).expect("matcher");
    for r in &records {
        matching.push(r);
    }
    write_run(dir, &matching.finish(), &config).expect("write run");
}

/// Drops the wall-time column (`ms`, 6th) of matches.csv: everything else must agree.
fn without_timing(csv: &str) -> String {
    csv.lines()
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            if f.len() > 5 {
                f.remove(5);
            }
            f.join(",")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn assert_same_run(a: &Path, b: &Path) {
    let read = |d: &Path, f: &str| std::fs::read_to_string(d.join(f)).expect(f);
    assert_eq!(
        read(a, "trajectory.tum"),
        read(b, "trajectory.tum"),
        "trajectories differ"
    );
    assert_eq!(
        without_timing(&read(a, "matches.csv")),
        without_timing(&read(b, "matches.csv")),
        "per-scan figures differ"
    );
}

const T: Duration = Duration::from_secs(120);

#[test]
fn two_processes_reproduce_the_in_process_trajectory_in_either_start_order() {
    let dir = tempdir("same");
    let scans = 150;
    in_process(scans, MatcherKind::QWsm, &dir.join("inproc"));
    let n = scans.to_string();
    for (order, subscriber_first) in [("sub-first", true), ("pub-first", false)] {
        let p = prefix(order);
        let out = dir.join(order);
        let sub_args = [
            "match",
            "--subscribe",
            "--matcher",
            "q-wsm",
            "--service-prefix",
            &p,
            "--out",
        ];
        let mut sub_args: Vec<&str> = sub_args.to_vec();
        let out_s = out.to_string_lossy().to_string();
        sub_args.push(&out_s);
        let pub_args = [
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            &n,
            "--service-prefix",
            &p,
        ];
        let (sub, publ) = if subscriber_first {
            let s = Proc::spawn("subscriber", &sub_args);
            std::thread::sleep(Duration::from_millis(300));
            (s, Proc::spawn("publisher", &pub_args))
        } else {
            let pb = Proc::spawn("publisher", &pub_args);
            std::thread::sleep(Duration::from_millis(300));
            (Proc::spawn("subscriber", &sub_args), pb)
        };
        let (ps, pout, perr) = publ.wait(T);
        assert!(ps.success(), "publisher failed: {perr}");
        let (ss, _, serr) = sub.wait(T);
        assert!(ss.success(), "subscriber failed: {serr}");
        let report = publisher_report(&pout);
        assert_eq!(report["published"], scans as u64);
        let s = summary(&out);
        assert_eq!(s["bridge"]["end"], "end_of_stream");
        assert_eq!(bridge_u64(&s, "received"), scans as u64);
        assert_eq!(bridge_u64(&s, "missing"), 0);
        assert_eq!(bridge_u64(&s, "poses_published"), scans as u64);
        assert_same_run(&dir.join("inproc"), &out);
    }
}

#[test]
fn late_subscriber_gets_the_history_it_asked_for() {
    let dir = tempdir("late");
    let p = prefix("late");
    // 40 scans at 10x the park's 1 Hz: 4 s; the subscriber joins after ~1.5 s.
    let publ = Proc::spawn(
        "publisher",
        &[
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            "40",
            "--rate",
            "10x",
            "--wait-subscribers",
            "0",
            "--service-prefix",
            &p,
        ],
    );
    std::thread::sleep(Duration::from_millis(1500));
    let out = dir.join("sub");
    let sub = Proc::spawn(
        "subscriber",
        &[
            "match",
            "--subscribe",
            "--matcher",
            "idc",
            "--history",
            "10",
            "--service-prefix",
            &p,
            "--out",
            &out.to_string_lossy(),
        ],
    );
    let (ps, _, perr) = publ.wait(T);
    assert!(ps.success(), "publisher: {perr}");
    let (ss, _, serr) = sub.wait(T);
    assert!(ss.success(), "subscriber: {serr}");
    let s = summary(&out);
    let received = bridge_u64(&s, "received");
    let missed = bridge_u64(&s, "missed_before_join");
    assert_eq!(s["bridge"]["end"], "end_of_stream");
    assert!(missed > 0, "joined late but missed nothing? {s}");
    assert!(received >= 10, "history of 10 not delivered: {s}");
    assert_eq!(received + missed, 40, "{s}");
    assert_eq!(bridge_u64(&s, "missing"), 0);
}

#[test]
fn killed_publisher_is_reported_and_the_subscriber_exits() {
    let dir = tempdir("killed");
    let p = prefix("killed");
    let out = dir.join("sub");
    let sub = Proc::spawn(
        "subscriber",
        &[
            "match",
            "--subscribe",
            "--matcher",
            "idc",
            "--reconnect-timeout",
            "1",
            "--service-prefix",
            &p,
            "--out",
            &out.to_string_lossy(),
        ],
    );
    let mut publ = Proc::spawn(
        "publisher",
        &[
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            "200",
            "--rate",
            "20x",
            "--service-prefix",
            &p,
        ],
    );
    std::thread::sleep(Duration::from_millis(1500));
    publ.kill(); // SIGKILL: no end marker, no goodbye
    let started = Instant::now();
    let (ss, _, serr) = sub.wait(Duration::from_secs(30));
    assert!(!ss.success(), "a lost publisher must fail the run: {serr}");
    assert!(serr.contains("publisher lost"), "{serr}");
    assert!(started.elapsed() < Duration::from_secs(15));
    let s = summary(&out);
    assert_eq!(s["bridge"]["end"], "publisher_lost");
    assert_eq!(bridge_u64(&s, "publishers_lost"), 1);
    let received = bridge_u64(&s, "received");
    assert!(received > 0 && received < 200, "{s}");
    assert_eq!(
        s["scans"].as_u64(),
        Some(received),
        "outputs cover what was received"
    );
}

#[test]
fn restarted_publisher_is_picked_up() {
    let dir = tempdir("restart");
    let p = prefix("restart");
    let out = dir.join("sub");
    let sub = Proc::spawn(
        "subscriber",
        &[
            "match",
            "--subscribe",
            "--matcher",
            "idc",
            "--reconnect-timeout",
            "20",
            "--service-prefix",
            &p,
            "--out",
            &out.to_string_lossy(),
        ],
    );
    let mut first = Proc::spawn(
        "publisher 1",
        &[
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            "200",
            "--rate",
            "20x",
            "--service-prefix",
            &p,
        ],
    );
    std::thread::sleep(Duration::from_millis(1200));
    first.kill();
    std::thread::sleep(Duration::from_millis(500));
    let second = Proc::spawn(
        "publisher 2",
        &[
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            "25",
            "--service-prefix",
            &p,
        ],
    );
    let (ps, _, perr) = second.wait(T);
    assert!(ps.success(), "second publisher: {perr}");
    let (ss, _, serr) = sub.wait(T);
    assert!(ss.success(), "subscriber: {serr}");
    let s = summary(&out);
    assert_eq!(s["bridge"]["end"], "end_of_stream");
    assert_eq!(bridge_u64(&s, "publishers_seen"), 2, "{s}");
    assert_eq!(bridge_u64(&s, "publishers_lost"), 1, "{s}");
    assert_eq!(bridge_u64(&s, "missing"), 0, "{s}");
    let received = bridge_u64(&s, "received");
    assert!(received > 25 && received < 225, "{s}");
}

/// A subscriber that takes 30 ms a scan, fed `scans` scans of the park drive.
fn slow_subscriber(mode: &str, scans: u32) -> (serde_json::Value, serde_json::Value) {
    let scans = scans.to_string();
    let dir = tempdir(mode);
    let p = prefix(mode);
    let out = dir.join("sub");
    let sub = Proc::spawn(
        "subscriber",
        &[
            "match",
            "--subscribe",
            "--matcher",
            "idc",
            "--buffer",
            "4",
            "--delay-ms",
            "30",
            "--backpressure",
            mode,
            "--service-prefix",
            &p,
            "--out",
            &out.to_string_lossy(),
        ],
    );
    let publ = Proc::spawn(
        "publisher",
        &[
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            &scans,
            // A scan every 4 ms (the drive's 1 Hz sped up 250×) against a subscriber that
            // takes 30 ms a scan: about 7 arrive per read into a 4-scan buffer. At full speed
            // the whole stream could be sent before the subscriber's first read, leaving
            // nothing to lose mid-stream.
            "--rate",
            "250x",
            "--backpressure",
            mode,
            "--wait-subscribers",
            "1",
            "--service-prefix",
            &p,
        ],
    );
    let (ps, pout, perr) = publ.wait(T);
    assert!(ps.success(), "publisher: {perr}");
    let (ss, _, serr) = sub.wait(T);
    assert!(ss.success(), "subscriber: {serr}");
    (publisher_report(&pout), summary(&out))
}

#[test]
fn slow_subscriber_in_block_mode_loses_nothing() {
    let (report, s) = slow_subscriber("block", 80);
    assert_eq!(s["bridge"]["backpressure"], "block");
    assert_eq!(bridge_u64(&s, "received"), 80, "{s}");
    assert_eq!(bridge_u64(&s, "missing"), 0);
    assert!(
        report["blocked_sends"].as_u64().unwrap_or(0) > 0,
        "the publisher never had to wait: {report}"
    );
}

#[test]
fn slow_subscriber_in_drop_oldest_mode_counts_what_it_lost() {
    // 1 s of stream: the subscriber still sets up its pose publisher and matcher after the
    // publisher starts, and must be reading well before the stream ends.
    let (_, s) = slow_subscriber("drop-oldest", 250);
    assert_eq!(s["bridge"]["backpressure"], "drop-oldest");
    assert_eq!(s["bridge"]["end"], "end_of_stream");
    let received = bridge_u64(&s, "received");
    let missing = bridge_u64(&s, "missing");
    // Scans dropped from the full buffer before the subscriber's first read are counted as
    // missed before it joined (it cannot tell the two apart; see bridge/README.md).
    let before_first = bridge_u64(&s, "missed_before_join");
    assert!(missing > 0 && bridge_u64(&s, "gap_events") > 0, "{s}");
    assert_eq!(
        received + missing + before_first,
        250,
        "every scan received or counted lost: {s}"
    );
    assert_eq!(bridge_u64(&s, "announced"), 250);
}

#[test]
fn subscriber_without_publisher_times_out() {
    let dir = tempdir("nobody");
    let p = prefix("nobody");
    let out = dir.join("sub");
    let sub = Proc::spawn(
        "subscriber",
        &[
            "match",
            "--subscribe",
            "--matcher",
            "idc",
            "--connect-timeout",
            "1",
            "--service-prefix",
            &p,
            "--out",
            &out.to_string_lossy(),
        ],
    );
    let (ss, _, serr) = sub.wait(Duration::from_secs(20));
    assert!(!ss.success());
    assert!(serr.contains("no_publisher"), "{serr}");
    assert_eq!(summary(&out)["bridge"]["end"], "no_publisher");
}

/// `qicp bench bridge-park`: both arms run, the trajectories agree, the JSON has its keys.
/// (The measurement itself: `qicp bench bridge-park --runs 9 --json`, see the README.)
#[test]
fn bench_bridge_park_runs_both_arms() {
    let dir = tempdir("bench-park");
    let run = Proc::spawn(
        "bench",
        &[
            "bench",
            "bridge-park",
            PARK,
            "--runs",
            "1",
            "--json",
            "--scratch",
            &dir.to_string_lossy(),
        ],
    );
    let (status, out, err) = run.wait(T);
    assert!(status.success(), "{err}");
    let report: serde_json::Value = serde_json::from_str(&out).expect("bench JSON");
    assert_eq!(report["identical"], true, "{report}");
    assert!(report["scans"].as_u64().unwrap_or(0) > 700, "{report}");
    for arm in ["in_process", "two_process"] {
        let median = report[arm]["median_s"].as_f64().expect("median");
        assert!(median > 0.0 && median < 60.0, "{report}");
        assert_eq!(report[arm]["runs_s"].as_array().map(Vec::len), Some(1));
    }
    assert!(
        report["ratio"].as_f64().is_some_and(|r| r > 0.0),
        "{report}"
    );
    assert!(dir.join("two-process/trajectory.tum").exists());
}

/// `qicp match --subscribe --matcher idc` on prefix `p`, writing to `out`.
fn matcher(p: &str, out: &Path, extra: &[&str]) -> Proc {
    let out = out.to_string_lossy().to_string();
    let mut args = vec![
        "match",
        "--subscribe",
        "--matcher",
        "idc",
        "--service-prefix",
        p,
        "--out",
        &out,
    ];
    args.extend_from_slice(extra);
    Proc::spawn("subscriber", &args)
}

/// `qicp sim PARK --publish --max-scans n` on prefix `p`.
fn simulator(name: &'static str, p: &str, scans: usize, extra: &[&str]) -> Proc {
    let n = scans.to_string();
    let mut args = vec![
        "sim",
        PARK,
        "--publish",
        "--max-scans",
        &n,
        "--service-prefix",
        p,
    ];
    args.extend_from_slice(extra);
    Proc::spawn(name, &args)
}

/// Issue 14: a second publisher on the same prefix mixed its scans into the stream (680 of
/// 784 poses from the intruder) and its end marker ended the subscriber's run.
#[test]
fn second_publisher_on_a_scan_service_is_refused_and_the_stream_stays_whole() {
    let dir = tempdir("second-pub");
    let p = prefix("second-pub");
    let out = dir.join("sub");
    let sub = matcher(&p, &out, &[]);
    // 60 scans at 20x the park's 1 Hz: 3 s, while the intruder tries its luck.
    let first = simulator("publisher 1", &p, 60, &["--rate", "20x"]);
    std::thread::sleep(Duration::from_millis(1500));
    let second = simulator("publisher 2", &p, 30, &["--wait-subscribers", "0"]);
    let (status, _, err) = second.wait(Duration::from_secs(30));
    assert_eq!(
        status.code(),
        Some(1),
        "the intruder was not refused: {err}"
    );
    assert!(err.contains("already publishes"), "{err}");
    let (status, pout, err) = first.wait(T);
    assert!(status.success(), "the owner: {err}");
    assert_eq!(publisher_report(&pout)["published"], 60);
    let (status, _, err) = sub.wait(T);
    assert!(status.success(), "subscriber: {err}");
    let s = summary(&out);
    assert_eq!(s["bridge"]["end"], "end_of_stream", "{s}");
    assert_eq!(bridge_u64(&s, "received"), 60, "{s}");
    assert_eq!(bridge_u64(&s, "publishers_seen"), 1, "{s}");
    assert_eq!(bridge_u64(&s, "intruders"), 0, "{s}");
    assert_eq!(bridge_u64(&s, "missing"), 0, "{s}");
    assert_eq!(bridge_u64(&s, "missed_before_join"), 0, "{s}");
}

/// Issue 14: two subscribers both published poses on one pose service without a word.
#[test]
fn second_matcher_on_a_pose_service_is_refused() {
    let dir = tempdir("second-sub");
    let p = prefix("second-sub");
    let first = matcher(&p, &dir.join("first"), &[]);
    std::thread::sleep(Duration::from_millis(1000));
    let second = matcher(&p, &dir.join("second"), &[]);
    let (status, _, err) = second.wait(Duration::from_secs(30));
    assert_eq!(status.code(), Some(1), "the second matcher ran: {err}");
    assert!(err.contains("already publishes"), "{err}");
    assert!(
        err.contains("--service-prefix"),
        "no way out offered: {err}"
    );
    // The first one is undisturbed.
    let publisher = simulator("publisher", &p, 20, &[]);
    let (status, _, err) = publisher.wait(T);
    assert!(status.success(), "publisher: {err}");
    let (status, _, err) = first.wait(T);
    assert!(status.success(), "first matcher: {err}");
    let s = summary(&dir.join("first"));
    assert_eq!(bridge_u64(&s, "received"), 20, "{s}");
    assert_eq!(bridge_u64(&s, "poses_published"), 20, "{s}");
}

/// Issue 14: the block-mode publisher whose only subscriber left published the rest into
/// nothing and exited 0.
#[test]
fn block_publisher_fails_when_its_only_subscriber_leaves() {
    let dir = tempdir("sub-left");
    let p = prefix("sub-left");
    let sub = matcher(&p, &dir.join("sub"), &[]);
    // 200 scans at 20x: 10 s; the subscriber is stopped after 1.5 s.
    let publisher = simulator("publisher", &p, 200, &["--rate", "20x"]);
    std::thread::sleep(Duration::from_millis(1500));
    let killed = Command::new("kill")
        .args(["-TERM", &sub.child.id().to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    let (status, _, err) = sub.wait(Duration::from_secs(30));
    assert!(
        status.success(),
        "an interrupted subscriber exits cleanly: {err}"
    );
    let started = Instant::now();
    let (status, _, err) = publisher.wait(Duration::from_secs(30));
    assert_eq!(
        status.code(),
        Some(1),
        "the publisher went on into nothing: {err}"
    );
    assert!(err.contains("every subscriber"), "{err}");
    assert!(started.elapsed() < Duration::from_secs(5), "noticed late");
}

/// Issue 14: iceoryx2 read `./config/iceoryx2.toml` from the working directory, so a
/// publisher started from a directory holding one never met a subscriber started elsewhere.
#[test]
fn iceoryx2_config_in_the_working_directory_is_ignored() {
    let dir = tempdir("cwd-config");
    let p = prefix("cwd-config");
    let (pub_dir, sub_dir) = (dir.join("pub"), dir.join("sub"));
    for (d, text) in [
        // Valid, and another world: other file prefix, other root.
        (
            &pub_dir,
            "[global]\nprefix = \"elsewhere_\"\nroot-path = \"/tmp/qicp-elsewhere/\"\n",
        ),
        // Not even TOML.
        (&sub_dir, "\u{0}\u{1}garbage [[[ = = ="),
    ] {
        std::fs::create_dir_all(d.join("config")).expect("dir");
        std::fs::write(d.join("config/iceoryx2.toml"), text).expect("config");
    }
    let out = dir.join("out");
    let out_s = out.to_string_lossy().to_string();
    let spawn_in = |name: &'static str, cwd: &Path, args: &[&str]| Proc {
        child: Command::new(QICP)
            .args(args)
            .current_dir(cwd)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn"),
        name,
    };
    let sub = spawn_in(
        "subscriber",
        &sub_dir,
        &[
            "match",
            "--subscribe",
            "--matcher",
            "idc",
            "--connect-timeout",
            "30",
            "--service-prefix",
            &p,
            "--out",
            &out_s,
        ],
    );
    let publisher = spawn_in(
        "publisher",
        &pub_dir,
        &[
            "sim",
            PARK,
            "--publish",
            "--max-scans",
            "10",
            "--connect-timeout",
            "30",
            "--service-prefix",
            &p,
        ],
    );
    let (status, _, err) = publisher.wait(T);
    assert!(status.success(), "publisher: {err}");
    let (status, _, err) = sub.wait(T);
    assert!(status.success(), "subscriber: {err}");
    assert_eq!(bridge_u64(&summary(&out), "received"), 10);
    assert!(
        !Path::new("/tmp/qicp-elsewhere").exists(),
        "the cwd config was read"
    );
}

/// `--iceoryx2-config FILE` is the explicit way to another iceoryx2 setting: both sides with
/// it meet; one without it does not.
#[test]
fn iceoryx2_config_option_is_used_by_both_sides() {
    let dir = tempdir("config-option");
    let config = dir.join("iceoryx2.toml");
    std::fs::write(
        &config,
        format!("[global]\nprefix = \"qicp_it_{}_\"\n", std::process::id()),
    )
    .expect("config");
    let config = config.to_string_lossy().to_string();
    let with = ["--iceoryx2-config", config.as_str()];
    let p = prefix("config-option");
    let out = dir.join("out");
    let sub = matcher(&p, &out, &with);
    let publisher = simulator("publisher", &p, 10, &with);
    let (status, _, err) = publisher.wait(T);
    assert!(status.success(), "publisher: {err}");
    let (status, _, err) = sub.wait(T);
    assert!(status.success(), "subscriber: {err}");
    assert_eq!(bridge_u64(&summary(&out), "received"), 10);

    // Without the option on one side, the two live in different iceoryx2 worlds.
    let p = prefix("config-option-apart");
    let quick = ["--connect-timeout", "2"];
    let sub = matcher(&p, &dir.join("apart"), &quick);
    let mut args = with.to_vec();
    args.extend_from_slice(&quick);
    let publisher = simulator("publisher", &p, 10, &args);
    let (status, _, err) = publisher.wait(T);
    assert!(
        !status.success(),
        "met a subscriber outside its configuration"
    );
    assert!(err.contains("no subscriber"), "{err}");
    let (status, _, _) = sub.wait(T);
    assert!(!status.success());
}
