//! A Python process reads qicp's scans and poses: `bridge/examples/subscriber.py` (iceoryx2
//! from PyPI, same version as the crate) next to `qicp match --subscribe`, fed by
//! `qicp sim --publish`.
//!
//! Python: `$QICP_PYTHON`, else `target/bridge-venv/bin/python` (what `.ci/run` creates).
//! Without a Python that imports iceoryx2 the test fails under `CI=true` and is skipped,
//! loudly, elsewhere.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const QICP: &str = env!("CARGO_BIN_EXE_qicp");
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

impl Killed {
    fn output(mut self, timeout: Duration, name: &str) -> (bool, String, String) {
        use std::io::Read;
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.0.try_wait().expect("try_wait") {
                let (mut out, mut err) = (String::new(), String::new());
                if let Some(mut s) = self.0.stdout.take() {
                    let _ = s.read_to_string(&mut out);
                }
                if let Some(mut s) = self.0.stderr.take() {
                    let _ = s.read_to_string(&mut err);
                }
                return (status.success(), out, err);
            }
            assert!(Instant::now() < deadline, "{name} hung (> {timeout:?})");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

fn spawn(program: &Path, args: &[&str]) -> Killed {
    Killed(
        Command::new(program)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("spawning {}: {e}", program.display())),
    )
}

fn python() -> Option<PathBuf> {
    let candidates = std::env::var_os("QICP_PYTHON")
        .map(PathBuf::from)
        .into_iter()
        .chain([Path::new(ROOT).join("target/bridge-venv/bin/python")]);
    for python in candidates {
        let ok = Command::new(&python)
            .args(["-c", "import iceoryx2"])
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            return Some(python);
        }
    }
    None
}

#[test]
fn python_subscriber_reads_scans_and_poses() {
    let Some(python) = python() else {
        let msg = "Python with iceoryx2 not found (set QICP_PYTHON or run .ci/run, which creates \
                   target/bridge-venv)";
        assert!(std::env::var("CI").as_deref() != Ok("true"), "{msg}");
        eprintln!("SKIPPED python_subscriber_reads_scans_and_poses: {msg}");
        return;
    };
    let prefix = format!("qicp-py-{}", std::process::id());
    let out = std::env::temp_dir().join(format!("{prefix}-match"));
    let _ = std::fs::remove_dir_all(&out);
    let script = Path::new(ROOT).join("bridge/examples/subscriber.py");
    let py = spawn(
        &python,
        &[&script.to_string_lossy(), &prefix, "--timeout", "30"],
    );
    let matcher = spawn(
        Path::new(QICP),
        &[
            "match",
            "--subscribe",
            "--matcher",
            "q-idc",
            "--service-prefix",
            &prefix,
            "--out",
            &out.to_string_lossy(),
        ],
    );
    let park = Path::new(ROOT).join("configs/worlds/park.toml");
    let publisher = spawn(
        Path::new(QICP),
        &[
            "sim",
            &park.to_string_lossy(),
            "--publish",
            "--max-scans",
            "30",
            "--wait-subscribers",
            "2",
            "--service-prefix",
            &prefix,
        ],
    );
    let t = Duration::from_secs(90);
    let (ok, _, err) = publisher.output(t, "publisher");
    assert!(ok, "publisher: {err}");
    let (ok, _, err) = matcher.output(t, "matcher");
    assert!(ok, "matcher: {err}");
    let (ok, pout, perr) = py.output(t, "python subscriber");
    assert!(ok, "python subscriber: {pout}\n{perr}");
    let s: serde_json::Value = serde_json::from_str(pout.trim()).expect("python summary");
    assert_eq!(s["scans"], 30, "{s}");
    assert_eq!(s["beams"], 181, "{s}");
    assert_eq!(s["truth_poses"], 30, "{s}");
    assert_eq!(s["poses"], 30, "{s}");
    assert_eq!(s["scan_missing"], 0);
    assert_eq!(s["pose_missing"], 0);
    assert!(
        s["range_sum"]
            .as_f64()
            .is_some_and(|v| v > 0.0 && v.is_finite())
    );

    // The last pose Python read is the matcher's last trajectory line.
    let tum = std::fs::read_to_string(out.join("trajectory.tum")).expect("trajectory");
    let last: Vec<f64> = tum
        .lines()
        .last()
        .expect("a pose")
        .split_whitespace()
        .map(|v| v.parse().expect("number"))
        .collect();
    let pose = &s["last_pose"];
    assert_eq!(pose["scan_seq"], 29);
    // Every message names its publisher: the pose names the scan's.
    assert!(s["scan_publisher"].as_u64().is_some_and(|p| p > 0), "{s}");
    assert_eq!(pose["scan_publisher"], s["scan_publisher"], "{s}");
    assert!(pose["publisher"].as_u64().is_some_and(|p| p > 0), "{s}");
    let close = |a: f64, b: &serde_json::Value| (a - b.as_f64().expect("number")).abs() < 1e-9;
    assert!(
        close(last[1], &pose["x"]) && close(last[2], &pose["y"]),
        "{pose} vs {last:?}"
    );
}
