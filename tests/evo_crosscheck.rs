//! The ATE of `qicp run` against the field's standard evaluator: `evo_ape tum groundtruth.tum
//! <kind>/trajectory.tum --align_origin` (evo, Grupp 2017) must give the same RMSE within
//! 1 mm for every matcher and for raw odometry.
//!
//! `.ci/run` installs a pinned evo into a virtual environment and puts it on `PATH`. Without
//! evo the test is skipped with a loud message, unless `CI` is set: then it fails.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn evo_available() -> bool {
    Command::new("evo_ape")
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The `rmse` line of `evo_ape`'s statistics.
fn evo_rmse(truth: &Path, est: &Path) -> f64 {
    let o = Command::new("evo_ape")
        .arg("tum")
        .arg(truth)
        .arg(est)
        .arg("--align_origin")
        .output()
        .expect("runs evo_ape");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "evo_ape failed on {}: {stdout}{}",
        est.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
        .lines()
        .find_map(|l| {
            let mut words = l.split_whitespace();
            (words.next() == Some("rmse")).then(|| words.next()?.parse().ok())?
        })
        .unwrap_or_else(|| panic!("no rmse in evo_ape's output:\n{stdout}"))
}

#[test]
fn ate_agrees_with_evo_ape_within_a_millimetre() {
    if !evo_available() {
        assert!(
            std::env::var_os("CI").is_none(),
            "evo_ape is not on PATH under CI: .ci/run must install evo"
        );
        eprintln!(
            "\n\n!!! SKIPPED: evo_ape not found; `pip install evo` (or run .ci/run) to \
             cross-check the ATE against evo !!!\n"
        );
        return;
    }
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = std::env::temp_dir().join(format!("qicp-evo-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = Command::new(env!("CARGO_BIN_EXE_qicp"))
        .arg("run")
        .arg(repo.join("tests/fixtures/corridor_short.toml"))
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .expect("runs qicp");
    assert!(
        o.status.success(),
        "qicp run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("summary.json parses");
    let truth = out.join("groundtruth.tum");
    let mut checked = vec![(
        "odometry".to_string(),
        out.join("odometry.tum"),
        &summary["odometry"],
    )];
    for (kind, m) in summary["matchers"].as_object().expect("matchers") {
        checked.push((kind.clone(), out.join(kind).join("trajectory.tum"), m));
    }
    for (name, traj, m) in checked {
        let ours = m["ate_rmse_m"].as_f64().expect("ate_rmse_m");
        let evo = evo_rmse(&truth, &traj);
        println!("{name}: qicp {ours:.6} m, evo {evo:.6} m");
        assert!(
            (ours - evo).abs() < 1e-3,
            "{name}: qicp ATE {ours} m, evo_ape {evo} m"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}
