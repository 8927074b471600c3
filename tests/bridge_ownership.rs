//! One owner per bridge service, end to end: a second publisher or a second matcher on a
//! service is refused, a publisher whose only subscriber left fails, and iceoryx2's
//! configuration is the project's own. Separate processes, as in `bridge_cli.rs`.

mod bridge_procs;

use bridge_procs::{
    PARK, Proc, QICP, T, bridge_u64, matcher, prefix, publisher_report, simulator, summary, tempdir,
};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

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
