//! `qicp bench index --json` runs end to end, prints one JSON object with every documented key,
//! and all indexes agree on every nearest distance. Correctness only: no timing is asserted.

use serde_json::Value;
use std::process::Command;

fn bench_index(extra: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(["bench", "index", "--points", "5000", "--queries", "2000"])
        .args(extra)
        .args(["--json", "--reps", "1"])
        .output()
        .expect("the qicp binary runs");
    assert!(
        out.status.success(),
        "qicp bench index failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).expect("UTF-8 output");
    serde_json::from_str(stdout.trim()).expect("stdout is exactly one JSON object")
}

fn positive(v: &Value, path: &str) -> f64 {
    let x = v
        .pointer(path)
        .unwrap_or_else(|| panic!("missing key {path} in {v}"))
        .as_f64()
        .unwrap_or_else(|| panic!("{path} is not a number in {v}"));
    assert!(x.is_finite() && x > 0.0, "{path} = {x}");
    x
}

fn check_report(v: &Value, layout: &str) {
    assert_eq!(v["points"], 5000);
    assert_eq!(v["queries"], 2000);
    assert_eq!(v["layout"], layout);
    assert!(v["seed"].is_u64(), "seed missing in {v}");
    for index in ["quadtree", "kdtree", "brute"] {
        for key in ["build_ms", "insert_ns_per_point", "query_ns"] {
            positive(v, &format!("/indexes/{index}/{key}"));
        }
    }
    positive(v, "/scan_insert_us/quadtree");
    positive(v, "/scan_insert_us/kdtree");
    positive(v, "/query_ratio_quadtree_over_kdtree");
    assert_eq!(v["agree"], Value::Bool(true), "indexes disagree: {v}");
}

#[test]
fn bench_index_json_on_laser_scans_has_every_key_and_agrees() {
    let v = bench_index(&["--layout", "scans"]);
    check_report(&v, "scans");
}

#[test]
fn bench_index_json_on_uniform_points_agrees() {
    let v = bench_index(&["--layout", "uniform", "--seed", "3"]);
    check_report(&v, "uniform");
    assert_eq!(v["seed"], 3);
}

#[test]
fn brute_force_is_null_above_twenty_thousand_points() {
    let out = Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(["bench", "index", "--points", "20001", "--queries", "100"])
        .args(["--json", "--reps", "1"])
        .output()
        .expect("the qicp binary runs");
    assert!(out.status.success());
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert!(v["indexes"]["brute"].is_null(), "brute present: {v}");
    assert!(v["indexes"]["quadtree"].is_object());
    assert_eq!(v["agree"], Value::Bool(true));
}

fn bench_bridge(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(["bench", "bridge"])
        .args(args)
        .output()
        .expect("the qicp binary runs")
}

/// `qicp bench bridge --sizes … --json`: one entry per size, both transports with every
/// documented key. Shape only: the figures themselves are measured, not asserted.
#[test]
fn bench_bridge_sizes_json_has_every_key_per_size() {
    let out = bench_bridge(&[
        "--sizes",
        "2k,16k",
        "--messages",
        "20",
        "--burst",
        "60",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "qicp bench bridge --sizes failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).expect("stdout is one JSON object");
    let sizes = v["sizes"].as_array().expect("sizes");
    assert_eq!(sizes.len(), 2, "{v}");
    for (entry, bytes) in sizes.iter().zip([2048, 16384]) {
        assert_eq!(entry["bytes"], bytes, "{v}");
        assert_eq!(entry["messages"], 20, "{v}");
        assert_eq!(entry["burst"], 60, "{v}");
        for transport in ["iceoryx2", "uds"] {
            for key in ["p50_us", "p99_us", "msgs_per_s"] {
                positive(entry, &format!("/{transport}/{key}"));
            }
            let cpu = &entry[transport]["cpu_us_per_msg"];
            assert!(
                cpu.is_null() || cpu.as_f64().is_some_and(|c| c >= 0.0),
                "cpu_us_per_msg = {cpu} in {v}"
            );
        }
        positive(entry, "/p50_ratio");
    }
    assert_eq!(v["wait"], "event");
}

#[test]
fn bench_bridge_sizes_refuses_a_bad_size_and_beams() {
    for args in [
        &["--sizes", "0"][..],
        &["--sizes", "2x"],
        &["--sizes", "1g"],
        &["--sizes", "2k", "--beams", "181"],
    ] {
        let out = bench_bridge(args);
        assert_eq!(out.status.code(), Some(2), "{args:?} accepted");
    }
}

/// `--points 18446744073709551615` used to wrap the workload's size and panic (`mid > len`):
/// counts beyond the documented bounds are refused with an error, not a crash.
#[test]
fn bench_index_refuses_counts_that_overflowed_the_workload() {
    for args in [
        &["--points", "18446744073709551615"][..],
        &["--points", "50000001"],
        &["--queries", "18446744073709551615"],
        &["--reps", "1001"],
    ] {
        assert_count_refused("index", args, 1);
    }
}

#[test]
fn bench_bridge_refuses_counts_that_aborted_its_allocation() {
    // 10¹¹ beams aborted on an 800 GB allocation (exit 134); 0 messages was "empty bench".
    for args in [
        &["--beams", "100000000000"][..],
        &["--beams", "0"],
        &["--messages", "0"],
        &["--burst", "10000001"],
    ] {
        assert_count_refused("bridge", args, 2);
    }
}

/// `qicp bench BENCH ARGS` exits with `code` and names the option `args[0]`, without a panic.
fn assert_count_refused(bench: &str, args: &[&str], code: i32) {
    let out = Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(["bench", bench])
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("the qicp binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
    assert!(
        stderr.contains(&args[0][2..]) && !stderr.contains("panicked"),
        "{stderr}"
    );
}
