//! `qicp run CONFIG`: one experiment end to end. Simulate (or load) a drive, run every
//! matcher over the same records, score them, write the results and draw the paper's figures.
//!
//! ```toml
//! [source]
//! sim = "worlds/park.toml"     # a drive config (relative to this file), or:
//! # log = "../../shared/data/intel/intel.clf.bz2"   # a CARMEN log (plain or .bz2)
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
//! With `--worlds N` (a `sim` source) the experiment runs on N worlds: layout seeds
//! `world_seed`, `world_seed + 1`, … and noise seeds `seed`, `seed + 1`, … (defaults: the drive
//! config's), each in `DIR/world-<layout seed>/` without pictures; `DIR/worlds.json` and the
//! printed table give the median, minimum and maximum of every figure over the worlds. One
//! layout or one noise draw can be lucky or unlucky; the medians are what a method should be
//! judged by. (The corridor's layout is fixed; there only the noise changes.)

use crate::eval::{
    AteOptions, AteReport, LogPoses, RelationsReport, evaluate_ate, evaluate_relations,
};
use crate::logs::carmen::{CarmenOptions, read_carmen};
use crate::logs::relations::{Relation, read_relations};
use crate::logs::tum::{Stamped, write_tum};
use crate::matching::{MatchSummary, ScanRow, run_matcher, write_atomic, write_run};
use crate::plots::{self, Panel, PathSeries, ScanSeries};
use anyhow::{Context, Result};
use qicp_core::{Pose2, Record};
use qicp_matchers::{MatcherConfig, ReferenceKind};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value, json};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
use thiserror::Error;

/// The matchers an experiment runs when `[run] matchers` is not given.
pub const DEFAULT_MATCHERS: [&str; 5] = ["idc", "q-idc", "wsm", "q-wsm", "kd-wsm"];

/// Arguments of `qicp run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The experiment's TOML file, e.g. `configs/park.toml`.
    pub config: PathBuf,
    /// Output directory (created if missing). Default `out/<config stem>`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print summary.json on stdout (instead of the table).
    #[arg(long)]
    pub json: bool,
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
    /// Use this CARMEN log instead of the config's source (relations and ground truth of the
    /// config are kept).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Override `[source] max_scans`.
    #[arg(long)]
    pub max_scans: Option<usize>,
    /// Repeat the experiment on this many simulated worlds (layout and noise seeds from the
    /// config's upwards) and report medians.
    #[arg(long, value_name = "N")]
    pub worlds: Option<usize>,
    /// Matchers run at once, one per thread (default: every core). Results do not depend on
    /// it; only the per-scan times do, as matchers share the machine.
    #[arg(long, value_name = "N")]
    pub jobs: Option<std::num::NonZeroUsize>,
}

// ---------------------------------------------------------------------------------------------
// Configuration

/// An experiment configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ExperimentError {
    /// The file cannot be read.
    #[error("reading {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The TOML does not parse or does not fit the schema (unknown key, wrong type…).
    #[error("{0}")]
    Parse(String),
    /// A value is missing, contradictory or out of range.
    #[error("`{key}`: {why}")]
    Invalid {
        /// Dotted path of the key.
        key: String,
        /// What is wrong.
        why: String,
    },
    /// A per-kind matcher table is not a valid matcher configuration.
    #[error("`matchers.{kind}`: {source}")]
    Matcher {
        /// The kind whose table is wrong.
        kind: String,
        /// What the matcher registry said.
        source: qicp_matchers::ConfigError,
    },
}

fn invalid(key: &str, why: impl Into<String>) -> ExperimentError {
    ExperimentError::Invalid {
        key: key.into(),
        why: why.into(),
    }
}

/// `[source]`: where the records come from. Exactly one of `sim` and `log`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// A drive configuration for the simulator (`configs/worlds/*.toml`). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim: Option<PathBuf>,
    /// A CARMEN log (plain or `.bz2`). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log: Option<PathBuf>,
    /// Freiburg benchmark relations of the log. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relations: Option<PathBuf>,
    /// Ground truth of the log: TUM file or CARMEN log with `TRUEPOS`. Default: the log's own
    /// `TRUEPOS` records, if every laser record has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub groundtruth: Option<PathBuf>,
    /// Only the first `max_scans` scans. Default: all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_scans: Option<usize>,
    /// Override the drive's `[drive] seed` (sim only). Default: the drive's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Override the world's `[world] seed`, its procedural layout (sim only). Default: the
    /// world's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_seed: Option<u64>,
    /// Skip and count malformed log lines instead of failing (log only). Default false.
    #[serde(default)]
    pub lenient: bool,
}

impl SourceConfig {
    /// The drive of a `sim` source at `sim`, with the source's seeds and length applied.
    pub fn drive(&self, sim: &Path) -> Result<qicp_sim::SimConfig> {
        let mut cfg = qicp_sim::SimConfig::load(sim)
            .with_context(|| format!("loading drive {}", sim.display()))?;
        if let Some(seed) = self.seed {
            cfg.drive.seed = seed;
        }
        if let Some(seed) = self.world_seed {
            cfg.world.seed = seed;
        }
        if self.max_scans.is_some() {
            cfg.drive.max_scans = self.max_scans;
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

/// `[run]`: what runs over the records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// Matcher kinds, in report order. Default [`DEFAULT_MATCHERS`].
    #[serde(default = "default_matchers")]
    pub matchers: Vec<String>,
}

fn default_matchers() -> Vec<String> {
    DEFAULT_MATCHERS.map(String::from).to_vec()
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            matchers: default_matchers(),
        }
    }
}

/// An experiment: a source, the matchers, per-kind parameter overrides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// Where the records come from.
    pub source: SourceConfig,
    /// What runs.
    #[serde(default)]
    pub run: RunConfig,
    /// Per-kind overrides: each a `[matcher]` table without `kind`. Default: none (every
    /// matcher with its registry defaults).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub matchers: BTreeMap<String, toml::Table>,
}

impl ExperimentConfig {
    /// Parses a TOML document and validates it. Relative paths stay as written; see
    /// [`ExperimentConfig::resolve`].
    pub fn from_toml(text: &str) -> Result<Self, ExperimentError> {
        let c: Self = toml::from_str(text).map_err(|e| ExperimentError::Parse(e.to_string()))?;
        c.validate()?;
        Ok(c)
    }

    /// Reads, validates and resolves a file: relative paths become relative to its directory.
    pub fn load(path: &Path) -> Result<Self, ExperimentError> {
        let text = std::fs::read_to_string(path).map_err(|e| ExperimentError::Io {
            path: path.display().to_string(),
            source: e,
        })?;
        let mut c = Self::from_toml(&text).map_err(|e| match e {
            ExperimentError::Parse(m) => ExperimentError::Parse(format!("{}: {m}", path.display())),
            other => other,
        })?;
        c.resolve(path.parent().unwrap_or(Path::new(".")));
        Ok(c)
    }

    /// Makes every relative source path relative to `base` instead, and absolute (so the
    /// effective config written elsewhere still finds them).
    pub fn resolve(&mut self, base: &Path) {
        let s = &mut self.source;
        for p in [&mut s.sim, &mut s.log, &mut s.relations, &mut s.groundtruth]
            .into_iter()
            .flatten()
        {
            let joined = base.join(&*p);
            *p = std::fs::canonicalize(&joined)
                .or_else(|_| std::path::absolute(&joined))
                .unwrap_or(joined);
        }
    }

    /// Checks the source, the matcher list and every per-kind table; names the bad key.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        let s = &self.source;
        match (&s.sim, &s.log) {
            (None, None) => {
                return Err(invalid(
                    "source",
                    "give `sim` (a drive) or `log` (a CARMEN log)",
                ));
            }
            (Some(_), Some(_)) => return Err(invalid("source", "give `sim` or `log`, not both")),
            (Some(_), None) => {
                for (key, set) in [
                    ("source.relations", s.relations.is_some()),
                    ("source.groundtruth", s.groundtruth.is_some()),
                    ("source.lenient", s.lenient),
                ] {
                    if set {
                        return Err(invalid(
                            key,
                            "only for a `log` source (a simulated drive has its own ground truth)",
                        ));
                    }
                }
            }
            (None, Some(_)) => {
                for (key, set) in [
                    ("source.seed", s.seed.is_some()),
                    ("source.world_seed", s.world_seed.is_some()),
                ] {
                    if set {
                        return Err(invalid(key, "only for a `sim` source"));
                    }
                }
            }
        }
        if s.max_scans == Some(0) {
            return Err(invalid(
                "source.max_scans",
                "is 0: nothing would be matched",
            ));
        }
        if self.run.matchers.is_empty() {
            return Err(invalid(
                "run.matchers",
                "is empty: name at least one matcher kind",
            ));
        }
        let mut seen = std::collections::BTreeSet::new();
        let registry = crate::registry();
        for k in &self.run.matchers {
            if !seen.insert(k) {
                return Err(invalid("run.matchers", format!("`{k}` is listed twice")));
            }
            registry.resolve(k).map_err(|_| {
                invalid(
                    "run.matchers",
                    format!(
                        "unknown matcher kind `{k}`; known: {}",
                        registry.names().join(", ")
                    ),
                )
            })?;
        }
        for kind in self.matchers.keys() {
            let name = kind;
            registry.resolve(kind).map_err(|_| {
                invalid(
                    &format!("matchers.{name}"),
                    format!(
                        "unknown matcher kind; known: {}",
                        registry.names().join(", ")
                    ),
                )
            })?;
            if !self.run.matchers.contains(kind) {
                return Err(invalid(
                    &format!("matchers.{name}"),
                    "parameters for a kind that `run.matchers` does not list",
                ));
            }
            self.matcher(kind)?;
        }
        Ok(())
    }

    /// The effective configuration of `kind`: its registry defaults, overridden by its
    /// `[matchers.<kind>]` table.
    pub fn matcher(&self, kind: &str) -> Result<MatcherConfig, ExperimentError> {
        let err = |source| ExperimentError::Matcher {
            kind: kind.into(),
            source,
        };
        let Some(table) = self.matchers.get(kind) else {
            return crate::registry().config(kind).map_err(err);
        };
        if table.contains_key("kind") {
            return Err(err(qicp_matchers::ConfigError::Invalid {
                key: "kind".into(),
                why: "the table's name is the kind; drop `kind`".into(),
            }));
        }
        let mut matcher = table.clone();
        matcher.insert("kind".into(), toml::Value::String(kind.into()));
        let mut doc = toml::Table::new();
        doc.insert("matcher".into(), toml::Value::Table(matcher));
        let text = toml::to_string(&doc).map_err(|e| ExperimentError::Parse(e.to_string()))?;
        crate::registry().parse(&text).map_err(err)
    }

    /// The effective configuration as TOML: the source and run as loaded (paths resolved) and
    /// every matcher's parameters spelled out under `[matchers.<kind>]`. It loads back as an
    /// experiment that runs the same.
    pub fn effective_toml(&self) -> Result<String, ExperimentError> {
        let mut c = self.clone();
        for kind in &self.run.matchers {
            let m = self.matcher(kind)?;
            let mut value = m.to_table().map_err(|source| ExperimentError::Matcher {
                kind: kind.clone(),
                source,
            })?;
            for axis in ["algorithm", "reference", "index"] {
                value.remove(axis);
            }
            c.matchers.insert(kind.clone(), value);
        }
        toml::to_string_pretty(&c).map_err(|e| ExperimentError::Parse(e.to_string()))
    }
}

// ---------------------------------------------------------------------------------------------
// Source

/// The records of an experiment, with whatever scores them.
#[derive(Debug)]
pub struct Source {
    /// What the records are (`sim:<path>` or `log:<path>`).
    pub name: String,
    /// Laser records in time order.
    pub records: Vec<Record>,
    /// True robot poses, where known.
    pub truth: Option<Vec<Stamped>>,
    /// Freiburg relations, where given.
    pub relations: Option<Vec<Relation>>,
}

impl Source {
    /// Simulates the drive or reads the log the config names.
    pub fn load(c: &SourceConfig) -> Result<Self> {
        let (name, mut records, mut truth) = if let Some(sim) = &c.sim {
            let cfg = c.drive(sim)?;
            let (records, _, _) = qicp_sim::Simulation::run(cfg)
                .with_context(|| format!("simulating {}", sim.display()))?;
            (format!("sim:{}", sim.display()), records, None)
        } else if let Some(log) = &c.log {
            let opts = CarmenOptions {
                lenient: c.lenient,
                ..CarmenOptions::default()
            };
            let read =
                read_carmen(log, &opts).with_context(|| format!("reading {}", log.display()))?;
            if read.info.skipped_lines > 0 {
                eprintln!(
                    "warning: skipped {} malformed lines of {}",
                    read.info.skipped_lines,
                    log.display()
                );
            }
            let truth = match &c.groundtruth {
                Some(p) => Some(
                    crate::eval::load_trajectory(p, LogPoses::Truth)
                        .with_context(|| format!("reading ground truth {}", p.display()))?,
                ),
                None => None,
            };
            (format!("log:{}", log.display()), read.records, truth)
        } else {
            anyhow::bail!("`source`: give `sim` or `log`");
        };
        if let Some(n) = c.max_scans {
            records.truncate(n);
        }
        if records.is_empty() {
            anyhow::bail!("{name}: no laser records");
        }
        if truth.is_none() && records.iter().all(|r| r.truth.is_some()) {
            truth = Some(
                records
                    .iter()
                    .filter_map(|r| r.truth.map(|t| (r.timestamp(), t)))
                    .collect(),
            );
        }
        let relations = match &c.relations {
            Some(p) => Some(read_relations(p).with_context(|| format!("reading {}", p.display()))?),
            None => None,
        };
        Ok(Self {
            name,
            records,
            truth,
            relations,
        })
    }

    /// Raw odometry at the laser times.
    #[must_use]
    pub fn odometry(&self) -> Vec<Stamped> {
        self.records
            .iter()
            .map(|r| (r.timestamp(), r.odometry))
            .collect()
    }
}

// ---------------------------------------------------------------------------------------------
// Scoring

/// What one trajectory scores.
#[derive(Debug, Clone)]
pub struct Scores {
    /// Against ground truth, where known.
    pub ate: Option<AteReport>,
    /// Against Freiburg relations, where given.
    pub relations: Option<RelationsReport>,
}

impl Scores {
    /// Scores `traj` with whatever the source has.
    pub fn of(traj: &[Stamped], source: &Source) -> Result<Self> {
        let ate = match &source.truth {
            Some(truth) => Some(evaluate_ate(traj, truth, &AteOptions::default())?),
            None => None,
        };
        let relations = match &source.relations {
            Some(rel) => {
                let r = evaluate_relations(traj, rel, crate::eval::DEFAULT_MAX_DT)?;
                if r.n == 0 {
                    eprintln!(
                        "warning: none of the {} relations falls on this log's times: \
                         are they the log's?",
                        rel.len()
                    );
                }
                Some(r)
            }
            None => None,
        };
        Ok(Self { ate, relations })
    }

    fn insert_into(&self, m: &mut Map<String, Value>) -> Result<()> {
        if let Some(a) = &self.ate {
            m.insert("ate_rmse_m".into(), json!(a.ate_rmse_m));
            m.insert("rpe_trans_per_m".into(), json!(a.rpe_trans_per_m));
            m.insert("rpe_rot_deg_per_m".into(), json!(a.rpe_rot_deg_per_m));
            m.insert("final_error_m".into(), json!(a.final_error_m));
        }
        if let Some(r) = &self.relations {
            m.insert("relations".into(), serde_json::to_value(r)?);
        }
        Ok(())
    }
}

/// One matcher's results.
#[derive(Debug)]
pub struct MatcherOutcome {
    /// The effective configuration.
    pub config: MatcherConfig,
    /// Robot pose per record.
    pub trajectory: Vec<Stamped>,
    /// Per-scan figures.
    pub rows: Vec<ScanRow>,
    /// Totals.
    pub summary: MatchSummary,
    /// Scores.
    pub scores: Scores,
    /// Wall time of the whole run (s), matching and bookkeeping.
    pub seconds: f64,
}

impl MatcherOutcome {
    fn kind(&self) -> String {
        self.config.kind()
    }

    fn to_json(&self) -> Result<Value> {
        let s = &self.summary;
        let mut m = Map::new();
        self.scores.insert_into(&mut m)?;
        for (k, v) in [
            ("residual_mean_mm", json!(s.residual_mean_mm)),
            ("certainty_mean", json!(s.certainty_mean)),
            ("sigma_mean_mm", json!(s.sigma_mean_mm)),
            ("ms_per_scan_median", json!(s.ms_per_scan_median)),
            ("ms_per_scan_p99", json!(s.ms_per_scan_p99)),
            ("map_points", json!(s.map_points)),
            ("fallbacks", json!(s.fallbacks)),
            ("fallback_reasons", json!(s.fallback_reasons)),
            ("inserted", json!(s.inserted)),
            ("searched", json!(s.searched)),
            ("recovered", json!(s.recovered)),
            ("refused", json!(s.refused)),
            ("matching_seconds", json!(s.wall_seconds)),
        ] {
            m.insert(k.into(), v);
        }
        Ok(Value::Object(m))
    }
}

/// The kind of the scan-to-scan twin of a boosted matcher (same algorithm), if it is one.
#[must_use]
pub fn incremental_of(config: &MatcherConfig) -> Option<String> {
    (config.reference == ReferenceKind::Map).then(|| config.algorithm().to_string())
}

/// Boosted / incremental ratios of every boosted kind whose twin also ran:
/// `{"q-wsm/wsm": {"ate": …, "residual": …, "certainty": …, "sigma": …, "relations_trans": …}}`.
fn ratios(outcomes: &[MatcherOutcome]) -> Value {
    let mut out = Map::new();
    for b in outcomes {
        let Some(inc) = incremental_of(&b.config) else {
            continue;
        };
        let Some(i) = outcomes.iter().find(|o| o.kind() == inc) else {
            continue;
        };
        let ratio = |x: f64, y: f64| json!(x / y);
        let mut m = Map::new();
        if let (Some(ab), Some(ai)) = (&b.scores.ate, &i.scores.ate) {
            m.insert("ate".into(), ratio(ab.ate_rmse_m, ai.ate_rmse_m));
            m.insert(
                "final_error".into(),
                ratio(ab.final_error_m, ai.final_error_m),
            );
        }
        if let (Some(rb), Some(ri)) = (&b.scores.relations, &i.scores.relations) {
            m.insert(
                "relations_trans".into(),
                ratio(rb.trans_mean, ri.trans_mean),
            );
        }
        m.insert(
            "residual".into(),
            ratio(b.summary.residual_mean_mm, i.summary.residual_mean_mm),
        );
        m.insert(
            "certainty".into(),
            ratio(b.summary.certainty_mean, i.summary.certainty_mean),
        );
        m.insert(
            "sigma".into(),
            ratio(b.summary.sigma_mean_mm, i.summary.sigma_mean_mm),
        );
        // Per scan (paper Fig. 4c-d): the mean is at the mercy of a few near-degenerate
        // incremental matches, the median is not.
        let per_scan: Vec<f64> = b
            .rows
            .iter()
            .zip(&i.rows)
            .map(|(rb, ri)| rb.certainty / ri.certainty)
            .filter(|r| r.is_finite())
            .collect();
        let mean = per_scan.iter().sum::<f64>() / per_scan.len() as f64;
        m.insert("certainty_per_scan_mean".into(), json!(mean));
        m.insert(
            "certainty_per_scan_median".into(),
            json!(crate::matching::quantile(&per_scan, 0.5)),
        );
        out.insert(format!("{}/{}", b.kind(), inc), Value::Object(m));
    }
    Value::Object(out)
}

/// Runs every matcher of `config` on `source`, `jobs` at a time (each matcher on one thread,
/// taking the next from the list as it finishes), and writes each one's outputs under `out`.
/// The outcomes come back in the list's order; each matcher is deterministic, so they are the
/// same for any `jobs`.
fn run_matchers(
    config: &ExperimentConfig,
    source: &Source,
    out: &Path,
    jobs: usize,
    show_progress: bool,
) -> Result<Vec<MatcherOutcome>> {
    let kinds = &config.run.matchers;
    let one = |kind: &String, progress: bool| -> Result<MatcherOutcome> {
        let t = Instant::now();
        let matcher = config.matcher(kind)?;
        let run = run_matcher(&source.records, &matcher, progress)?;
        write_run(&out.join(kind), &run, &matcher)?;
        let scores =
            Scores::of(&run.trajectory, source).with_context(|| format!("scoring {kind}"))?;
        Ok(MatcherOutcome {
            config: matcher,
            trajectory: run.trajectory,
            rows: run.rows,
            summary: run.summary,
            scores,
            seconds: t.elapsed().as_secs_f64(),
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
                                eprintln!("{kind}: {} scans in {:.1} s", o.rows.len(), o.seconds)
                            }
                            Err(e) => eprintln!("{kind}: failed: {e:#}"),
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

// ---------------------------------------------------------------------------------------------
// The command

/// Runs the command.
pub fn run(args: RunArgs) -> Result<()> {
    let started = Instant::now();
    let mut config = ExperimentConfig::load(&args.config)?;
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
    config.validate()?;
    let out = args.out.clone().unwrap_or_else(|| {
        let stem = args
            .config
            .file_stem()
            .map_or("experiment".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("out").join(stem)
    });
    if let Some(n) = args.worlds {
        return run_worlds(&args, &config, &out, n, started);
    }
    let summary = run_once(&args, &config, &out, true, started)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else if !args.quiet {
        println!("{}", table(&summary, &config.run.matchers));
        println!("outputs in {}", out.display());
    }
    Ok(())
}

/// One experiment into `out`: its records, every matcher, the scores, the pictures (when
/// `pictures`) and `summary.json`, which it returns.
fn run_once(
    args: &RunArgs,
    config: &ExperimentConfig,
    out: &Path,
    pictures: bool,
    started: Instant,
) -> Result<Value> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    std::fs::write(out.join("config.toml"), config.effective_toml()?)
        .with_context(|| format!("writing {}", out.join("config.toml").display()))?;

    let t = Instant::now();
    let source = Source::load(&config.source)?;
    let source_seconds = t.elapsed().as_secs_f64();
    let odometry = source.odometry();
    write_trajectory(&out.join("odometry.tum"), &odometry)?;
    if let Some(truth) = &source.truth {
        write_trajectory(&out.join("groundtruth.tum"), truth)?;
    }
    let odometry_scores = Scores::of(&odometry, &source)?;

    let t = Instant::now();
    let jobs = args
        .jobs
        .or_else(|| std::thread::available_parallelism().ok())
        .map_or(1, std::num::NonZeroUsize::get);
    let outcomes = run_matchers(config, &source, out, jobs, !args.quiet)?;
    let matching_seconds = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let pictures = if pictures {
        draw_pictures(out, &source, &odometry, &outcomes)?
    } else {
        json!({})
    };
    let plot_seconds = t.elapsed().as_secs_f64();

    let mut matchers = Map::new();
    for o in &outcomes {
        matchers.insert(o.kind(), o.to_json()?);
    }
    let mut odo = Map::new();
    odometry_scores.insert_into(&mut odo)?;
    let summary = json!({
        "source": source.name,
        "config": args.config.display().to_string(),
        "scans": source.records.len(),
        "ground_truth": source.truth.is_some(),
        "matchers": matchers,
        "odometry": odo,
        "ratios": ratios(&outcomes),
        "pictures": pictures,
        "source_seconds": source_seconds,
        "matching_seconds": matching_seconds,
        "plot_seconds": plot_seconds,
        "wall_seconds": started.elapsed().as_secs_f64(),
    });
    let text = serde_json::to_string_pretty(&summary)?;
    write_atomic(&out.join("summary.json"), format!("{text}\n").as_bytes())?;
    Ok(summary)
}

/// Figures of one matcher summarised over the worlds of `--worlds`.
const WORLD_FIGURES: [&str; 8] = [
    "ate_rmse_m",
    "final_error_m",
    "rpe_trans_per_m",
    "residual_mean_mm",
    "certainty_mean",
    "sigma_mean_mm",
    "ms_per_scan_median",
    "fallbacks",
];

/// Ratios of a boosted / incremental pair summarised over the worlds of `--worlds`.
const WORLD_RATIOS: [&str; 6] = [
    "ate",
    "final_error",
    "residual",
    "certainty",
    "sigma",
    "certainty_per_scan_median",
];

/// `{"median", "min", "max"}` of the finite values (the median of an even count is the mean
/// of the two middle values); nulls when there are none.
fn spread(values: &[f64]) -> Value {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return json!({"median": null, "min": null, "max": null});
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    json!({"median": median, "min": v[0], "max": v[n - 1]})
}

/// `qicp run --worlds N`: the experiment on N layouts of the simulated world.
fn run_worlds(
    args: &RunArgs,
    config: &ExperimentConfig,
    out: &Path,
    n: usize,
    started: Instant,
) -> Result<()> {
    let Some(sim) = &config.source.sim else {
        anyhow::bail!("--worlds needs a `sim` source: a log has one world");
    };
    if n == 0 {
        anyhow::bail!("--worlds 0: nothing would run");
    }
    let drive = qicp_sim::SimConfig::load(sim)
        .with_context(|| format!("loading drive {}", sim.display()))?;
    let first = config.source.world_seed.unwrap_or(drive.world.seed);
    let first_noise = config.source.seed.unwrap_or(drive.drive.seed);
    let seeds: Vec<u64> = (0..n as u64).map(|k| first + k).collect();
    let mut summaries = Vec::with_capacity(n);
    for (k, &seed) in seeds.iter().enumerate() {
        if !args.quiet {
            eprintln!("world {}/{n} (seed {seed})", k + 1);
        }
        let mut c = config.clone();
        c.source.world_seed = Some(seed);
        c.source.seed = Some(first_noise + k as u64);
        let dir = out.join(format!("world-{seed}"));
        summaries.push(
            run_once(args, &c, &dir, false, Instant::now())
                .with_context(|| format!("world seed {seed}"))?,
        );
    }
    let collect = |get: &dyn Fn(&Value) -> &Value| -> Vec<f64> {
        summaries
            .iter()
            .map(|s| get(s).as_f64().unwrap_or(f64::NAN))
            .collect()
    };
    let mut matchers = Map::new();
    for kind in &config.run.matchers {
        let mut m = Map::new();
        for figure in WORLD_FIGURES {
            let values = collect(&|s| &s["matchers"][kind.as_str()][figure]);
            m.insert(figure.into(), spread(&values));
        }
        matchers.insert(kind.clone(), Value::Object(m));
    }
    let mut ratios = Map::new();
    if let Some(pairs) = summaries[0]["ratios"].as_object() {
        for pair in pairs.keys() {
            let mut m = Map::new();
            for figure in WORLD_RATIOS {
                let values = collect(&|s| &s["ratios"][pair][figure]);
                m.insert(figure.into(), spread(&values));
            }
            ratios.insert(pair.clone(), Value::Object(m));
        }
    }
    let report = json!({
        "source": summaries[0]["source"],
        "config": args.config.display().to_string(),
        "world_seeds": seeds,
        "noise_seeds": (0..n as u64).map(|k| first_noise + k).collect::<Vec<_>>(),
        "scans": spread(&collect(&|s| &s["scans"])),
        "matchers": matchers,
        "ratios": ratios,
        "wall_seconds": started.elapsed().as_secs_f64(),
    });
    let text = serde_json::to_string_pretty(&report)?;
    let path = out.join("worlds.json");
    write_atomic(&path, format!("{text}\n").as_bytes())?;
    if args.json {
        println!("{text}");
    } else if !args.quiet {
        println!("{}", worlds_table(&report, &config.run.matchers));
        println!("outputs in {}", out.display());
    }
    Ok(())
}

/// The table printed after `--worlds`: median [min-max] of each figure.
fn worlds_table(report: &Value, kinds: &[String]) -> String {
    let cell = |v: &Value, scale: f64, digits: usize| match (
        v["median"].as_f64(),
        v["min"].as_f64(),
        v["max"].as_f64(),
    ) {
        (Some(m), Some(lo), Some(hi)) => format!(
            "{:.digits$} [{:.digits$}-{:.digits$}]",
            m * scale,
            lo * scale,
            hi * scale
        ),
        _ => "-".into(),
    };
    let columns: [(&str, &str, f64, usize); 6] = [
        ("ATE m", "ate_rmse_m", 1.0, 2),
        ("final m", "final_error_m", 1.0, 2),
        ("resid. mm", "residual_mean_mm", 1.0, 1),
        ("certainty mm²", "certainty_mean", 1e6, 1),
        ("σ mm", "sigma_mean_mm", 1.0, 1),
        ("ms/scan", "ms_per_scan_median", 1.0, 2),
    ];
    let mut rows = vec![
        std::iter::once("matcher".to_string())
            .chain(columns.iter().map(|c| c.0.to_string()))
            .collect::<Vec<_>>(),
    ];
    for k in kinds {
        let m = &report["matchers"][k.as_str()];
        rows.push(
            std::iter::once(k.to_string())
                .chain(columns.iter().map(|c| cell(&m[c.1], c.2, c.3)))
                .collect(),
        );
    }
    let widths: Vec<usize> = (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut text = format!(
        "{} — {} worlds (seeds {}), median [min-max]\n",
        report["source"].as_str().unwrap_or("?"),
        report["world_seeds"].as_array().map_or(0, Vec::len),
        report["world_seeds"]
            .as_array()
            .map(|s| {
                let s: Vec<String> = s.iter().map(ToString::to_string).collect();
                s.join(", ")
            })
            .unwrap_or_default(),
    );
    for r in rows {
        let cells: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(c, s)| {
                if c == 0 {
                    format!("{s:<w$}", w = widths[c])
                } else {
                    format!("{s:>w$}", w = widths[c])
                }
            })
            .collect();
        text += &cells.join("  ");
        text.push('\n');
    }
    if let Some(ratios) = report["ratios"].as_object().filter(|r| !r.is_empty()) {
        text += "\nboosted / incremental, median [min-max]:";
        for (pair, r) in ratios {
            let parts: Vec<String> = ["ate", "residual", "certainty", "sigma"]
                .iter()
                .map(|k| format!("{k} {}", cell(&r[*k], 1.0, 3)))
                .collect();
            text += &format!("\n  {pair}: {}", parts.join(", "));
        }
        text.push('\n');
    }
    text += &format!(
        "\nwall time {:.1} s",
        report["wall_seconds"].as_f64().unwrap_or(f64::NAN)
    );
    text
}

fn write_trajectory(path: &Path, traj: &[Stamped]) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    write_tum(&mut w, traj).with_context(|| format!("writing {}", path.display()))?;
    std::io::Write::flush(&mut w).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// `traj` moved so its first pose lies on `truth`'s first (the ATE alignment of
/// [`evaluate_ate`]); unchanged without truth.
fn aligned(traj: &[Stamped], truth: Option<&[Stamped]>) -> Vec<Pose2> {
    let to_truth = match (traj.first(), truth.and_then(<[Stamped]>::first)) {
        (Some((_, e)), Some((_, t))) => crate::eval::origin_alignment(e, t),
        _ => Pose2::IDENTITY,
    };
    traj.iter().map(|(_, p)| to_truth * *p).collect()
}

/// Draws every picture; returns `{file: what it shows}`.
fn draw_pictures(
    out: &Path,
    source: &Source,
    odometry: &[Stamped],
    outcomes: &[MatcherOutcome],
) -> Result<Value> {
    let mut pictures = Map::new();
    let truth = source.truth.as_deref();
    let truth_poses: Option<Vec<Pose2>> = truth.map(|t| t.iter().map(|p| p.1).collect());
    let scans: Vec<&qicp_core::Scan> = source.records.iter().map(|r| &r.scan).collect();
    let aligned_note = if truth.is_some() {
        ", start aligned with the truth"
    } else {
        ""
    };

    // Maps (paper Figs. 3, 5): one per matcher, drawn in parallel (each is independent).
    let maps: Vec<(String, Result<usize, plots::PlotError>)> = std::thread::scope(|s| {
        let handles: Vec<_> = outcomes
            .iter()
            .map(|o| {
                let (scans, truth_poses) = (&scans, &truth_poses);
                s.spawn(move || {
                    let poses = aligned(&o.trajectory, truth);
                    let lasers: Vec<Pose2> = poses
                        .iter()
                        .zip(&source.records)
                        .map(|(p, r)| *p * r.laser_offset)
                        .collect();
                    let file = format!("map_{}.png", o.kind());
                    let title = format!("{}: every scan at its estimated pose", o.kind());
                    let r = plots::occupancy_map(
                        &out.join(&file),
                        &title,
                        &lasers,
                        scans,
                        &poses,
                        truth_poses.as_deref(),
                    );
                    (file, r)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    (
                        "map".into(),
                        Err(plots::PlotError::Empty {
                            path: "map".into(),
                            why: "drawing thread panicked",
                        }),
                    )
                })
            })
            .collect()
    });
    for (file, r) in maps {
        r?;
        pictures.insert(
            file,
            json!("occupancy grid of every scan at the matcher's poses: black hit, white free, grey unseen; blue estimated path, grey true path (paper Figs. 3, 5)"),
        );
    }

    // Trajectories.
    let aligned_all: Vec<Vec<Pose2>> = outcomes
        .iter()
        .map(|o| aligned(&o.trajectory, truth))
        .collect();
    let odo = aligned(odometry, truth);
    let mut series = Vec::new();
    if let Some(t) = &truth_poses {
        series.push(PathSeries {
            label: "ground truth".into(),
            poses: t,
            color: plots::TRUTH_COLOR,
            width: 4,
            dashed: false,
        });
    }
    series.push(PathSeries {
        label: "odometry".into(),
        poses: &odo,
        color: plots::ODOMETRY_COLOR,
        width: 2,
        dashed: false,
    });
    for (k, (o, poses)) in outcomes.iter().zip(&aligned_all).enumerate() {
        series.push(PathSeries {
            label: o.kind(),
            poses,
            color: plots::PALETTE[k % plots::PALETTE.len()],
            width: 2,
            // kd-tree kinds often coincide with their quad-tree twins: dashed, both show.
            dashed: o.config.reference == ReferenceKind::Map && o.config.index() != "quadtree",
        });
    }
    let title = format!("Robot paths, {} scans{aligned_note}", source.records.len());
    plots::trajectories(&out.join("trajectories.png"), &title, &series)?;
    pictures.insert(
        "trajectories.png".into(),
        json!("every matcher's path with the ground truth (black) and raw odometry (grey), metres"),
    );

    // Paper Fig. 4: per family, the boosted matcher in front of the incremental one.
    // The quad-tree form first, as the paper draws it.
    let pairs: Vec<(&MatcherOutcome, &MatcherOutcome)> = outcomes
        .iter()
        .filter(|i| i.config.reference == ReferenceKind::Scan)
        .filter_map(|i| {
            let twins = || {
                outcomes.iter().filter(|b| {
                    b.config.reference == ReferenceKind::Map
                        && b.config.algorithm() == i.config.algorithm()
                })
            };
            let b = twins()
                .find(|b| b.config.index() == "quadtree")
                .or_else(|| twins().next())?;
            Some((i, b))
        })
        .collect();
    if !pairs.is_empty() {
        let (inc_color, boost_color) = (plots::PALETTE[0], plots::PALETTE[1]);
        let residual: Vec<Panel> = pairs
            .iter()
            .map(|(i, b)| Panel {
                title: format!(
                    "Residual correlation distance, {} vs {}",
                    b.kind(),
                    i.kind()
                ),
                series: vec![
                    ScanSeries {
                        label: i.kind(),
                        values: i.rows.iter().map(|r| r.residual_mm).collect(),
                        color: inc_color,
                    },
                    ScanSeries {
                        label: b.kind(),
                        values: b.rows.iter().map(|r| r.residual_mm).collect(),
                        color: boost_color,
                    },
                ],
                reference: None,
                y_cap: None,
            })
            .collect();
        plots::per_scan(
            &out.join("residual.png"),
            "residual correlation distance (mm)",
            &residual,
        )?;
        pictures.insert("residual.png".into(), json!("residual correlation distance per scan (mm), boosted in front of incremental, thick lines the means (paper Fig. 4a-b)"));
        let certainty: Vec<Panel> = pairs
            .iter()
            .map(|(i, b)| Panel {
                title: format!("Matching certainty, {} relative to {}", b.kind(), i.kind()),
                series: vec![ScanSeries {
                    label: format!("{} / {}", b.kind(), i.kind()),
                    values: b
                        .rows
                        .iter()
                        .zip(&i.rows)
                        .map(|(rb, ri)| rb.certainty / ri.certainty)
                        .collect(),
                    color: boost_color,
                }],
                reference: Some(1.0),
                y_cap: Some(3.0),
            })
            .collect();
        plots::per_scan(
            &out.join("certainty.png"),
            "certainty ratio (boosted / incremental)",
            &certainty,
        )?;
        pictures.insert("certainty.png".into(), json!("per scan, the boosted matcher's certainty sqrt(σxx²+σyy²) (covariance diagonal, m²) divided by the incremental one's; dashed: 1, thick: the mean (paper Fig. 4c-d)"));
    }
    Ok(Value::Object(pictures))
}

/// The table printed after a run.
fn table(summary: &Value, kinds: &[String]) -> String {
    let f = |v: &Value, scale: f64, digits: usize| {
        v.as_f64()
            .map_or_else(|| "-".to_string(), |x| format!("{:.digits$}", x * scale))
    };
    let truth = summary["ground_truth"].as_bool().unwrap_or(false);
    let relations = kinds
        .first()
        .is_some_and(|k| summary["matchers"][k.as_str()].get("relations").is_some());
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
    let mut row_of = |name: &str, m: &Value, matched: bool| {
        let mut r = vec![name.to_string()];
        if truth {
            r.push(f(&m["ate_rmse_m"], 1.0, 3));
            r.push(f(&m["rpe_trans_per_m"], 100.0, 2));
            r.push(f(&m["final_error_m"], 1.0, 3));
        }
        if relations {
            r.push(f(&m["relations"]["trans_mean"], 1.0, 3));
            r.push(f(&m["relations"]["rot_mean_deg"], 1.0, 2));
        }
        if matched {
            r.push(f(&m["residual_mean_mm"], 1.0, 2));
            r.push(f(&m["certainty_mean"], 1e6, 2));
            r.push(f(&m["sigma_mean_mm"], 1.0, 2));
            r.push(f(&m["ms_per_scan_median"], 1.0, 2));
            r.push(f(&m["ms_per_scan_p99"], 1.0, 2));
            r.push(m["map_points"].to_string());
            r.push(m["fallbacks"].to_string());
        } else {
            r.extend(std::iter::repeat_n("-".to_string(), 7));
        }
        rows.push(r);
    };
    row_of("odometry", &summary["odometry"], false);
    for k in kinds {
        row_of(k, &summary["matchers"][k.as_str()], true);
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
    let line = |cells: Vec<String>| {
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
    };
    let mut text = format!(
        "{} — {} scans\n",
        summary["source"].as_str().unwrap_or("?"),
        summary["scans"]
    );
    text += &line(head.iter().map(|s| (*s).to_string()).collect());
    text.push('\n');
    for r in rows {
        text += &line(r);
        text.push('\n');
    }
    if let Some(ratios) = summary["ratios"].as_object().filter(|r| !r.is_empty()) {
        text += "\nboosted / incremental:";
        for (pair, r) in ratios {
            let parts: Vec<String> = [
                "ate",
                "residual",
                "certainty",
                "certainty_per_scan_median",
                "sigma",
                "relations_trans",
            ]
            .iter()
            .filter_map(|k| {
                r.get(*k)
                    .and_then(Value::as_f64)
                    .map(|v| format!("{k} {v:.3}"))
            })
            .collect();
            text += &format!("\n  {pair}: {}", parts.join(", "));
        }
        text.push('\n');
    }
    text += &format!(
        "\nwall time {:.2} s (source {:.2} s, matching {:.2} s, pictures {:.2} s)",
        summary["wall_seconds"].as_f64().unwrap_or(f64::NAN),
        summary["source_seconds"].as_f64().unwrap_or(f64::NAN),
        summary["matching_seconds"].as_f64().unwrap_or(f64::NAN),
        summary["plot_seconds"].as_f64().unwrap_or(f64::NAN),
    );
    text
}
