//! The bridge end to end: `qicp sim --publish` and `qicp match --subscribe` as separate
//! processes. Each test uses its own service prefix (so tests run in parallel), every wait
//! has a timeout, and children are killed if a test fails.

mod bridge_procs;

use bridge_procs::{
    PARK, Proc, T, bridge_u64, prefix, publisher_report, simulator, subscriber, summary, tempdir,
};
use qicp::matching::{Matching, write_run};
use qicp_matchers::{MatcherConfig, MatcherKind};
use std::path::Path;
use std::time::{Duration, Instant};

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

#[test]
fn two_processes_reproduce_the_in_process_trajectory_in_either_start_order() {
    let dir = tempdir("same");
    let scans = 150;
    in_process(scans, MatcherKind::QWsm, &dir.join("inproc"));
    for (order, subscriber_first) in [("sub-first", true), ("pub-first", false)] {
        let p = prefix(order);
        let out = dir.join(order);
        let start_subscriber = || subscriber("q-wsm", &p, &out, &[]);
        let start_publisher = || simulator("publisher", &p, scans, &[]);
        let (sub, publ) = if subscriber_first {
            let s = start_subscriber();
            std::thread::sleep(Duration::from_millis(300));
            (s, start_publisher())
        } else {
            let pb = start_publisher();
            std::thread::sleep(Duration::from_millis(300));
            (start_subscriber(), pb)
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
    let publ = simulator(
        "publisher",
        &p,
        40,
        &["--rate", "10x", "--wait-subscribers", "0"],
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
    let mut publ = simulator("publisher", &p, 200, &["--rate", "20x"]);
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
    let mut first = simulator("publisher 1", &p, 200, &["--rate", "20x"]);
    std::thread::sleep(Duration::from_millis(1200));
    first.kill();
    std::thread::sleep(Duration::from_millis(500));
    let second = simulator("publisher 2", &p, 25, &[]);
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
