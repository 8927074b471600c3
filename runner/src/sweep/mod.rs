//! Robustness sweeps (`qicp sweep LOG --matcher KIND --relations FILE`): how robust a matcher is to its input and
//! to its parameters (issue 12).
//!
//! The matcher runs on the log once as configured ("default") and once per variant, and every
//! run is scored with the Freiburg relations, or, for a log without relations, against the
//! default run's own motion ([`SweepInput::against_default`]). A variant perturbs one thing:
//!
//! - **input variants** (deterministic, seeded): fewer scans ([`every_other_record`]), fewer
//!   beams ([`every_other_beam`]), odometry drift ([`noisy_increment`]), a slipping wheel
//!   ([`biased_increment`]), range noise ([`noisy_ranges`]), a shorter-sighted laser
//!   ([`capped_range`]);
//! - **parameter variants**: every key of
//!   [`MatcherConfig::steering_parameters`] times 0.7 and times 1.4, one at a time.
//!
//! The ratio of a variant is its mean translational relation error over the default's; the
//! sweep reports the worst and the median ratio. The runs are spread over worker threads; each
//! run is deterministic, so the figures (all but the wall times) do not depend on `--jobs`.

use crate::matching::MatchLoop;
use anyhow::{Context, Result, bail};
use qicp_core::{BeamGeometry, BeamStatus, Pose2, Record, Scan, ScanError};
use qicp_eval::stats::median;
use qicp_eval::{
    RelationError, RelationProbe, SNAPPED_MAX_DT, evaluate_relations, relation_errors,
};
use qicp_io::carmen::CarmenOptions;
use qicp_io::relations::{Relation, read_relations};
use qicp_io::tum::Stamped;
use qicp_io::{LogOptions, LogReader};
use qicp_matchers::MatcherConfig;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::collections::HashMap;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

mod perturb;
mod running;
mod variants;

pub use perturb::*;
pub use running::*;
pub use variants::*;

/// Association window (s) of a relation's time with the log's records, as `qicp match
/// --relations` uses it. The relations are then moved onto those records' own times, and every
/// run is scored on the records it matched ([`SNAPPED_MAX_DT`]): `scans/2` has no pose for the
/// records it drops, and the pose of the record beside one, up to this far away, would add
/// the robot's motion in between to the variant's error.
pub const MAX_DT: f64 = 0.1;
/// A relation whose translational error exceeds this (m) counts as a failure.
pub const FAILURE_M: f64 = 0.5;
/// Seed of the random input variants (issue 12).
pub const SEED: u64 = 12;
/// Factors every steering parameter is scaled by, one at a time.
pub const PARAMETER_FACTORS: [f64; 2] = [0.7, 1.4];

/// Odometry noise: σ of x and y per metre travelled (m/m).
pub const ODOM_NOISE_XY_PER_M: f64 = 0.05;
/// Odometry noise: σ of the heading per metre travelled (2°/m, in rad/m).
pub const ODOM_NOISE_THETA_PER_M: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Odometry noise: σ of the heading per radian turned (rad/rad).
pub const ODOM_NOISE_THETA_PER_RAD: f64 = 0.05;
/// Odometry bias: scale of the translation of every increment.
pub const ODOM_BIAS_SCALE: f64 = 1.05;
/// Odometry bias: heading added per metre travelled (1°/m, in rad/m).
pub const ODOM_BIAS_THETA_PER_M: f64 = std::f64::consts::PI / 180.0;
/// Range noise σ (m).
pub const RANGE_NOISE_SIGMA: f64 = 0.01;
/// Maximum range (m) of the `max-range-10` variant.
pub const CAPPED_MAX_RANGE: f64 = 10.0;

/// One variant's line of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VariantReport {
    /// The variant's name.
    pub name: String,
    /// Its figures (absent when it could not run).
    #[serde(flatten)]
    pub figures: Option<RunFigures>,
    /// Its `trans_mean` over the default's: over [`default_trans_mean`] where that is given.
    ///
    /// [`default_trans_mean`]: Self::default_trans_mean
    pub ratio: Option<f64>,
    /// The default's mean translational error (m) on the relations this variant scored,
    /// when it scored only some of the default's (`scans/2` scores those between two of the
    /// records it keeps): its ratio and its bound are taken against this, not against the
    /// default's whole `trans_mean`, so that both runs are judged on the same relations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub default_trans_mean: Option<f64>,
    /// Why it could not run (an invalid scaled configuration, say).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The sweep's report (`--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepReport {
    /// The log.
    pub log: String,
    /// Registry name of the matcher.
    pub matcher: String,
    /// Records of the log used.
    pub scans: usize,
    /// What the runs are scored with: `"relations"` (the relations file's), `"default run"`
    /// (relations drawn along the default run's trajectory, for a log without any:
    /// [`SweepInput::against_default`]; the figures are then disagreements with the default,
    /// and there are no ratios) or `"reference trajectory"` (relations drawn along
    /// [`reference`](Self::reference): [`SweepInput::against_trajectory`]).
    pub scored_against: ScoredAgainst,
    /// The reference trajectory's file, when the runs are scored against one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
    /// Relations in the relations file (against the default run or a reference trajectory:
    /// the segments and revisits drawn along it, [`relations_along`]).
    pub relations_total: usize,
    /// The run with the configuration as given.
    pub default: RunFigures,
    /// Every variant, in report order.
    pub variants: Vec<VariantReport>,
    /// The largest ratio of the variants that ran.
    pub worst_ratio: Option<f64>,
    /// The variant with the largest ratio.
    pub worst_variant: Option<String>,
    /// The median ratio of the variants that ran (the mean of the middle two for an even
    /// count).
    pub median_ratio: Option<f64>,
    /// Relations of the default run with a translational error above 0.5 m.
    pub relations_over_0_5_m: usize,
    /// Variants whose `trans_mean` exceeds the bound max([`BOUND_FACTOR`] × the default's,
    /// [`BOUND_FLOOR_M`]): the fragile ones.
    pub variants_over_bound: usize,
    /// The geometric mean of the variants' `trans_mean` (m): one figure for the whole sweep
    /// that a single lucky or unlucky variant moves less than the worst ratio, and a lucky
    /// default does not move at all (the ratios do).
    pub variants_geomean_trans_mean: Option<f64>,
}

/// What a sweep's runs are scored with ([`SweepReport::scored_against`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ScoredAgainst {
    /// The relations file's relations.
    #[serde(rename = "relations")]
    Relations,
    /// Relations drawn along the default run's trajectory ([`SweepInput::against_default`]).
    #[serde(rename = "default run")]
    DefaultRun,
    /// Relations drawn along a reference trajectory ([`SweepInput::against_trajectory`]):
    /// disagreements with it, the default's included.
    #[serde(rename = "reference trajectory")]
    Reference,
}

/// A variant is fragile when its mean error exceeds this many times the default's…
pub const BOUND_FACTOR: f64 = 2.0;
/// … and this many metres.
pub const BOUND_FLOOR_M: f64 = 0.05;

/// How many of `variants` exceed the bound around `default_trans_mean` (see
/// [`SweepReport::variants_over_bound`]; around a variant's own
/// [`VariantReport::default_trans_mean`] where it has one), and the geometric mean of their
/// mean errors (of those that ran with a positive, finite error).
#[must_use]
pub fn robustness_figures(
    default_trans_mean: f64,
    variants: &[VariantReport],
) -> (usize, Option<f64>) {
    let bound = |v: &VariantReport| {
        (BOUND_FACTOR * v.default_trans_mean.unwrap_or(default_trans_mean)).max(BOUND_FLOOR_M)
    };
    let runs: Vec<(f64, f64)> = variants
        .iter()
        .filter_map(|v| v.figures.as_ref().map(|f| (f.trans_mean, bound(v))))
        .collect();
    // An error that is not a number counts as over: it is no evidence of robustness.
    let over = runs.iter().filter(|&&(e, b)| e > b || e.is_nan()).count();
    let errors: Vec<f64> = runs.iter().map(|r| r.0).collect();
    let logs: Vec<f64> = errors
        .iter()
        .filter(|e| e.is_finite() && **e > 0.0)
        .map(|e| e.ln())
        .collect();
    let geomean = (!logs.is_empty()).then(|| (logs.iter().sum::<f64>() / logs.len() as f64).exp());
    (over, geomean)
}

/// The runs of a sweep: the default, then one per variant, in report order.
#[must_use]
pub fn plan(config: &MatcherConfig, variants: &[Variant]) -> Vec<Job> {
    std::iter::once(Job::default_run(config))
        .chain(variants.iter().map(|v| Job::variant(config, v)))
        .collect()
}

/// Sweeps `variants` of the matcher `config` over the records of `input`, scored with its
/// relations, with `jobs` runs at a time; `progress` hears of each run as it finishes (name,
/// result, time). Every run reads the log afresh, so memory holds `jobs` maps and no log.
pub fn sweep(
    input: &SweepInput,
    config: &MatcherConfig,
    variants: &[Variant],
    jobs: usize,
    mut progress: impl FnMut(&str, &Result<RunFigures, String>, Duration),
) -> Result<(RunFigures, Vec<VariantReport>)> {
    let jobs_list = plan(config, variants);
    if input.against_default {
        return sweep_against_default(input, &jobs_list, jobs, progress);
    }
    let mut results = run_parallel(
        &jobs_list,
        jobs,
        |job| job.run(input),
        |i, result, elapsed| {
            if let Some(job) = jobs_list.get(i) {
                progress(&job.name, result, elapsed);
            }
        },
    )
    .into_iter();
    let default = match results.next() {
        Some(Ok(figures)) => figures,
        Some(Err(e)) => bail!("the default run failed: {e}"),
        None => bail!("the default run gave no result"),
    };
    let reports = jobs_list
        .iter()
        .skip(1)
        .zip(results)
        .map(|(job, result)| variant_report(&job.name, result, &default))
        .collect();
    Ok((default, reports))
}

/// [`sweep`] of an input without relations ([`SweepInput::against_default`]): the default runs
/// alone first, keeping its poses (a pose per record in memory, besides the map); then the
/// variants run `jobs` at a time, scored with the relations drawn along its trajectory.
fn sweep_against_default(
    input: &SweepInput,
    jobs_list: &[Job],
    jobs: usize,
    mut progress: impl FnMut(&str, &Result<RunFigures, String>, Duration),
) -> Result<(RunFigures, Vec<VariantReport>)> {
    // The default runs alone first: its trajectory is what the variants are scored with.
    let Some(default_job) = jobs_list.first() else {
        bail!("a sweep has a default run");
    };
    let t0 = Instant::now();
    let (default, relations) = default_relations(input, default_job)?;
    let scored = SweepInput {
        relations,
        ..input.clone()
    };
    progress(&default_job.name, &default, t0.elapsed());
    let default = default.map_err(|e| anyhow::anyhow!("the default run failed: {e}"))?;
    let results = run_parallel(
        &jobs_list[1..],
        jobs,
        |job| job.run(&scored),
        |i, result, elapsed| {
            if let Some(job) = jobs_list.get(i + 1) {
                progress(&job.name, result, elapsed);
            }
        },
    );
    let reports = jobs_list[1..]
        .iter()
        .zip(results)
        .map(|(job, result)| variant_report(&job.name, result, &default))
        .collect();
    Ok((default, reports))
}

/// The default run of a sweep against it ([`SweepInput::against_default`]): `default_job`
/// (the configuration as given) on `input`, keeping its poses, and the relations drawn along
/// its trajectory that the variants are scored with. Its figures are scored against them (no
/// error, every relation found); a run that fails gives its message and no relations. `Err`
/// when the run succeeded but moved too little to draw a relation.
pub fn default_relations(
    input: &SweepInput,
    default_job: &Job,
) -> Result<(Result<RunFigures, String>, Vec<Relation>)> {
    let mut trajectory = Vec::with_capacity(input.scans);
    let run = default_job.run_tracking(input, &mut trajectory);
    // Segments end on records every variant keeps (`scans/2` keeps the even ones), so a
    // variant is compared at the default's own times, never at a neighbour's.
    let kept: Vec<Stamped> = trajectory.iter().step_by(2).copied().collect();
    let relations = relations_along(&kept);
    if run.is_ok() && relations.is_empty() {
        bail!(
            "the default run moved less than {SEGMENT_M} m and turned less than 30° \
             over the {} scans: there is nothing to compare the variants' motion with",
            input.scans
        );
    }
    let default = run
        .and_then(|mut figures| {
            figures.score(&trajectory, &relations)?;
            Ok(figures)
        })
        .map_err(|e| format!("{e:#}"));
    Ok((default, relations))
}

fn fmt_f(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        "-".to_string()
    }
}

/// The report as a table: the default, one line per variant, the summary.
#[must_use]
pub fn table(report: &SweepReport) -> String {
    use std::fmt::Write;
    let width = report
        .variants
        .iter()
        .map(|v| v.name.len())
        .chain(std::iter::once("default".len()))
        .max()
        .unwrap_or(7);
    let mut out = String::new();
    if report.scored_against == ScoredAgainst::Relations {
        let _ = writeln!(
            out,
            "{} on {} ({} scans, {} relations in file)",
            report.matcher, report.log, report.scans, report.relations_total
        );
    } else if report.scored_against == ScoredAgainst::Reference {
        let _ = writeln!(
            out,
            "{} on {} ({} scans), scored against the reference trajectory {}: its motion over \
             {} relations (segments of {SEGMENT_M} m or 30°, and revisits {REVISIT_GAP_S} s \
             or more apart within {REVISIT_M} m); errors are disagreements with it",
            report.matcher,
            report.log,
            report.scans,
            report.reference.as_deref().unwrap_or("?"),
            report.relations_total
        );
    } else {
        let _ = writeln!(
            out,
            "{} on {} ({} scans), scored against the default run: its motion over {} \
             relations (segments of {SEGMENT_M} m or 30°, and revisits {REVISIT_GAP_S} s or \
             more apart within {REVISIT_M} m); errors are disagreements with it",
            report.matcher, report.log, report.scans, report.relations_total
        );
    }
    let _ = writeln!(
        out,
        "{:width$}  {:>10}  {:>9}  {:>8}  {:>6}  {:>6}  {:>6}  {:>10}  {:>7}",
        "variant",
        "trans_mean",
        "trans_max",
        "rot_mean",
        "ratio",
        "n",
        ">0.5m",
        "map_points",
        "ms/scan"
    );
    let line = |name: &str, f: &RunFigures, ratio: Option<f64>| {
        format!(
            "{name:width$}  {:>10}  {:>9}  {:>8}  {:>6}  {:>6}  {:>6}  {:>10}  {:>7}",
            fmt_f(f.trans_mean, 4),
            fmt_f(f.trans_max, 3),
            fmt_f(f.rot_mean_deg, 3),
            ratio.map_or_else(|| "-".to_string(), |r| fmt_f(r, 2)),
            f.relations,
            f.relations_over_0_5_m,
            f.map_points,
            fmt_f(f.ms_per_scan_median, 2),
        )
    };
    let own = (report.scored_against != ScoredAgainst::DefaultRun).then_some(1.0);
    let _ = writeln!(out, "{}", line("default", &report.default, own));
    for v in &report.variants {
        match (&v.figures, &v.error) {
            (Some(f), _) => {
                let _ = writeln!(out, "{}", line(&v.name, f, v.ratio));
                if let Some(d) = v.default_trans_mean {
                    let _ = writeln!(
                        out,
                        "{:width$}  (ratio and bound against the default's {} m on these {} relations)",
                        "",
                        fmt_f(d, 4),
                        f.relations
                    );
                }
            }
            (None, e) => {
                let _ = writeln!(
                    out,
                    "{:width$}  error: {}",
                    v.name,
                    e.as_deref().unwrap_or("no result")
                );
            }
        }
    }
    let _ = writeln!(
        out,
        "worst ratio {} ({}), median ratio {}; default: {} of {} relations above {FAILURE_M} m",
        report
            .worst_ratio
            .map_or_else(|| "-".to_string(), |r| fmt_f(r, 2)),
        report.worst_variant.as_deref().unwrap_or("-"),
        report
            .median_ratio
            .map_or_else(|| "-".to_string(), |r| fmt_f(r, 2)),
        report.relations_over_0_5_m,
        report.default.relations
    );
    let _ = writeln!(
        out,
        "{} of {} variants over max({BOUND_FACTOR} × default, {BOUND_FLOOR_M} m); geometric mean of the variants' trans_mean {} m",
        report.variants_over_bound,
        report.variants.len(),
        report
            .variants_geomean_trans_mean
            .map_or_else(|| "-".to_string(), |g| fmt_f(g, 4)),
    );
    out
}

/// A sweep's inputs, checked: the log, read afresh by every run (so that memory holds no
/// log), and the relations every run is scored with.
#[derive(Debug, Clone)]
pub struct SweepInput {
    /// The log, as named in reports.
    pub log: String,
    path: PathBuf,
    options: LogOptions,
    /// Records of the log the runs use.
    pub scans: usize,
    /// The relations every run is scored with (for a sweep against the default run, none
    /// until the default has run: see [`SweepInput::against_default`]).
    pub relations: Vec<Relation>,
    /// True when the runs are scored against the default run's trajectory rather than against
    /// relations ([`SweepInput::against_default`]).
    pub against_default: bool,
    /// The trajectory the relations were drawn along, when they were
    /// ([`SweepInput::against_trajectory`]).
    pub reference: Option<String>,
    /// Where each run writes its trajectory (see [`SweepInput::with_trajectories`]).
    trajectories: Option<PathBuf>,
}

impl SweepInput {
    /// Reads the relations, then streams the log once (its first `scans` records): a CARMEN
    /// log (`lenient` skips malformed lines) or a ROS 2 bag with scans on `/scan` and odometry
    /// on `/odom`. That pass counts the records and checks that some relation falls within
    /// them, so that an unreadable log or the relations file of another log fails before any
    /// matching.
    pub fn load(
        log: &Path,
        relations: &Path,
        scans: Option<NonZeroUsize>,
        lenient: bool,
    ) -> Result<Self> {
        let carmen = CarmenOptions {
            lenient,
            ..CarmenOptions::default()
        };
        Self::load_with(log, relations, scans, carmen)
    }

    /// [`SweepInput::load`] with a CARMEN log read as `carmen` says (its record order, say).
    pub fn load_with(
        log: &Path,
        relations: &Path,
        scans: Option<NonZeroUsize>,
        carmen: CarmenOptions,
    ) -> Result<Self> {
        let relations_name = relations.display().to_string();
        let relations = read_relations(relations)
            .with_context(|| format!("reading relations {relations_name}"))?;
        if relations.is_empty() {
            bail!("{relations_name} holds no relations");
        }
        let options = LogOptions {
            carmen,
            ..LogOptions::default()
        };
        let mut probe = RelationProbe::new(&relations, MAX_DT)?;
        let (count, span) = count_records(log, &options, scans, |t, odometry| {
            probe.push(t, odometry).map_err(anyhow::Error::from)
        })?;
        let (found, _) = relation_errors(&probe.trajectory(), &relations, MAX_DT)?;
        if found.is_empty() {
            bail!(
                "none of the {} relations of {relations_name} falls within the {count} scans \
                 used ({} to {} s): do they belong to this log?",
                relations.len(),
                span.0,
                span.1
            );
        }
        let relations = if scans.is_some_and(|n| n.get() <= count) {
            // A relation about a record past the first `scans` must not be taken onto a
            // record beside it that the runs use: the records past them are looked at too.
            let mut all = RelationProbe::new(&relations, MAX_DT)?;
            let reader = LogReader::open(log, &options)
                .with_context(|| format!("reading {}", log.display()))?;
            // Quietly, and up to the first record it cannot read: the runs never read that far.
            for record in reader.map_while(std::result::Result::ok) {
                all.push(record.timestamp(), record.odometry)?;
            }
            probe.snap_within(&relations, &all)
        } else {
            probe.snap(&relations)
        };
        Ok(Self::counted(log, options, count, relations))
    }

    /// A sweep scored against a reference trajectory of the log (TUM; another matcher's, a
    /// SLAM system's): relations drawn along its poses nearest the records every variant
    /// keeps, as [`relations_along`] draws them, a segment per [`SEGMENT_M`] or
    /// [`SEGMENT_RAD`] and the revisits. For a log without relations whose trusted trajectory
    /// is not the default run's: every run, the default's too, is scored by how far its
    /// motion disagrees with the reference's, and the ratios say what each variant costs.
    /// Streams the log once to count its records.
    pub fn against_trajectory(
        log: &Path,
        reference: &Path,
        scans: Option<NonZeroUsize>,
        carmen: CarmenOptions,
    ) -> Result<Self> {
        let name = reference.display().to_string();
        let mut trajectory = qicp_io::tum::read_tum(reference)
            .with_context(|| format!("reading the reference trajectory {name}"))?;
        trajectory.sort_by(|a, b| a.0.total_cmp(&b.0));
        let options = LogOptions {
            carmen,
            ..LogOptions::default()
        };
        // Segments end on records every variant keeps (`scans/2` keeps the even ones), as
        // against the default run: the reference's pose nearest each such record's time.
        let mut kept = Vec::new();
        let mut last_taken: Option<Stamped> = None;
        let mut k = 0usize;
        let (count, span) = count_records(log, &options, scans, |t, _| {
            // Drawn at the record's own time, which every run is scored at.
            if k.is_multiple_of(2)
                && let Some(&pose) = nearest_within(&trajectory, t, MAX_DT)
                && last_taken != Some(pose)
            {
                kept.push((t, pose.1));
                last_taken = Some(pose);
            }
            k += 1;
            Ok(())
        })?;
        let relations = relations_along(&kept);
        if relations.is_empty() {
            bail!(
                "the reference trajectory {name} has {} poses within {MAX_DT} s of the {count} \
                 scans used ({} to {} s), and they never move {SEGMENT_M} m or turn 30°: no \
                 segment to score with (is it this log's?)",
                kept.len(),
                span.0,
                span.1
            );
        }
        Ok(Self {
            reference: Some(name),
            ..Self::counted(log, options, count, relations)
        })
    }

    /// A sweep of a log without relations (CARMEN read as `carmen` says, or a bag): every
    /// variant is scored against the default run instead, with relations drawn along the
    /// default's own trajectory ([`relations_along`]): a variant's `trans_mean` is then how
    /// far its motion disagrees with the default's over each segment of about a metre and
    /// between the default's revisits of a place, not an error against the truth. A matcher
    /// that holds on a log agrees with itself under small changes; a fragile one does not.
    /// Streams the log once to count its records.
    pub fn against_default(
        log: &Path,
        scans: Option<NonZeroUsize>,
        carmen: CarmenOptions,
    ) -> Result<Self> {
        let options = LogOptions {
            carmen,
            ..LogOptions::default()
        };
        let (count, _) = count_records(log, &options, scans, |_, _| Ok(()))?;
        Ok(Self {
            against_default: true,
            ..Self::counted(log, options, count, Vec::new())
        })
    }

    /// The input of `log` read with `options`, `scans` records counted, scored with
    /// `relations`.
    fn counted(log: &Path, options: LogOptions, scans: usize, relations: Vec<Relation>) -> Self {
        Self {
            log: log.display().to_string(),
            path: log.to_path_buf(),
            options,
            scans,
            relations,
            against_default: false,
            reference: None,
            trajectories: None,
        }
    }

    /// Makes every run write its trajectory to `dir/<run>.tum` (TUM format; the run's name
    /// with `/` and `*` spelt `-` and `-x`, e.g. `scans-2.tum`, `icp.max_dist_end-x0.7.tum`), so
    /// that a variant that fails can be compared with the default pose by pose. The directory
    /// is created now, before any matching; each file appears under its name only when its run
    /// is complete.
    pub fn with_trajectories(mut self, dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the trajectories directory {}", dir.display()))?;
        // A directory that cannot take files is refused now, not after the first run.
        tempfile::NamedTempFile::new_in(dir)
            .with_context(|| format!("writing into {}", dir.display()))?;
        self.trajectories = Some(dir.to_path_buf());
        Ok(self)
    }

    /// The file run `name` writes its trajectory to, if trajectories are kept.
    #[must_use]
    pub fn trajectory_path(&self, name: &str) -> Option<PathBuf> {
        let file = name.replace(['/', '\\'], "-").replace('*', "-x");
        self.trajectories
            .as_ref()
            .map(|dir| dir.join(format!("{file}.tum")))
    }

    /// The records the runs use, read afresh from the log, one at a time.
    pub fn records(&self) -> Result<impl Iterator<Item = Result<Record>> + use<>> {
        let reader = LogReader::open(&self.path, &self.options)
            .with_context(|| format!("reading {}", self.path.display()))?;
        Ok(reader
            .take(self.scans)
            .map(|r| r.map_err(anyhow::Error::from)))
    }
}

/// Streams the first `scans` records of `log`, calling `each(timestamp, odometry)`; returns
/// their count and the first and last timestamps. An unreadable or empty log is an error.
fn count_records(
    log: &Path,
    options: &LogOptions,
    scans: Option<NonZeroUsize>,
    mut each: impl FnMut(f64, Pose2) -> Result<()>,
) -> Result<(usize, (f64, f64))> {
    let mut reader = LogReader::open(log, options)?;
    let mut count = 0;
    let mut span = (f64::NAN, f64::NAN);
    for record in reader
        .by_ref()
        .take(scans.map_or(usize::MAX, NonZeroUsize::get))
    {
        let record = record.with_context(|| format!("reading {}", log.display()))?;
        each(record.timestamp(), record.odometry)?;
        if count == 0 {
            span.0 = record.timestamp();
        }
        span.1 = record.timestamp();
        count += 1;
    }
    reader.warn(log);
    if count == 0 {
        return Err(reader.empty(log).into());
    }
    Ok((count, span))
}

/// A segment of [`relations_along`] ends once the robot moved this far (m)…
pub const SEGMENT_M: f64 = 1.0;
/// … or turned this much (30°, in rad) since it began.
pub const SEGMENT_RAD: f64 = std::f64::consts::PI / 6.0;

/// The pose of `trajectory` (sorted by time) nearest `t`, if within `max_dt`.
fn nearest_within(trajectory: &[Stamped], t: f64, max_dt: f64) -> Option<&Stamped> {
    let i = trajectory.partition_point(|s| s.0 < t);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|j| trajectory.get(j))
        .filter(|s| (s.0 - t).abs() <= max_dt)
        .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
}

/// A revisit of [`relations_along`] joins poses at least this far apart in time (s)…
pub const REVISIT_GAP_S: f64 = 60.0;
/// … and at most this far apart in space (m).
pub const REVISIT_M: f64 = 1.0;
/// Every this-many-th pose of the trajectory is tried for a revisit.
pub const REVISIT_STRIDE: usize = 10;

/// Relations along a trajectory (time order): a chain of segments, each from a pose to the
/// first later one that moved [`SEGMENT_M`] or turned [`SEGMENT_RAD`] from it, holding the
/// trajectory's own motion over the segment; then the revisits, each from one of every
/// [`REVISIT_STRIDE`]-th pose to the nearest earlier such pose (the latest of equals) at
/// least [`REVISIT_GAP_S`] older within [`REVISIT_M`] of it: one a pose, so that a long wait
/// in one place cannot outnumber the drive. Scored against them, the trajectory itself has
/// no error; another run of the same log has the error of its motion where it disagrees.
/// The segments see a run disagree over about a metre; the revisits, as the Freiburg
/// benchmark's relations between poses far apart in time do, see a heading lost once and
/// never regained, which the chain counts on one segment only.
#[must_use]
pub fn relations_along(trajectory: &[(f64, Pose2)]) -> Vec<Relation> {
    let mut relations = Vec::new();
    let Some(&(mut t1, mut from)) = trajectory.first() else {
        return relations;
    };
    for &(t2, to) in &trajectory[1..] {
        let delta = from.between(&to);
        if delta.translation().norm() >= SEGMENT_M || delta.theta.abs() >= SEGMENT_RAD {
            relations.push(Relation { t1, t2, delta });
            (t1, from) = (t2, to);
        }
    }
    relations.extend(revisits_along(trajectory));
    relations
}

/// The revisits of [`relations_along`], in the order of their later pose.
fn revisits_along(trajectory: &[(f64, Pose2)]) -> Vec<Relation> {
    let cell = |p: &Pose2| {
        // Saturating casts: a pose far out only shares its cell with its neighbours there.
        (
            (p.x / REVISIT_M).floor() as i64,
            (p.y / REVISIT_M).floor() as i64,
        )
    };
    let mut cells: HashMap<(i64, i64), Vec<Stamped>> = HashMap::new();
    let mut relations = Vec::new();
    for &(t2, to) in trajectory.iter().step_by(REVISIT_STRIDE) {
        if !(t2.is_finite() && to.x.is_finite() && to.y.is_finite()) {
            continue;
        }
        let (cx, cy) = cell(&to);
        let mut nearest: Option<(f64, Stamped)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                let Some(earlier) = cells.get(&(cx.saturating_add(dx), cy.saturating_add(dy)))
                else {
                    continue;
                };
                for &(t1, from) in earlier {
                    let d = from.distance(&to);
                    let better =
                        nearest.is_none_or(|(best, (tb, _))| d < best || (d == best && t1 > tb));
                    if t2 - t1 >= REVISIT_GAP_S && d <= REVISIT_M && better {
                        nearest = Some((d, (t1, from)));
                    }
                }
            }
        }
        if let Some((_, (t1, from))) = nearest {
            relations.push(Relation {
                t1,
                t2,
                delta: from.between(&to),
            });
        }
        cells.entry((cx, cy)).or_default().push((t2, to));
    }
    relations
}

/// The report of a sweep of `config` on `input`: the default run, the variants, the worst and
/// the median ratio (none for a sweep against the default run, whose own error is 0).
#[must_use]
pub fn report(
    input: &SweepInput,
    config: &MatcherConfig,
    default: RunFigures,
    variants: Vec<VariantReport>,
) -> SweepReport {
    // Against the default run there is no ratio: the default's own error is 0.
    let variants: Vec<VariantReport> = if input.against_default {
        variants
            .into_iter()
            .map(|v| VariantReport { ratio: None, ..v })
            .collect()
    } else {
        variants
    };
    let ratios: Vec<(f64, &str)> = variants
        .iter()
        .filter_map(|v| v.ratio.map(|r| (r, v.name.as_str())))
        .filter(|(r, _)| !r.is_nan())
        .collect();
    let worst = ratios.iter().copied().max_by(|a, b| a.0.total_cmp(&b.0));
    let median_ratio = median(&ratios.iter().map(|r| r.0).collect::<Vec<_>>());
    let worst_ratio = worst.map(|w| w.0);
    let worst_variant = worst.map(|w| w.1.to_string());
    let (variants_over_bound, variants_geomean_trans_mean) =
        robustness_figures(default.trans_mean, &variants);
    SweepReport {
        log: input.log.clone(),
        matcher: config.kind(),
        scans: input.scans,
        scored_against: if input.against_default {
            ScoredAgainst::DefaultRun
        } else if input.reference.is_some() {
            ScoredAgainst::Reference
        } else {
            ScoredAgainst::Relations
        },
        reference: input.reference.clone(),
        relations_total: if input.against_default {
            default.relations
        } else {
            input.relations.len()
        },
        relations_over_0_5_m: default.relations_over_0_5_m,
        default,
        worst_ratio,
        worst_variant,
        median_ratio,
        variants_over_bound,
        variants_geomean_trans_mean,
        variants,
    }
}

/// The ratio of a variant's figures to the default's, as reports give it: to the default's
/// on the same relations where the variant scored only some of them
/// ([`VariantReport::default_trans_mean`]).
#[must_use]
pub fn variant_report(
    name: &str,
    result: Result<RunFigures, String>,
    default: &RunFigures,
) -> VariantReport {
    let (figures, error) = match result {
        Ok(f) => (Some(f), None),
        Err(e) => (None, Some(e)),
    };
    let same_relations = figures
        .as_ref()
        .and_then(|f| default.mean_on_relations_of(f));
    VariantReport {
        name: name.to_string(),
        ratio: figures
            .as_ref()
            .map(|f| f.trans_mean / same_relations.unwrap_or(default.trans_mean)),
        default_trans_mean: same_relations,
        figures,
        error,
    }
}

#[cfg(test)]
mod tests;
