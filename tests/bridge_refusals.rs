//! Bad timing options and a log whose time jumps: a clear error naming the option or the
//! scan, never a panic (issue 14: `--connect-timeout inf`, `--linger inf`, `--block-timeout
//! inf`, `--rate 1e-300x` and a realtime replay across a 1e20 s jump all panicked in
//! `Duration::from_secs_f64`, exit 101).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const QICP: &str = env!("CARGO_BIN_EXE_qicp");
const PARK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/worlds/park.toml");

fn qicp(args: &[&str]) -> Output {
    Command::new(QICP)
        .args(args)
        .output()
        .expect("the qicp binary runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Refused by the argument parser (exit 2), naming the option, no panic.
fn assert_refused_option(args: &[&str], option: &str) {
    let out = qicp(args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{args:?} not refused: {err}");
    assert!(
        err.contains(option),
        "{args:?}: the error names no {option}: {err}"
    );
    assert!(!err.contains("panicked"), "{args:?}: {err}");
}

fn prefix(test: &str) -> String {
    format!("qicp-refusal-{}-{test}", std::process::id())
}

fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-refusal-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

#[test]
fn infinite_connect_timeout_is_refused_not_a_panic() {
    let p = prefix("connect");
    assert_refused_option(
        &[
            "sim",
            PARK,
            "--publish",
            "--service-prefix",
            &p,
            "--connect-timeout",
            "inf",
        ],
        "--connect-timeout",
    );
    assert_refused_option(
        &[
            "match",
            "--subscribe",
            "--service-prefix",
            &p,
            "--connect-timeout",
            "inf",
        ],
        "--connect-timeout",
    );
}

#[test]
fn infinite_linger_is_refused_not_a_panic() {
    assert_refused_option(&["sim", PARK, "--publish", "--linger", "inf"], "--linger");
}

#[test]
fn infinite_block_timeout_is_refused_not_a_panic() {
    assert_refused_option(
        &["sim", PARK, "--publish", "--block-timeout", "inf"],
        "--block-timeout",
    );
}

#[test]
fn vanishing_rate_factor_is_refused_not_a_panic() {
    for rate in ["1e-300x", "0x", "-2x", "infx", "NaNx", "1e300x"] {
        let arg = format!("--rate={rate}");
        assert_refused_option(&["sim", PARK, "--publish", &arg], "--rate");
    }
}

/// Every timing option: finite, above 0, at most a day.
#[test]
fn every_timing_option_refuses_inf_nan_zero_negative_and_beyond_a_day() {
    let publisher = ["--connect-timeout", "--linger", "--block-timeout"];
    let subscriber = ["--connect-timeout", "--reconnect-timeout", "--idle-timeout"];
    for bad in ["inf", "-inf", "NaN", "0", "-1", "86401", "1e300", "ten"] {
        for option in publisher {
            let arg = format!("{option}={bad}");
            assert_refused_option(&["sim", PARK, "--publish", &arg], option);
        }
        for option in subscriber {
            let arg = format!("{option}={bad}");
            assert_refused_option(&["match", "--subscribe", &arg], option);
        }
    }
}

/// A CARMEN log of three scans at `times`.
fn log_at(dir: &Path, times: &[f64]) -> PathBuf {
    let mut text = String::new();
    for (i, t) in times.iter().enumerate() {
        let ranges = vec!["2.0"; 181].join(" ");
        let x = i as f64 * 0.1;
        text.push_str(&format!(
            "FLASER 181 {ranges} {x} 0 0 {x} 0 0 {t} host {t}\n"
        ));
    }
    let path = dir.join("jump.clf");
    std::fs::write(&path, text).expect("log");
    path
}

#[test]
fn realtime_replay_across_a_1e20_s_time_jump_is_refused_naming_the_scan() {
    let dir = scratch("jump");
    let log = log_at(&dir, &[0.0, 0.2, 1e20]);
    let p = prefix("jump");
    let out = qicp(&[
        "replay",
        &log.to_string_lossy(),
        "--publish",
        "--rate",
        "realtime",
        "--wait-subscribers",
        "0",
        "--service-prefix",
        &p,
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("scan 2"), "the error names no scan: {err}");
    assert!(
        err.contains("--rate max"),
        "the error suggests no way out: {err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_iceoryx2_config_is_refused_naming_the_file() {
    let p = prefix("noconfig");
    let out = qicp(&[
        "sim",
        PARK,
        "--publish",
        "--service-prefix",
        &p,
        "--iceoryx2-config",
        "/nonexistent/qicp-iceoryx2.toml",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("/nonexistent/qicp-iceoryx2.toml"), "{err}");
}

/// Issue 14: `qicp bench bridge-park` wrote through a link planted in its scratch directory
/// (another user's file was overwritten). A given scratch must be new or empty, and never a
/// link.
#[test]
fn bench_park_refuses_a_scratch_dir_with_a_planted_link_and_spares_its_target() {
    let dir = scratch("park-link");
    let victim = dir.join("victim.tum");
    std::fs::write(&victim, "precious\n").expect("victim");
    let planted = dir.join("scratch");
    std::fs::create_dir(&planted).expect("scratch");
    std::fs::create_dir(planted.join("two-process")).expect("run dir");
    std::os::unix::fs::symlink(&victim, planted.join("two-process/trajectory.tum")).expect("link");
    let out = qicp(&[
        "bench",
        "bridge-park",
        PARK,
        "--runs",
        "1",
        "--scratch",
        &planted.to_string_lossy(),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("not empty"), "{err}");
    assert_eq!(
        std::fs::read_to_string(&victim).expect("victim"),
        "precious\n"
    );

    let linked = dir.join("linked-scratch");
    std::os::unix::fs::symlink(&dir, &linked).expect("link");
    let out = qicp(&[
        "bench",
        "bridge-park",
        PARK,
        "--scratch",
        &linked.to_string_lossy(),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("symbolic link"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
