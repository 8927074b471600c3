//! A reader that goes away ends nothing badly: results written to a stdout whose reader has
//! closed it end the command quietly (exit 0, as ripgrep does), and progress written to a
//! closed stderr is dropped while the work goes on. Reads `../shared/data/intel/` (never
//! copied).

mod intel_data;

use intel_data::data;
use std::process::{Child, Command, Stdio};

/// `qicp ARGS` with both its stdout and its stderr read through pipes.
fn spawn_piped(args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs qicp")
}

/// `qicp matchers | true`: the reader is gone before qicp writes its listing.
#[test]
fn a_closed_stdout_ends_the_command_quietly() {
    let mut child = spawn_piped(&["matchers"]);
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("waits for qicp");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {stderr}", out.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// `qicp sweep … 2>&1 | head -1` with the JSON kept: the progress lines' reader is gone from
/// the start, and the sweep still finishes and reports.
#[test]
fn a_sweep_whose_progress_reader_went_away_still_reports() {
    let (log, relations) = (data("intel.clf.bz2"), data("intel.relations"));
    let mut child = spawn_piped(&[
        "sweep",
        &log,
        "--matcher",
        "q-wsm",
        "--scans",
        "300",
        "--variants",
        "beams/2",
        "--relations",
        &relations,
        "--json",
    ]);
    drop(child.stderr.take());
    let out = child.wait_with_output().expect("waits for qicp");
    assert!(out.status.success(), "{:?}", out.status);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(report["scans"], 300);
    let variants = report["variants"].as_array().expect("variants");
    assert_eq!(variants.len(), 1);
    assert!(variants[0].get("error").is_none(), "{report}");
}
