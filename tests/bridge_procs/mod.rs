//! What the bridge's end-to-end tests share: `qicp` child processes killed when dropped, a
//! service prefix and a scratch directory per test, and the reports they read.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

pub const QICP: &str = env!("CARGO_BIN_EXE_qicp");
pub const PARK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/worlds/park.toml");

/// A child process killed when dropped (a failing test leaves nothing running).
pub struct Proc {
    pub child: Child,
    pub name: &'static str,
}

impl Proc {
    pub fn spawn(name: &'static str, args: &[&str]) -> Self {
        let child = Command::new(QICP)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("spawning {name}: {e}"));
        Self { child, name }
    }

    /// Waits up to `timeout` for the exit; panics (killing it) on timeout.
    pub fn wait(mut self, timeout: Duration) -> (ExitStatus, String, String) {
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

    pub fn kill(&mut self) {
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

pub fn prefix(test: &str) -> String {
    format!("qicp-it-{}-{test}", std::process::id())
}

pub fn tempdir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-bridge-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

pub fn summary(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary JSON")
}

pub fn bridge_u64(s: &serde_json::Value, key: &str) -> u64 {
    s["bridge"][key]
        .as_u64()
        .unwrap_or_else(|| panic!("bridge.{key} missing in {s}"))
}

pub fn publisher_report(out: &str) -> serde_json::Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("publisher report {out:?}: {e}"))
}

/// How long a bridge process may take before a test calls it hung.
pub const T: Duration = Duration::from_secs(120);

/// `qicp match --subscribe --matcher idc` on prefix `p`, writing to `out`.
pub fn matcher(p: &str, out: &Path, extra: &[&str]) -> Proc {
    subscriber("idc", p, out, extra)
}

/// `qicp match --subscribe --matcher kind` on prefix `p`, writing to `out`.
pub fn subscriber(kind: &str, p: &str, out: &Path, extra: &[&str]) -> Proc {
    let out = out.to_string_lossy().to_string();
    let mut args = vec![
        "match",
        "--subscribe",
        "--matcher",
        kind,
        "--service-prefix",
        p,
        "--out",
        &out,
    ];
    args.extend_from_slice(extra);
    Proc::spawn("subscriber", &args)
}

/// `qicp sim PARK --publish --max-scans n` on prefix `p`.
pub fn simulator(name: &'static str, p: &str, scans: usize, extra: &[&str]) -> Proc {
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
