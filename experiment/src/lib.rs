//! # qicp-experiment
//!
//! Experiments, as `qicp run CONFIG` runs them: simulate (or load) a drive, run every
//! matcher over the same records, concurrently, score them, write the results and draw the
//! paper's figures. Matcher names resolve in the [`Registry`] the caller gives (`qicp` gives
//! its own: the built-ins and PL-ICP).
//!
//! An experiment file:
//!
//! ```toml
//! [source]
//! sim = "worlds/park.toml"     # a drive config (relative to this file), or:
//! # log = "../../shared/data/intel/intel.clf.bz2"   # a CARMEN log (plain or .bz2) or a ROS 2
//! #                            # bag (MCAP): scan_topic = "/scan", odom_topic = "/odom" or
//! #                            # odom_frame = "odom" with base_frame = "base_link"
//! # relations = "../../shared/data/intel/intel.relations"  # Freiburg relations (log only)
//! # groundtruth = "truth.tum"  # TUM file or CARMEN log with TRUEPOS (log only)
//! # max_scans = 100            # only the first scans (default: all)
//! # seed = 3                   # override the drive's noise seed (sim only)
//! # world_seed = 8             # override the world's layout seed (sim only)
//! # lenient = false            # skip and count malformed log lines (log only)
//!
//! [run]
//! matchers = ["idc", "q-idc", "wsm", "q-wsm", "kd-wsm"]   # the default
//!
//! [matchers.q-wsm]             # optional, per kind: a [matcher] table without `kind`
//! icp = { max_iterations = 30 }
//! ```
//!
//! Outputs in `--out DIR` (default `out/<config stem>`):
//!
//! - `summary.json`: per matcher ATE/RPE/final error (with ground truth), Freiburg relation
//!   errors (with relations), residual, certainty (m²) and position σ, timing, map size,
//!   fallbacks; the same for raw odometry; boosted/incremental ratios; the experiment's wall
//!   time;
//! - `<kind>/trajectory.tum`, `<kind>/matches.csv`, `<kind>/config.toml`;
//! - `groundtruth.tum` (when known), `odometry.tum`;
//! - `config.toml`: the effective experiment, every matcher's parameters spelled out (it runs
//!   again as is);
//! - `map_<kind>.png`, `trajectories.png`, `residual.png`, `certainty.png`.
//!
//! `summary.json` is written last and marks a complete run: one that fails after its source
//! was read keeps the files it completed (each written whole, under a temporary name first)
//! and has no `summary.json`.
//!
//! With `--worlds N` (a `sim` source) the experiment runs on N worlds: layout seeds
//! `world_seed`, `world_seed + 1`, … and noise seeds `seed`, `seed + 1`, … (defaults: the drive
//! config's), each in `DIR/world-<layout seed>/` without pictures; `DIR/worlds.json` and the
//! printed table give the median, minimum and maximum of every figure over the worlds. One
//! layout or one noise draw can be lucky or unlucky; the medians are what a method should be
//! judged by. (The plain corridor's layout is fixed, and there only the noise changes; the
//! office floors of `configs/worlds/office.toml` draw a layout from each seed.)
//!
//! A simulated drive is short and held in memory. A log is not: it is read once to count its
//! scans, once for raw odometry, once by every matcher as it matches (`stream`) and once more
//! for each matcher's map picture, so memory holds the matchers' maps, not the log (see
//! `stream` for the little that grows with the scans).

#![warn(missing_docs)]

use anyhow::{Context, Result};
use qicp_core::{Pose2, Record};
use qicp_eval::{AteOptions, AteReport, RelationsReport, evaluate_ate, evaluate_relations};
use qicp_io::carmen::CarmenOptions;
use qicp_io::relations::{Relation, read_relations};
use qicp_io::tum::{Stamped, write_tum};
use qicp_matchers::{MatcherConfig, Registry};
use qicp_plots::{self as plots, Panel, PathSeries, ScanSeries};
use qicp_runner::matching::{MatchSummary, ScanRow, run_matcher, write_atomic, write_run};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod config;
mod pictures;
mod source;
mod stream;
mod summary;
mod worlds;

pub use config::*;
use pictures::{draw_pictures, write_trajectory};
pub use source::*;
pub use summary::*;
use worlds::run_worlds;

/// The matchers an experiment runs when `[run] matchers` is not given.
pub const DEFAULT_MATCHERS: [&str; 5] = ["idc", "q-idc", "wsm", "q-wsm", "kd-wsm"];

/// What `qicp run` is given: the experiment and how to run it (with the `clap` feature, its
/// command-line arguments).
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct RunArgs {
    /// The experiment's TOML file, e.g. `configs/park.toml`.
    pub config: PathBuf,
    /// Output directory (created if missing). Default `out/<config stem>`.
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: Option<PathBuf>,
    /// Print summary.json on stdout (instead of the table).
    #[cfg_attr(feature = "clap", arg(long))]
    pub json: bool,
    /// Print nothing but errors.
    #[cfg_attr(feature = "clap", arg(long))]
    pub quiet: bool,
    /// Use this CARMEN log instead of the config's source (relations and ground truth of the
    /// config are kept).
    #[cfg_attr(feature = "clap", arg(long))]
    pub log: Option<PathBuf>,
    /// Override `[source] max_scans`.
    #[cfg_attr(feature = "clap", arg(long))]
    pub max_scans: Option<usize>,
    /// Repeat the experiment on this many simulated worlds (layout and noise seeds from the
    /// config's upwards) and report medians; at most 10,000.
    #[cfg_attr(feature = "clap", arg(long, value_name = "N"))]
    pub worlds: Option<usize>,
    /// Matchers run at once, one per thread (default: every core). Results do not depend on
    /// it; only the per-scan times do, as matchers share the machine.
    #[cfg_attr(feature = "clap", arg(long, value_name = "N"))]
    pub jobs: Option<std::num::NonZeroUsize>,
}

/// Runs every matcher of `config` on `source`, `jobs` at a time (each matcher on one thread,
/// taking the next from the list as it finishes), and writes each one's outputs under `out`.
/// The outcomes come back in the list's order; each matcher is deterministic, so they are the
/// same for any `jobs`. On a log source each matcher streams the log itself (and, with
/// `pictures`, gathers its map picture's bounds), so memory holds `jobs` maps, not the log.
fn run_matchers(
    config: &ExperimentConfig,
    registry: &Registry,
    source: &Source,
    out: &Path,
    jobs: usize,
    show_progress: bool,
    pictures: bool,
) -> Result<Vec<MatcherOutcome>> {
    let kinds = &config.run.matchers;
    let one = |kind: &String, progress: bool| -> Result<MatcherOutcome> {
        let t = Instant::now();
        let matcher = config.matcher(kind, registry)?;
        let dir = out.join(kind);
        let Records::Held(records) = &source.records else {
            return stream::run_streamed(source, &matcher, &dir, progress, pictures);
        };
        let run = run_matcher(records, &matcher, progress)?;
        write_run(&dir, &run, &matcher)?;
        let scores =
            Scores::of(&run.trajectory, source).with_context(|| format!("scoring {kind}"))?;
        let mut per_scan = PerScan::default();
        for row in &run.rows {
            per_scan.push(row);
        }
        Ok(MatcherOutcome {
            config: matcher,
            trajectory: Some(run.trajectory),
            trajectory_file: dir.join("trajectory.tum"),
            per_scan,
            summary: run.summary,
            scores,
            seconds: t.elapsed().as_secs_f64(),
            extent: None,
        })
    };
    let jobs = jobs.clamp(1, kinds.len().max(1));
    if jobs == 1 {
        return kinds.iter().map(|k| one(k, show_progress)).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<Result<MatcherOutcome>>>> =
        kinds.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..jobs {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(kind) = kinds.get(i) else { break };
                    let result = one(kind, false);
                    if show_progress {
                        match &result {
                            Ok(o) => {
                                qicp_core::note!(
                                    "{kind}: {} scans in {:.1} s",
                                    o.summary.scans,
                                    o.seconds
                                )
                            }
                            Err(e) => qicp_core::note!("{kind}: failed: {e:#}"),
                        }
                    }
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(result);
                    }
                }
            });
        }
    });
    slots
        .into_iter()
        .zip(kinds)
        .map(|(slot, kind)| {
            slot.into_inner().ok().flatten().unwrap_or_else(|| {
                Err(anyhow::anyhow!("{kind}: its thread ended without a result"))
            })
        })
        .collect()
}

/// Runs the command.
pub fn run(args: &RunArgs, registry: &Registry) -> Result<()> {
    qicp_runner::matching::remove_on_signal()?;
    let started = Instant::now();
    let mut config = ExperimentConfig::load(&args.config, registry)
        .with_context(|| format!("experiment {}", args.config.display()))?;
    if let Some(log) = &args.log {
        config.source.sim = None;
        config.source.seed = None;
        config.source.log = Some(
            std::fs::canonicalize(log)
                .or_else(|_| std::path::absolute(log))
                .unwrap_or_else(|_| log.clone()),
        );
    }
    if args.max_scans.is_some() {
        config.source.max_scans = args.max_scans;
    }
    config.validate(registry)?;
    let out = args.out.clone().unwrap_or_else(|| {
        let stem = args
            .config
            .file_stem()
            .map_or("experiment".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("out").join(stem)
    });
    if let Some(n) = args.worlds {
        return run_worlds(args, registry, &config, &out, n, started);
    }
    let summary = run_once(args, registry, &config, &out, true, started)?;
    if args.json {
        qicp_core::say!("{}", serde_json::to_string_pretty(&summary)?)?;
    } else if !args.quiet {
        qicp_core::say!("{}", table(&summary, &config.run.matchers))?;
        qicp_core::say!("outputs in {}", out.display())?;
    }
    Ok(())
}

/// One experiment into `out`: its records, every matcher, the scores, the pictures (when
/// `pictures`) and `summary.json`, which it returns.
fn run_once(
    args: &RunArgs,
    registry: &Registry,
    config: &ExperimentConfig,
    out: &Path,
    pictures: bool,
    started: Instant,
) -> Result<ExperimentSummary> {
    let t = Instant::now();
    // The source is read (a missing file or bad relations refused) before anything is written.
    let source = Source::load(&config.source)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_atomic(
        &out.join("config.toml"),
        config.effective_toml(registry)?.as_bytes(),
    )?;
    let odometry_path = out.join("odometry.tum");
    let odometry_scores = match source.odometry() {
        Some(odometry) => {
            write_trajectory(&odometry_path, &odometry)?;
            Scores::of(&odometry, &source)?
        }
        None => stream::odometry_pass(&source, &odometry_path)?,
    };
    let source_seconds = t.elapsed().as_secs_f64();
    if let Some(truth) = &source.truth {
        write_trajectory(&out.join("groundtruth.tum"), truth)?;
    }

    let t = Instant::now();
    let jobs = args
        .jobs
        .or_else(|| std::thread::available_parallelism().ok())
        .map_or(1, std::num::NonZeroUsize::get);
    let outcomes = run_matchers(config, registry, &source, out, jobs, !args.quiet, pictures)?;
    let matching_seconds = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let pictures = if pictures {
        draw_pictures(out, &source, &outcomes)?
    } else {
        BTreeMap::new()
    };
    let plot_seconds = t.elapsed().as_secs_f64();

    let summary = ExperimentSummary {
        source: source.name.clone(),
        config: args.config.display().to_string(),
        scans: source.scans(),
        ground_truth: source.truth.is_some(),
        matchers: outcomes.iter().map(|o| (o.kind(), o.figures())).collect(),
        odometry: odometry_scores.figures(),
        ratios: ratios(&outcomes),
        pictures,
        source_seconds,
        matching_seconds,
        plot_seconds,
        wall_seconds: started.elapsed().as_secs_f64(),
    };
    let text = serde_json::to_string_pretty(&summary)?;
    write_atomic(&out.join("summary.json"), format!("{text}\n").as_bytes())?;
    Ok(summary)
}

/// One line of a printed table: the first cell left-aligned, the others right-aligned, each
/// padded to its column's width.
fn table_line(cells: &[String], widths: &[usize]) -> String {
    cells
        .iter()
        .enumerate()
        .map(|(c, s)| {
            if c == 0 {
                format!("{s:<w$}", w = widths[c])
            } else {
                format!("{s:>w$}", w = widths[c])
            }
        })
        .collect::<Vec<_>>()
        .join("  ")
}

/// The table printed after a run.
fn table(summary: &ExperimentSummary, kinds: &[String]) -> String {
    let f = |v: Option<f64>, scale: f64, digits: usize| {
        v.filter(|x| x.is_finite())
            .map_or_else(|| "-".to_string(), |x| format!("{:.digits$}", x * scale))
    };
    let truth = summary.ground_truth;
    let relations = kinds.first().is_some_and(|k| {
        summary
            .matchers
            .get(k)
            .is_some_and(|m| m.scores.relations.is_some())
    });
    let mut head = vec!["matcher"];
    if truth {
        head.extend(["ATE m", "RPE %", "final m"]);
    }
    if relations {
        head.extend(["rel. trans m", "rel. rot °"]);
    }
    head.extend([
        "resid. mm",
        "certainty mm²",
        "σ mm",
        "ms/scan",
        "p99 ms",
        "map pts",
        "fallbacks",
    ]);
    let mut rows: Vec<Vec<String>> = Vec::new();
    let mut row_of = |name: &str, scores: &Scored, matched: Option<&MatcherFigures>| {
        let mut r = vec![name.to_string()];
        let t = scores.truth.as_ref();
        if truth {
            r.push(f(t.map(|t| t.ate_rmse_m), 1.0, 3));
            r.push(f(t.map(|t| t.rpe_trans_per_m), 100.0, 2));
            r.push(f(t.map(|t| t.final_error_m), 1.0, 3));
        }
        if relations {
            let rel = scores.relations.as_ref();
            r.push(f(rel.map(|r| r.trans_mean), 1.0, 3));
            r.push(f(rel.map(|r| r.rot_mean_deg), 1.0, 2));
        }
        if let Some(m) = matched {
            r.push(f(Some(m.residual_mean_mm), 1.0, 2));
            r.push(f(Some(m.certainty_mean), 1e6, 2));
            r.push(f(Some(m.sigma_mean_mm), 1.0, 2));
            r.push(f(Some(m.ms_per_scan_median), 1.0, 2));
            r.push(f(Some(m.ms_per_scan_p99), 1.0, 2));
            r.push(m.map_points.to_string());
            r.push(m.fallbacks.to_string());
        } else {
            r.extend(std::iter::repeat_n("-".to_string(), 7));
        }
        rows.push(r);
    };
    row_of("odometry", &summary.odometry, None);
    for k in kinds {
        if let Some(m) = summary.matchers.get(k) {
            row_of(k, &m.scores, Some(m));
        }
    }
    let widths: Vec<usize> = (0..head.len())
        .map(|c| {
            rows.iter()
                .map(|r| r[c].chars().count())
                .chain([head[c].chars().count()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let line = |cells: Vec<String>| table_line(&cells, &widths);
    let mut text = format!("{} — {} scans\n", summary.source, summary.scans);
    text += &line(head.iter().map(|s| (*s).to_string()).collect());
    text.push('\n');
    for r in rows {
        text += &line(r);
        text.push('\n');
    }
    if !summary.ratios.is_empty() {
        text += "\nboosted / incremental:";
        for (pair, r) in &summary.ratios {
            let parts: Vec<String> = [
                ("ate", r.ate),
                ("residual", Some(r.residual)),
                ("certainty", Some(r.certainty)),
                (
                    "certainty_per_scan_median",
                    Some(r.certainty_per_scan_median),
                ),
                ("sigma", Some(r.sigma)),
                ("relations_trans", r.relations_trans),
            ]
            .iter()
            .filter_map(|(k, v)| v.filter(|v| v.is_finite()).map(|v| format!("{k} {v:.3}")))
            .collect();
            text += &format!(
                "\n  {pair}: {} (means over the {} scans both matched)",
                parts.join(", "),
                r.scans_both_matched
            );
        }
        text.push('\n');
    }
    text += &format!(
        "\nwall time {:.2} s (source {:.2} s, matching {:.2} s, pictures {:.2} s)",
        summary.wall_seconds,
        summary.source_seconds,
        summary.matching_seconds,
        summary.plot_seconds,
    );
    text
}
