//! End to end: `qicp sim CONFIG --out DIR` on a short park drive writes every output file, a
//! summary with every key, and a CARMEN log the log reader reads back with the same scans.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-sim-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn sim(config: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_qicp"))
        .arg("sim")
        .arg(config)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("runs qicp")
}

#[test]
fn sim_writes_log_trajectories_picture_and_summary() {
    let out = out_dir("park");
    let o = sim(
        &repo().join("configs/worlds/park.toml"),
        &out,
        &["--max-scans", "25"],
    );
    assert!(
        o.status.success(),
        "qicp sim failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    for f in [
        "sim.log",
        "groundtruth.tum",
        "odometry.tum",
        "world.png",
        "summary.json",
        "config.toml",
    ] {
        let meta = std::fs::metadata(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(meta.len() > 0, "{f} is empty");
    }
    let png = std::fs::read(out.join("world.png")).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("read"))
            .expect("summary is JSON");
    for key in [
        "world",
        "scans",
        "beams",
        "fov_deg",
        "path_length_m",
        "odometry_final_error_m",
        "odometry_ate_m",
        "loop_gap_m",
        "returns_fraction",
        "sim_seconds",
        "wall_seconds",
    ] {
        assert!(summary.get(key).is_some(), "summary.json lacks {key}");
    }
    assert_eq!(summary["world"], "park");
    assert_eq!(summary["scans"], 25);
    assert_eq!(summary["beams"], 181);

    for tum in ["groundtruth.tum", "odometry.tum"] {
        let text = std::fs::read_to_string(out.join(tum)).expect("tum");
        let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
        assert_eq!(lines.len(), 25, "{tum}");
        assert!(
            lines.iter().all(|l| l.split_whitespace().count() == 8),
            "{tum}"
        );
    }

    // The log reads back: same number of scans, same beams, no-returns marked invalid.
    let log = qicp::logs::carmen::read_carmen(&out.join("sim.log"), &Default::default())
        .expect("the CARMEN reader reads the simulated log");
    assert_eq!(log.records.len(), 25);
    let first = &log.records[0];
    assert_eq!(first.scan.beams(), 181);
    assert!((first.scan.geometry.max_range - 20.0).abs() < 1e-9);
    let [valid, max_range, _, _] = first.scan.status_counts();
    assert!(
        valid > 0 && max_range > 0,
        "{valid} valid, {max_range} no-return"
    );
    assert!(first.truth.is_some(), "ground truth travels in the log");

    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn sim_refuses_a_bad_config_naming_the_key() {
    let out = out_dir("bad");
    std::fs::create_dir_all(&out).expect("dir");
    let cfg = out.join("bad.toml");
    std::fs::write(&cfg, "[laser]\nbeams = 0\n").expect("write");
    let o = sim(&cfg, &out.join("run"), &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("laser.beams"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

/// A park too crowded for its trees used to fail with an error naming no key, after making
/// an empty output directory.
#[test]
fn a_crowded_park_names_its_key_and_leaves_no_directory() {
    let out = out_dir("crowded");
    std::fs::create_dir_all(&out).expect("dir");
    let cfg = out.join("crowded.toml");
    std::fs::write(&cfg, "[world.park]\ntrees = 5000\n").expect("write");
    let o = sim(&cfg, &out.join("run"), &[]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("`world.park.trees`"), "{err}");
    assert!(
        !out.join("run").exists(),
        "an empty output directory was left"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn sim_takes_an_experiment_config_and_simulates_its_source() {
    let out = out_dir("experiment");
    let o = sim(
        &repo().join("configs/park.toml"),
        &out,
        &["--max-scans", "10"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary"))
            .expect("JSON");
    assert_eq!(summary["scans"], 10);
    assert_eq!(summary["world"], "park");
    // The same drive as the drive config itself.
    let direct = out_dir("experiment-direct");
    let o = sim(
        &repo().join("configs/worlds/park.toml"),
        &direct,
        &["--max-scans", "10"],
    );
    assert!(o.status.success());
    let direct: serde_json::Value =
        serde_json::from_slice(&std::fs::read(direct.join("summary.json")).expect("summary"))
            .expect("JSON");
    assert_eq!(summary["digest"], direct["digest"]);

    // An experiment on a log has nothing to simulate: said plainly.
    let o = sim(&repo().join("configs/intel.toml"), &out, &[]);
    assert!(!o.status.success());
    let why = String::from_utf8_lossy(&o.stderr);
    assert!(why.contains("source is a log"), "{why}");
}

#[test]
fn sim_world_seed_moves_the_parks_layout_and_nothing_else() {
    let park = repo().join("configs/worlds/park.toml");
    let run = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = out_dir(name);
        let o = sim(&park, &out, &[&["--max-scans", "10"], extra].concat());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let summary =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary"))
                .expect("JSON");
        let _ = std::fs::remove_dir_all(&out);
        summary
    };
    let seven = run("world-7", &[]);
    let stated = run("world-7-stated", &["--world-seed", "7"]);
    let eight = run("world-8", &["--world-seed", "8"]);
    assert_eq!(seven["world_seed"], 7);
    assert_eq!(
        stated["digest"], seven["digest"],
        "the config's own seed, stated"
    );
    assert_eq!(eight["world_seed"], 8);
    assert_eq!(eight["noise_seed"], seven["noise_seed"]);
    assert_ne!(
        eight["digest"], seven["digest"],
        "another park, other scans"
    );
}
