//! Running a matcher over a sequence of records: the loop behind `qicp match`, `qicp run`
//! and the bridge's matcher process.

use anyhow::{Context, Result};
use qicp_core::{Fallback, Record};
use qicp_io::tum::{Stamped, write_tum_pose};
use qicp_matchers::trail::Amendment;
use qicp_matchers::{Check, Estimate, MatcherConfig, Odometry};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

pub use crate::output::{CreatedDir, OutputFile, remove_on_hangup, remove_on_signal, write_atomic};
use std::time::Instant;

/// Per-scan figures, one row of `matches.csv`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScanRow {
    /// Record timestamp (s).
    pub timestamp: f64,
    /// Iterations the matcher ran.
    pub iterations: u32,
    /// Correspondences in the final iteration.
    pub correspondences: usize,
    /// Residual correlation distance (mm); NaN for a fallback.
    pub residual_mm: f64,
    /// Matching certainty sqrt(σxx² + σyy²) of the paper's Fig. 4c-d (m²); NaN for a
    /// fallback. See [`MatchResult::certainty`](qicp_core::MatchResult::certainty).
    pub certainty: f64,
    /// Position standard deviation sqrt(σxx + σyy) (mm); NaN for a fallback.
    pub sigma_mm: f64,
    /// Wall time of this scan (ms).
    pub ms: f64,
    /// Whether the scan entered the reference.
    pub inserted: bool,
    /// Why the scan fell back to odometry, if it did.
    #[serde(skip)]
    pub fallback: Option<Fallback>,
    /// What the check before insertion said.
    #[serde(skip)]
    pub check: Check,
}

/// Summary of one matcher over one drive (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MatchSummary {
    /// Registry name of the matcher.
    pub matcher: String,
    /// Records processed.
    pub scans: usize,
    /// Median wall time per scan (ms).
    pub ms_per_scan_median: f64,
    /// 99th percentile of the wall time per scan (ms).
    pub ms_per_scan_p99: f64,
    /// Total time spent matching (s), the sum over scans.
    pub wall_seconds: f64,
    /// Live points in the reference at the end (the whole map for boosted matchers), without
    /// those a full cell replaced or carving removed that the index has not dropped yet.
    pub map_points: usize,
    /// Mean residual correlation distance over matched scans (mm).
    pub residual_mean_mm: f64,
    /// Mean matching certainty over matched scans (m²).
    pub certainty_mean: f64,
    /// Mean position standard deviation over matched scans (mm).
    pub sigma_mean_mm: f64,
    /// Scans that fell back to odometry (the first scan, with nothing to match, included).
    pub fallbacks: usize,
    /// Fallbacks by reason.
    pub fallback_reasons: std::collections::BTreeMap<String, usize>,
    /// Scans that entered the reference.
    pub inserted: usize,
    /// Matches that looked wrong, so the correlative search ran.
    pub searched: usize,
    /// … of which the search's start gave a better match, which replaced the first.
    pub recovered: usize,
    /// Matches that stayed poor and did not enter the reference.
    pub refused: usize,
    /// Matches that odometry contradicted: reported, but kept out of the map.
    pub withheld: usize,
    /// Matches re-anchored to the old map on a revisit.
    pub reanchored: usize,
    /// Matches that kept odometry's estimate along the direction the scan does not fix
    /// (`[matcher.motion] hold_unobserved`).
    pub held: usize,
}

impl MatchSummary {
    /// A warning when most scans fell back to odometry (more than half, of two or more): the
    /// trajectory is then mostly odometry, which a configuration out of reach of the data (a
    /// noise model a thousand times off, a correspondence count above the beams) produces
    /// without any error.
    #[must_use]
    pub fn fallback_warning(&self) -> Option<String> {
        if self.scans < 2 || 2 * self.fallbacks <= self.scans {
            return None;
        }
        let reasons: Vec<String> = self
            .fallback_reasons
            .iter()
            .map(|(why, n)| format!("{why}: {n}"))
            .collect();
        Some(format!(
            "{} of {} scans fell back to odometry ({}): the trajectory is mostly odometry; \
             check the matcher's configuration against the log",
            self.fallbacks,
            self.scans,
            reasons.join(", ")
        ))
    }
}

/// A matcher's whole run over a drive.
#[derive(Debug)]
pub struct MatchRun {
    /// Robot pose at every record's timestamp.
    pub trajectory: Vec<Stamped>,
    /// Per-scan figures.
    pub rows: Vec<ScanRow>,
    /// Totals.
    pub summary: MatchSummary,
    /// The pipeline after the run (its map, for pictures).
    pub odometry: Box<dyn Odometry>,
}

pub use qicp_eval::stats::quantile;

mod histogram;
pub use histogram::TimeHistogram;

/// A progress bar on a terminal, nothing otherwise (CI, pipes).
#[must_use]
pub fn progress_bar(len: usize, label: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len as u64);
    let style = indicatif::ProgressStyle::with_template(
        "{prefix:>8} [{bar:30}] {pos}/{len} scans {per_sec} eta {eta}",
    )
    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
    .progress_chars("=> ");
    bar.set_style(style);
    bar.set_prefix(label.to_string());
    bar
}

/// Running totals of a run, from which [`MatchSummary`] is made: bounded memory whatever the
/// number of scans.
#[derive(Debug, Clone, Default)]
struct RunTotals {
    scans: usize,
    times: TimeHistogram,
    residual: (f64, usize),
    certainty: (f64, usize),
    sigma: (f64, usize),
    fallbacks: usize,
    reasons: std::collections::BTreeMap<String, usize>,
    inserted: usize,
    searched: usize,
    recovered: usize,
    refused: usize,
    withheld: usize,
    reanchored: usize,
    held: usize,
}

impl RunTotals {
    fn add(&mut self, r: &ScanRow) {
        let sum = |acc: &mut (f64, usize), v: f64| {
            if v.is_finite() {
                acc.0 += v;
                acc.1 += 1;
            }
        };
        self.scans += 1;
        self.times.add(r.ms);
        sum(&mut self.residual, r.residual_mm);
        sum(&mut self.certainty, r.certainty);
        sum(&mut self.sigma, r.sigma_mm);
        if let Some(f) = r.fallback {
            self.fallbacks += 1;
            let key = match f {
                Fallback::TooFewPoints { .. } => "too_few_points",
                Fallback::TooFewCorrespondences { .. } => "too_few_correspondences",
                Fallback::EmptyReference => "empty_reference",
                Fallback::Degenerate => "degenerate",
                Fallback::Refused => "refused",
            };
            *self.reasons.entry(key.to_string()).or_insert(0) += 1;
        }
        self.inserted += usize::from(r.inserted);
        self.searched += usize::from(r.check.searched);
        self.recovered += usize::from(r.check.recovered);
        self.refused += usize::from(r.check.refused);
        self.withheld += usize::from(r.check.withheld);
        self.reanchored += usize::from(r.check.reanchored);
        self.held += usize::from(r.check.held);
    }

    fn summary(&self, matcher: &str, busy: std::time::Duration, map_points: usize) -> MatchSummary {
        let mean = |(sum, n): (f64, usize)| if n == 0 { f64::NAN } else { sum / n as f64 };
        MatchSummary {
            matcher: matcher.to_string(),
            scans: self.scans,
            ms_per_scan_median: self.times.quantile(0.5),
            ms_per_scan_p99: self.times.quantile(0.99),
            wall_seconds: busy.as_secs_f64(),
            map_points,
            residual_mean_mm: mean(self.residual),
            certainty_mean: mean(self.certainty),
            sigma_mean_mm: mean(self.sigma),
            fallbacks: self.fallbacks,
            fallback_reasons: self.reasons.clone(),
            inserted: self.inserted,
            searched: self.searched,
            recovered: self.recovered,
            refused: self.refused,
            withheld: self.withheld,
            reanchored: self.reanchored,
            held: self.held,
        }
    }
}

/// A spinner counting scans on a terminal (for streams of unknown length), nothing otherwise.
#[must_use]
pub fn progress_spinner(label: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner();
    let style =
        indicatif::ProgressStyle::with_template("{prefix:>8} {spinner} {pos} scans {per_sec}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner());
    bar.set_style(style);
    bar.set_prefix(label.to_string());
    bar
}

/// A matcher consuming records one at a time (in time order) and keeping running totals:
/// the loop behind every command, in-process or fed by the bridge. Memory does not grow with
/// the number of scans beyond the matcher's own reference; [`Matching`] keeps the trajectory
/// and rows as well.
#[derive(Debug)]
pub struct MatchLoop {
    kind: String,
    odometry: Box<dyn Odometry>,
    totals: RunTotals,
    busy: std::time::Duration,
}

impl MatchLoop {
    /// A fresh run of the matcher `config` describes.
    pub fn new(config: &MatcherConfig) -> Result<Self> {
        Ok(Self {
            kind: config.kind(),
            odometry: config.build()?,
            totals: RunTotals::default(),
            busy: std::time::Duration::ZERO,
        })
    }

    /// Matches one record: the estimate and its row of `matches.csv`.
    pub fn push(&mut self, record: &Record) -> (Estimate, ScanRow) {
        let t0 = Instant::now();
        let estimate = self.odometry.process(record);
        let elapsed = t0.elapsed();
        self.busy += elapsed;
        let result = &estimate.result;
        // A fallback has no residual or covariance of its own.
        let (residual_mm, certainty, sigma_mm) = if result.fallback.is_none() {
            (
                result.residual * 1e3,
                result.certainty(),
                result.position_sigma() * 1e3,
            )
        } else {
            (f64::NAN, f64::NAN, f64::NAN)
        };
        let row = ScanRow {
            timestamp: record.timestamp(),
            iterations: result.iterations,
            correspondences: result.correspondences,
            residual_mm,
            certainty,
            sigma_mm,
            ms: elapsed.as_secs_f64() * 1e3,
            inserted: estimate.inserted,
            fallback: result.fallback,
            check: estimate.check,
        };
        self.totals.add(&row);
        (estimate, row)
    }

    /// A correction of earlier records' poses made by the last [`MatchLoop::push`], once
    /// ([`Odometry::take_amendment`]).
    pub fn take_amendment(&mut self) -> Option<Amendment> {
        self.odometry.take_amendment()
    }

    /// Whether [`MatchLoop::take_amendment`] can ever give one ([`Odometry::amends`]).
    #[must_use]
    pub fn amends(&self) -> bool {
        self.odometry.amends()
    }

    /// The totals so far.
    #[must_use]
    pub fn summary(&self) -> MatchSummary {
        self.totals
            .summary(&self.kind, self.busy, self.odometry.live_len())
    }

    /// Ends the run: totals and the pipeline (with its map).
    #[must_use]
    pub fn finish(self) -> (MatchSummary, Box<dyn Odometry>) {
        (self.summary(), self.odometry)
    }
}

/// A [`MatchLoop`] that keeps the whole trajectory and every row in memory, for experiments,
/// sweeps and figures.
#[derive(Debug)]
pub struct Matching {
    inner: MatchLoop,
    trajectory: Vec<Stamped>,
    rows: Vec<ScanRow>,
}

impl Matching {
    /// A fresh run of the matcher `config` describes.
    pub fn new(config: &MatcherConfig) -> Result<Self> {
        Ok(Self {
            inner: MatchLoop::new(config)?,
            trajectory: Vec::new(),
            rows: Vec::new(),
        })
    }

    /// Matches one record and returns the estimate.
    pub fn push(&mut self, record: &Record) -> Estimate {
        let (estimate, row) = self.inner.push(record);
        if let Some(amendment) = self.inner.take_amendment() {
            amendment.apply(&mut self.trajectory, |(_, pose)| pose);
        }
        self.trajectory.push((record.timestamp(), estimate.pose));
        self.rows.push(row);
        estimate
    }

    /// Ends the run: totals and the pipeline (with its map).
    #[must_use]
    pub fn finish(self) -> MatchRun {
        let (summary, odometry) = self.inner.finish();
        MatchRun {
            trajectory: self.trajectory,
            rows: self.rows,
            summary,
            odometry,
        }
    }
}

/// Runs the matcher `config` describes over `records` (in time order).
pub fn run_matcher(
    records: &[Record],
    config: &MatcherConfig,
    show_progress: bool,
) -> Result<MatchRun> {
    let mut matching = Matching::new(config)?;
    let bar = if show_progress {
        progress_bar(records.len(), &config.kind())
    } else {
        indicatif::ProgressBar::hidden()
    };
    for record in records {
        matching.push(record);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(matching.finish())
}

/// The `check` column of `matches.csv`: `refused`, `reanchored`, `recovered`, `searched`,
/// `withheld` or empty.
fn check_label(check: &Check) -> &'static str {
    match (
        check.refused,
        check.reanchored,
        check.recovered,
        check.searched,
        check.withheld,
    ) {
        (true, ..) => "refused",
        (false, true, ..) => "reanchored",
        (false, false, true, ..) => "recovered",
        (false, false, false, true, _) => "searched",
        (false, false, false, false, true) => "withheld",
        _ => "",
    }
}

/// Writes `matches.csv`.
pub fn write_rows<W: Write>(mut w: W, rows: &[ScanRow]) -> std::io::Result<()> {
    write_rows_header(&mut w)?;
    for r in rows {
        write_row(&mut w, r)?;
    }
    Ok(())
}

/// The header line of `matches.csv`.
fn write_rows_header<W: Write>(w: &mut W) -> std::io::Result<()> {
    writeln!(
        w,
        "timestamp,iterations,correspondences,residual_mm,certainty,ms,inserted,fallback,sigma_mm,\
         inlier_share,check,held"
    )
}

/// One line of `matches.csv`.
fn write_row<W: Write>(w: &mut W, r: &ScanRow) -> std::io::Result<()> {
    writeln!(
        w,
        "{},{},{},{:.4},{:.6e},{:.4},{},{},{:.4},{:.4},{},{}",
        r.timestamp,
        r.iterations,
        r.correspondences,
        r.residual_mm,
        r.certainty,
        r.ms,
        u8::from(r.inserted),
        r.fallback.map(|f| f.to_string()).unwrap_or_default(),
        r.sigma_mm,
        r.check.inlier_share,
        check_label(&r.check),
        u8::from(r.check.held),
    )
}

/// The output files of a run, written as the scans come and put in place only when the run
/// is complete: each file is first written under a temporary name in the output directory and
/// renamed at [`RunWriter::commit`]; a run that fails or is dropped leaves no partial file
/// ([`OutputFile`]; with [`crate::output::remove_on_signal`], neither does one stopped by a
/// signal).
///
/// The directory is created and its files opened before any matching, so a bad `--out` fails
/// at once.
#[derive(Debug)]
pub struct RunWriter {
    dir: std::path::PathBuf,
    trajectory: OutputFile,
    /// The poses so far (32 bytes a record), written at [`RunWriter::commit`], where a
    /// re-anchoring spread over the stretch before it may amend them ([`RunWriter::amend`]);
    /// `None` writes each pose as it comes.
    poses: Option<Vec<Stamped>>,
    matches: OutputFile,
    // Last, so that it is dropped after the files have removed their temporaries.
    made: CreatedDir,
}

impl RunWriter {
    /// The files [`RunWriter::commit`] writes into `dir`.
    pub const FILES: [&'static str; 4] = [
        "trajectory.tum",
        "matches.csv",
        "config.toml",
        "summary.json",
    ];

    /// Creates `dir` if needed and opens the temporary files in it.
    pub fn create(dir: &Path) -> Result<Self> {
        let made = CreatedDir::create(dir)?;
        let trajectory = OutputFile::create(&dir.join("trajectory.tum"))?;
        let mut matches = OutputFile::create(&dir.join("matches.csv"))?;
        write_rows_header(&mut matches).context("writing matches.csv")?;
        Ok(Self {
            dir: dir.to_path_buf(),
            trajectory,
            poses: None,
            matches,
            made,
        })
    }

    /// Keeps the poses until [`RunWriter::commit`] when `keep` (for a matcher that may amend
    /// them, [`MatchLoop::amends`]) instead of writing each as it comes.
    #[must_use]
    pub fn keeping_poses(mut self, keep: bool) -> Self {
        self.poses = keep.then(Vec::new);
        self
    }

    /// Appends one scan's pose and row.
    pub fn push(&mut self, timestamp: f64, pose: &qicp_core::Pose2, row: &ScanRow) -> Result<()> {
        match &mut self.poses {
            Some(poses) => poses.push((timestamp, *pose)),
            None => write_tum_pose(&mut self.trajectory, timestamp, pose)
                .context("writing trajectory.tum")?,
        }
        write_row(&mut self.matches, row).context("writing matches.csv")?;
        Ok(())
    }

    /// Moves the poses pushed so far as `amendment` says (by their order of pushing). Poses
    /// already written are not kept and cannot be moved: a writer that may be amended must
    /// keep them ([`RunWriter::keeping_poses`]).
    pub fn amend(&mut self, amendment: &Amendment) -> Result<()> {
        let Some(poses) = &mut self.poses else {
            anyhow::bail!("trajectory.tum: a correction of poses already written (keep them)");
        };
        amendment.apply(poses, |(_, pose)| pose);
        Ok(())
    }

    /// Writes `config.toml` and `summary.json` (when given) and renames every file into place.
    pub fn commit(mut self, config: &MatcherConfig, summary: Option<&str>) -> Result<()> {
        for (t, pose) in self.poses.iter().flatten() {
            write_tum_pose(&mut self.trajectory, *t, pose).context("writing trajectory.tum")?;
        }
        self.trajectory.commit()?;
        self.matches.commit()?;
        write_atomic(&self.dir.join("config.toml"), config.to_toml().as_bytes())?;
        if let Some(text) = summary {
            write_atomic(&self.dir.join("summary.json"), text.as_bytes())?;
        }
        self.made.keep();
        Ok(())
    }
}

/// A ROS 2 bag written under a temporary name beside its path and renamed into place by
/// [`BagOutput::commit`]; dropped before, it leaves no file.
#[derive(Debug)]
pub struct BagOutput {
    /// The bag, written to its temporary file.
    pub writer: qicp_io::rosbag::BagWriter<OutputFile>,
}

impl BagOutput {
    /// Opens the temporary file beside `path` (a bad directory fails here, before any work).
    pub fn create(path: &std::path::Path) -> Result<Self> {
        let writer = qicp_io::rosbag::BagWriter::new(
            OutputFile::create(path)?,
            &path.display().to_string(),
            qicp_io::rosbag::BagLayout::default(),
        )?;
        Ok(Self { writer })
    }

    /// Finishes the bag and renames it into place.
    pub fn commit(self) -> Result<()> {
        self.writer.finish()?.commit()
    }
}

/// Writes `trajectory.tum`, `matches.csv` and `config.toml` of a run into `dir`, each renamed
/// into place when complete.
pub fn write_run(dir: &Path, run: &MatchRun, config: &MatcherConfig) -> Result<()> {
    let mut writer = RunWriter::create(dir)?;
    for ((t, pose), row) in run.trajectory.iter().zip(&run.rows) {
        writer.push(*t, pose, row)?;
    }
    writer.commit(config, None)
}
