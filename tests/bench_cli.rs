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
