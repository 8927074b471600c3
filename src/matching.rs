//! Running a matcher over a sequence of records: the loop behind `qicp match`, `qicp run`
//! and the bridge's matcher process.

use crate::logs::tum::{Stamped, write_tum};
use anyhow::{Context, Result};
use qicp_core::{Fallback, Record};
use qicp_matchers::{Check, Estimate, MatcherConfig, Odometry};
use serde::Serialize;
use std::io::Write;
use std::path::Path;
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
    /// Points in the reference at the end (the whole map for boosted matchers).
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

/// The `q`-quantile of `values` (nearest rank); NaN for none.
#[must_use]
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for v in values.filter(|v| v.is_finite()) {
        sum += v;
        n += 1;
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

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

/// A matcher consuming records one at a time (in time order), keeping the trajectory and the
/// per-scan figures: the loop behind every command, in-process or fed by the bridge.
#[derive(Debug)]
pub struct Matching {
    kind: String,
    odometry: Box<dyn Odometry>,
    trajectory: Vec<Stamped>,
    rows: Vec<ScanRow>,
    busy: std::time::Duration,
}

impl Matching {
    /// A fresh run of the matcher `config` describes.
    pub fn new(config: &MatcherConfig) -> Result<Self> {
        Ok(Self {
            kind: config.kind.name().to_string(),
            odometry: config.build()?,
            trajectory: Vec::new(),
            rows: Vec::new(),
            busy: std::time::Duration::ZERO,
        })
    }

    /// Matches one record and returns the estimate.
    pub fn push(&mut self, record: &Record) -> Estimate {
        let t0 = Instant::now();
        let estimate = self.odometry.process(record);
        let elapsed = t0.elapsed();
        self.busy += elapsed;
        let Estimate {
            pose,
            result,
            inserted,
            check,
        } = estimate;
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
        self.trajectory.push((record.timestamp(), pose));
        self.rows.push(ScanRow {
            timestamp: record.timestamp(),
            iterations: result.iterations,
            correspondences: result.correspondences,
            residual_mm,
            certainty,
            sigma_mm,
            ms: elapsed.as_secs_f64() * 1e3,
            inserted,
            fallback: result.fallback,
            check,
        });
        estimate
    }

    /// Ends the run: totals and the pipeline (with its map).
    #[must_use]
    pub fn finish(self) -> MatchRun {
        let rows = self.rows;
        let times: Vec<f64> = rows.iter().map(|r| r.ms).collect();
        let mut reasons = std::collections::BTreeMap::new();
        for f in rows.iter().filter_map(|r| r.fallback) {
            let key = match f {
                Fallback::TooFewPoints { .. } => "too_few_points",
                Fallback::TooFewCorrespondences { .. } => "too_few_correspondences",
                Fallback::EmptyReference => "empty_reference",
                Fallback::Degenerate => "degenerate",
                Fallback::Refused => "refused",
            };
            *reasons.entry(key.to_string()).or_insert(0) += 1;
        }
        let summary = MatchSummary {
            matcher: self.kind,
            scans: rows.len(),
            ms_per_scan_median: quantile(&times, 0.5),
            ms_per_scan_p99: quantile(&times, 0.99),
            wall_seconds: self.busy.as_secs_f64(),
            map_points: self.odometry.reference_points().len(),
            residual_mean_mm: mean(rows.iter().map(|r| r.residual_mm)),
            certainty_mean: mean(rows.iter().map(|r| r.certainty)),
            sigma_mean_mm: mean(rows.iter().map(|r| r.sigma_mm)),
            fallbacks: rows.iter().filter(|r| r.fallback.is_some()).count(),
            fallback_reasons: reasons,
            inserted: rows.iter().filter(|r| r.inserted).count(),
            searched: rows.iter().filter(|r| r.check.searched).count(),
            recovered: rows.iter().filter(|r| r.check.recovered).count(),
            refused: rows.iter().filter(|r| r.check.refused).count(),
        };
        MatchRun {
            trajectory: self.trajectory,
            rows,
            summary,
            odometry: self.odometry,
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
        progress_bar(records.len(), config.kind.name())
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

/// The `check` column of `matches.csv`: `refused`, `recovered`, `searched` or empty.
fn check_label(check: &Check) -> &'static str {
    match (check.refused, check.recovered, check.searched) {
        (true, _, _) => "refused",
        (false, true, _) => "recovered",
        (false, false, true) => "searched",
        _ => "",
    }
}

/// Writes `matches.csv`.
pub fn write_rows<W: Write>(mut w: W, rows: &[ScanRow]) -> std::io::Result<()> {
    writeln!(
        w,
        "timestamp,iterations,correspondences,residual_mm,certainty,ms,inserted,fallback,sigma_mm,\
         inlier_share,check"
    )?;
    for r in rows {
        writeln!(
            w,
            "{},{},{},{:.4},{:.6e},{:.4},{},{},{:.4},{:.4},{}",
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
        )?;
    }
    Ok(())
}

/// Writes `trajectory.tum`, `matches.csv` and `config.toml` of a run into `dir`.
pub fn write_run(dir: &Path, run: &MatchRun, config: &MatcherConfig) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let create = |name: &str| -> Result<std::io::BufWriter<std::fs::File>> {
        let path = dir.join(name);
        Ok(std::io::BufWriter::new(
            std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?,
        ))
    };
    write_tum(create("trajectory.tum")?, &run.trajectory).context("writing trajectory.tum")?;
    write_rows(create("matches.csv")?, &run.rows).context("writing matches.csv")?;
    std::fs::write(dir.join("config.toml"), config.to_toml()).context("writing config.toml")?;
    Ok(())
}
