//! What an experiment reports (`summary.json`, `worlds.json` and the printed tables), as typed
//! reports that serialise. A figure that cannot be computed (a ratio over zero, a mean of no
//! scans) is NaN in memory and `null` in the JSON.

use qicp_eval::{AteReport, RelationsReport};
use qicp_runner::matching::MatchSummary;
use serde::Serialize;
use std::collections::BTreeMap;

/// A trajectory against ground truth (ATE after origin alignment, RPE per metre).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthFigures {
    /// Root mean square of the position errors (m).
    pub ate_rmse_m: f64,
    /// Translational drift per metre travelled (share).
    pub rpe_trans_per_m: f64,
    /// Rotational drift per metre travelled (deg/m).
    pub rpe_rot_deg_per_m: f64,
    /// Position error at the end (m).
    pub final_error_m: f64,
}

impl From<&AteReport> for TruthFigures {
    fn from(a: &AteReport) -> Self {
        Self {
            ate_rmse_m: a.ate_rmse_m,
            rpe_trans_per_m: a.rpe_trans_per_m,
            rpe_rot_deg_per_m: a.rpe_rot_deg_per_m,
            final_error_m: a.final_error_m,
        }
    }
}

/// What one trajectory scores, with whatever the source has to score it against.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Scored {
    /// Against ground truth, where known (its fields stand at this level in the JSON).
    #[serde(flatten)]
    pub truth: Option<TruthFigures>,
    /// Against Freiburg relations, where given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relations: Option<RelationsReport>,
}

/// One matcher's figures: its scores and how its matching went.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MatcherFigures {
    /// The trajectory's scores (their fields stand at this level in the JSON).
    #[serde(flatten)]
    pub scores: Scored,
    /// Mean residual correlation distance (mm).
    pub residual_mean_mm: f64,
    /// Mean matching certainty (m²).
    pub certainty_mean: f64,
    /// Mean position standard deviation (mm).
    pub sigma_mean_mm: f64,
    /// Median time per scan (ms).
    pub ms_per_scan_median: f64,
    /// 99th percentile of the time per scan (ms).
    pub ms_per_scan_p99: f64,
    /// Points in the reference at the end.
    pub map_points: usize,
    /// Scans that kept the prediction.
    pub fallbacks: usize,
    /// … by reason.
    pub fallback_reasons: BTreeMap<String, usize>,
    /// Scans inserted into the reference.
    pub inserted: usize,
    /// Correlative searches run.
    pub searched: usize,
    /// … that recovered the match.
    pub recovered: usize,
    /// Matches the validation refused.
    pub refused: usize,
    /// Matches kept out of the map.
    pub withheld: usize,
    /// Matches re-anchored to the old map on a revisit.
    pub reanchored: usize,
    /// Wall time of the match loop (s).
    pub matching_seconds: f64,
}

impl MatcherFigures {
    /// The figures of a run summarised by `summary` and scored `scores`.
    #[must_use]
    pub fn new(scores: Scored, s: &MatchSummary) -> Self {
        Self {
            scores,
            residual_mean_mm: s.residual_mean_mm,
            certainty_mean: s.certainty_mean,
            sigma_mean_mm: s.sigma_mean_mm,
            ms_per_scan_median: s.ms_per_scan_median,
            ms_per_scan_p99: s.ms_per_scan_p99,
            map_points: s.map_points,
            fallbacks: s.fallbacks,
            fallback_reasons: s.fallback_reasons.clone(),
            inserted: s.inserted,
            searched: s.searched,
            recovered: s.recovered,
            refused: s.refused,
            withheld: s.withheld,
            reanchored: s.reanchored,
            matching_seconds: s.wall_seconds,
        }
    }
}

/// A boosted matcher over its scan-to-scan twin (same algorithm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Ratios {
    /// ATE, with ground truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ate: Option<f64>,
    /// Final position error, with ground truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_error: Option<f64>,
    /// Mean translational relation error, with relations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relations_trans: Option<f64>,
    /// Mean residual, over the scans both matchers matched (neither fell back).
    pub residual: f64,
    /// Mean certainty, over the scans both matched.
    pub certainty: f64,
    /// Mean position σ, over the scans both matched.
    pub sigma: f64,
    /// The scans both matched: the three means' scans.
    pub scans_both_matched: usize,
    /// Mean of the per-scan certainty ratios (paper Fig. 4c-d).
    pub certainty_per_scan_mean: f64,
    /// Their median: the mean is at the mercy of a few near-degenerate incremental matches.
    pub certainty_per_scan_median: f64,
}

/// `summary.json` of one experiment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExperimentSummary {
    /// The source's name.
    pub source: String,
    /// The experiment file.
    pub config: String,
    /// Scans in the drive or log.
    pub scans: usize,
    /// Whether the scores include ground truth.
    pub ground_truth: bool,
    /// Per matcher kind.
    pub matchers: BTreeMap<String, MatcherFigures>,
    /// Raw odometry's scores.
    pub odometry: Scored,
    /// Per boosted kind whose twin also ran, as `"q-wsm/wsm"`.
    pub ratios: BTreeMap<String, Ratios>,
    /// The pictures drawn: file name → what it shows.
    pub pictures: BTreeMap<String, String>,
    /// Time to load or simulate the source and score raw odometry (s).
    pub source_seconds: f64,
    /// Time running the matchers (s).
    pub matching_seconds: f64,
    /// Time drawing the pictures (s).
    pub plot_seconds: f64,
    /// The whole experiment (s).
    pub wall_seconds: f64,
}

/// The median, minimum and maximum of the finite values among some (`null`s when none is),
/// and how many of them were finite: a world whose figure is not a number (a matcher that
/// fell back on every scan has no residual) is left out, and `n` says so.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Spread {
    /// The median (of an even count, the mean of the two middle values).
    pub median: Option<f64>,
    /// The least.
    pub min: Option<f64>,
    /// The greatest.
    pub max: Option<f64>,
    /// The finite values the spread is of.
    pub n: usize,
}

impl Spread {
    /// The spread of the finite `values`.
    #[must_use]
    pub fn of(values: &[f64]) -> Self {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        Self {
            median: Some(median),
            min: Some(v[0]),
            max: Some(v[n - 1]),
            n,
        }
    }
}

/// `worlds.json`: one experiment over several simulated worlds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorldsReport {
    /// The source's name (the first world's).
    pub source: String,
    /// The experiment file.
    pub config: String,
    /// The worlds' layout seeds.
    pub world_seeds: Vec<u64>,
    /// The drives' noise seeds, one per world.
    pub noise_seeds: Vec<u64>,
    /// Scans per world.
    pub scans: Spread,
    /// Per matcher kind, per figure ([`WORLD_FIGURES`]).
    pub matchers: BTreeMap<String, BTreeMap<&'static str, Spread>>,
    /// Per boosted / incremental pair, per ratio ([`WORLD_RATIOS`]).
    pub ratios: BTreeMap<String, BTreeMap<&'static str, Spread>>,
    /// The whole run (s).
    pub wall_seconds: f64,
}

/// A figure that a matcher's figures give, NaN where they do not.
pub type Figure<T> = (&'static str, fn(&T) -> f64);

fn truth(m: &MatcherFigures, get: fn(&TruthFigures) -> f64) -> f64 {
    m.scores.truth.as_ref().map_or(f64::NAN, get)
}

/// Figures of one matcher summarised over the worlds of `--worlds`.
pub const WORLD_FIGURES: [Figure<MatcherFigures>; 8] = [
    ("ate_rmse_m", |m| truth(m, |t| t.ate_rmse_m)),
    ("final_error_m", |m| truth(m, |t| t.final_error_m)),
    ("rpe_trans_per_m", |m| truth(m, |t| t.rpe_trans_per_m)),
    ("residual_mean_mm", |m| m.residual_mean_mm),
    ("certainty_mean", |m| m.certainty_mean),
    ("sigma_mean_mm", |m| m.sigma_mean_mm),
    ("ms_per_scan_median", |m| m.ms_per_scan_median),
    ("fallbacks", |m| m.fallbacks as f64),
];

/// Ratios of a boosted / incremental pair summarised over the worlds of `--worlds`.
pub const WORLD_RATIOS: [Figure<Ratios>; 6] = [
    ("ate", |r| r.ate.unwrap_or(f64::NAN)),
    ("final_error", |r| r.final_error.unwrap_or(f64::NAN)),
    ("residual", |r| r.residual),
    ("certainty", |r| r.certainty),
    ("sigma", |r| r.sigma),
    ("certainty_per_scan_median", |r| r.certainty_per_scan_median),
];
