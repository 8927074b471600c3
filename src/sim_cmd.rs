//! `qicp sim CONFIG --out DIR`: simulate a drive and write what a real robot run would give,
//! plus the ground truth:
//!
//! - `sim.log`: CARMEN log (`PARAM`, `ODOM`, `FLASER`, `TRUEPOS`);
//! - `groundtruth.tum`, `odometry.tum`: trajectories at the laser times (TUM format);
//! - `world.png`: obstacles black, true path green, odometry red, start blue, 10 m grid grey;
//! - `summary.json`: the drive's figures (path length, odometry drift, laser returns, timing);
//! - `config.toml`: the effective configuration.

use crate::matching::OutputFile;
use anyhow::{Context, Result};
use qicp_core::Pose2;
use qicp_sim::{DriveScores, SimConfig, Simulation, render};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::logs::{carmen::write_carmen, tum::write_tum};

/// Arguments of `qicp sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// The drive's TOML configuration, e.g. `configs/worlds/park.toml`, or an experiment
    /// configuration with a `sim` source (e.g. `configs/park.toml`): its drive is simulated,
    /// with the source's seeds and length.
    pub config: PathBuf,
    /// Output directory (created if missing); not with --publish.
    #[arg(long, required_unless_present = "publish", conflicts_with = "publish")]
    pub out: Option<PathBuf>,
    /// Override `[drive] seed` (laser and encoder noise).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Override `[world] seed`: a park's layout (where its trees, rocks and benches stand),
    /// as `qicp run --worlds` numbers its worlds. The corridor's layout follows from its
    /// dimensions alone.
    #[arg(long)]
    pub world_seed: Option<u64>,
    /// Override `[drive] max_scans`: stop after this many scans.
    #[arg(long)]
    pub max_scans: Option<usize>,
    /// Publish the scans through the iceoryx2 bridge instead of writing files.
    #[command(flatten)]
    pub bridge: crate::bridge_cmd::PublishArgs,
}

/// Runs the command.
pub fn run(a: SimArgs) -> Result<()> {
    let mut cfg = load_drive(&a.config)?;
    if let Some(seed) = a.seed {
        cfg.drive.seed = seed;
    }
    if let Some(seed) = a.world_seed {
        cfg.world.seed = seed;
    }
    if a.max_scans.is_some() {
        cfg.drive.max_scans = a.max_scans;
    }
    cfg.validate()?;
    if a.bridge.publish {
        let beams = cfg.laser.beams;
        let sim = Simulation::new(cfg)?.map(|r| r.map_err(anyhow::Error::from));
        let report = crate::bridge_cmd::publish_records(sim, beams, &a.bridge)?;
        return crate::bridge_cmd::print_publish_report(&report);
    }
    let out = a.out.clone().context("--out is required")?;
    crate::matching::remove_on_signal()?;
    let started = Instant::now();
    // The world is built (and refused when it cannot be) before the directory is made.
    let mut sim = Simulation::new(cfg.clone())?;
    let made = crate::matching::CreatedDir::create(&out)?;
    let progress = progress_spinner();
    let mut records = Vec::new();
    for r in sim.by_ref() {
        records.push(r?);
        if records.len() % 20 == 0 {
            progress.set_message(format!("{} scans", records.len()));
            progress.tick();
        }
    }
    progress.finish_and_clear();
    let wall_seconds = started.elapsed().as_secs_f64();
    let stats = sim.stats();
    let scores = DriveScores::of(&records);

    let truth: Vec<(f64, Pose2)> = records
        .iter()
        .filter_map(|r| r.truth.map(|t| (r.timestamp(), t)))
        .collect();
    let odometry: Vec<(f64, Pose2)> = records
        .iter()
        .map(|r| (r.timestamp(), r.odometry))
        .collect();
    write_file(&out.join("sim.log"), |w| write_carmen(w, &records))?;
    write_file(&out.join("groundtruth.tum"), |w| write_tum(w, &truth))?;
    write_file(&out.join("odometry.tum"), |w| write_tum(w, &odometry))?;
    let truth_poses: Vec<Pose2> = truth.iter().map(|p| p.1).collect();
    let odom_poses: Vec<Pose2> = odometry.iter().map(|p| p.1).collect();
    write_file(&out.join("world.png"), |w| {
        render::write_png(w, sim.world(), &truth_poses, &odom_poses)
    })?;
    let effective = cfg.to_toml_string()?;
    write_file(&out.join("config.toml"), |w| {
        w.write_all(effective.as_bytes())
    })?;

    let summary = serde_json::json!({
        "world": cfg.world.kind.name(),
        "config": a.config.display().to_string(),
        "scans": records.len(),
        "beams": cfg.laser.beams,
        "fov_deg": cfg.laser.fov_deg,
        "max_range_m": cfg.laser.max_range,
        "rate_hz": cfg.laser.rate_hz,
        "path_length_m": scores.path_length_m,
        "odometry_final_error_m": scores.odometry_final_error_m,
        "odometry_ate_m": scores.odometry_ate_m,
        "loop_gap_m": scores.loop_gap_m,
        "returns_fraction": scores.returns_fraction,
        "route_completed": stats.route_completed,
        "contact_steps": stats.contact_steps,
        "min_clearance_m": stats.min_clearance_m,
        "physics_steps": stats.steps,
        "sim_seconds": stats.sim_seconds,
        "wall_seconds": wall_seconds,
        "realtime_factor": stats.sim_seconds / wall_seconds.max(1e-9),
        "world_seed": cfg.world.seed,
        "noise_seed": cfg.drive.seed,
        "digest": format!("{:016x}", qicp_sim::digest(&records)),
        "world_png": render::LEGEND,
    });
    write_file(&out.join("summary.json"), |mut w| {
        serde_json::to_writer_pretty(&mut w, &summary)?;
        writeln!(w)
    })?;
    made.keep();
    qicp_core::say!("{}", serde_json::to_string_pretty(&summary)?)?;
    Ok(())
}

/// The drive a configuration describes: a drive configuration, or an experiment's `sim`
/// source (told apart by the experiment's `[source]` table).
fn load_drive(path: &Path) -> Result<SimConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let is_experiment = toml::from_str::<toml::Table>(&text)
        .map(|t| t.contains_key("source"))
        .unwrap_or(false);
    if !is_experiment {
        return SimConfig::load(path).with_context(|| format!("drive {}", path.display()));
    }
    let experiment = crate::experiment::ExperimentConfig::load(path, crate::registry())
        .with_context(|| format!("experiment {}", path.display()))?;
    let Some(sim) = &experiment.source.sim else {
        anyhow::bail!(
            "{}: an experiment whose source is a log, not a drive to simulate",
            path.display()
        );
    };
    experiment.source.drive(sim)
}

/// Writes `path` under a temporary name and renames it into place when complete.
fn write_file(
    path: &Path,
    write: impl FnOnce(&mut OutputFile) -> std::io::Result<()>,
) -> Result<()> {
    let mut w = OutputFile::create(path)?;
    write(&mut w).with_context(|| format!("writing {}", path.display()))?;
    w.commit()
}

/// A spinner on stderr when it is a terminal; hidden otherwise (logs, CI, tests).
fn progress_spinner() -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_message("simulating");
    bar
}
