//! The iteration parameters and helpers every ICP-style matcher shares.

use crate::ConfigError;
use qicp_core::{Pair, Point2, Pose2, Reference, SpatialIndex};
use serde::{Deserialize, Serialize};

/// How an ICP-style matcher iterates (TOML section `[matcher.icp]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IcpParams {
    /// Most iterations per scan. Default 60.
    pub max_iterations: u32,
    /// Pairs farther apart than this are outliers at first (m). Default 1.0.
    pub max_dist_start: f64,
    /// Each time the estimate settles, the gate shrinks by `shrink`, down to this (m).
    /// Default 0.2.
    pub max_dist_end: f64,
    /// Factor by which the gate (and IDC's window) shrinks once the estimate settles, in
    /// (0, 1).
    /// Default 0.5.
    pub shrink: f64,
    /// Iterations at one gate after which it shrinks even if the estimate has not settled.
    /// Default 8.
    pub stage_iterations: u32,
    /// Pairs farther apart than this many times the median pair distance are dropped
    /// (0 disables). Default 0: in a corridor the few pairs that fix the motion along it
    /// are exactly the far ones.
    pub trim: f64,
    /// Fewer pairs than this and the scan falls back to the initial guess. Default 12.
    pub min_correspondences: usize,
    /// Converged when a step moves less than this (m)… Default 1e-4.
    pub tolerance_translation: f64,
    /// … and turns less than this (rad), with the gate at its end value. Default 1e-4.
    pub tolerance_rotation: f64,
}

impl Default for IcpParams {
    fn default() -> Self {
        Self {
            max_iterations: 60,
            max_dist_start: 1.0,
            max_dist_end: 0.2,
            shrink: 0.5,
            stage_iterations: 8,
            trim: 0.0,
            min_correspondences: 12,
            tolerance_translation: 1e-4,
            tolerance_rotation: 1e-4,
        }
    }
}

/// Refuses a value that is not finite and positive.
pub(crate) fn positive(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            key,
            format!("{v} must be finite and > 0"),
        ))
    }
}

/// The most ICP iterations a match may run: far above what converging matches need (tens),
/// low enough that a typo cannot hang a run.
pub const MAX_ITERATIONS: u32 = 10_000;

/// Refuses a value that is negative or not finite.
pub(crate) fn non_negative(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            key,
            format!("{v} must be finite and ≥ 0"),
        ))
    }
}

impl IcpParams {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(1..=MAX_ITERATIONS).contains(&self.max_iterations) {
            return Err(ConfigError::invalid(
                "matcher.icp.max_iterations",
                format!("{} must lie in 1..={MAX_ITERATIONS}", self.max_iterations),
            ));
        }
        positive("matcher.icp.max_dist_start", self.max_dist_start)?;
        positive("matcher.icp.max_dist_end", self.max_dist_end)?;
        if self.max_dist_end > self.max_dist_start {
            return Err(ConfigError::invalid(
                "matcher.icp.max_dist_end",
                format!(
                    "{} exceeds max_dist_start {}",
                    self.max_dist_end, self.max_dist_start
                ),
            ));
        }
        if self.stage_iterations == 0 {
            return Err(ConfigError::invalid(
                "matcher.icp.stage_iterations",
                "must be at least 1",
            ));
        }
        // At 1 a gate above max_dist_end would never reach it: every match would run all its
        // iterations and report no convergence.
        if !(self.shrink > 0.0 && self.shrink < 1.0) {
            return Err(ConfigError::invalid(
                "matcher.icp.shrink",
                format!("{} must be in (0, 1)", self.shrink),
            ));
        }
        if !(self.trim.is_finite() && (self.trim == 0.0 || self.trim >= 1.0)) {
            return Err(ConfigError::invalid(
                "matcher.icp.trim",
                format!("{} must be 0 (off) or ≥ 1", self.trim),
            ));
        }
        if self.min_correspondences < 3 {
            return Err(ConfigError::invalid(
                "matcher.icp.min_correspondences",
                "must be at least 3",
            ));
        }
        positive(
            "matcher.icp.tolerance_translation",
            self.tolerance_translation,
        )?;
        positive("matcher.icp.tolerance_rotation", self.tolerance_rotation)
    }

    /// The outlier gate after it has shrunk `level` times.
    #[must_use]
    pub fn gate(&self, level: u32) -> f64 {
        (self.max_dist_start * self.shrink.powi(level as i32)).max(self.max_dist_end)
    }

    /// Why matching `scan` against `reference` cannot even start, if it cannot.
    #[must_use]
    pub fn cannot_match<I: SpatialIndex>(
        &self,
        scan: &qicp_core::Scan,
        reference: &Reference<I>,
    ) -> Option<qicp_core::Fallback> {
        let valid = scan.valid_count();
        if valid < self.min_correspondences {
            Some(qicp_core::Fallback::TooFewPoints { valid })
        } else if reference.is_empty() {
            Some(qicp_core::Fallback::EmptyReference)
        } else {
            None
        }
    }

    /// The level of the gate schedule to start at: with an odometry prior (information
    /// `prior`), the last level whose gate still holds `sigmas` of its translation standard
    /// deviations, at most one before the last level; 0 without a prior or with `sigmas` 0.
    /// The wide gates exist for large initial errors, and odometry says how large they can be.
    #[must_use]
    pub fn first_level(&self, prior: Option<&nalgebra::Matrix3<f64>>, sigmas: f64) -> u32 {
        let Some(lambda) = prior else { return 0 };
        let information = lambda[(0, 0)].min(lambda[(1, 1)]);
        if sigmas == 0.0 || information <= 0.0 {
            return 0;
        }
        let needed = sigmas / information.sqrt();
        let last = self.last_level();
        let mut level = 0;
        while level + 1 < last && self.gate(level + 1) >= needed {
            level += 1;
        }
        level
    }

    /// Number of shrinks from the first gate to the last.
    #[must_use]
    pub fn last_level(&self) -> u32 {
        if self.shrink >= 1.0 || self.max_dist_start <= self.max_dist_end {
            return 0;
        }
        ((self.max_dist_end / self.max_dist_start).ln() / self.shrink.ln()).ceil() as u32
    }

    /// True when the gate after `level` shrinks is at its end value.
    #[must_use]
    pub fn at_last_gate(&self, level: u32) -> bool {
        self.gate(level) <= self.max_dist_end
    }

    /// Stage bookkeeping for the shrinking gate: call [`Schedule::advance`] after every step.
    #[must_use]
    pub fn schedule(&self) -> Schedule {
        Schedule {
            level: 0,
            in_stage: 0,
        }
    }

    /// True when a step from `a` to `b` is below both tolerances.
    #[must_use]
    pub fn small_step(&self, a: &Pose2, b: &Pose2) -> bool {
        a.distance(b) < self.tolerance_translation
            && qicp_core::normalize_angle(a.theta - b.theta).abs() < self.tolerance_rotation
    }
}

/// Moves the scan points into the reference frame.
pub fn move_points(pose: &Pose2, local: &[Point2<f64>], out: &mut Vec<Point2<f64>>) {
    out.clear();
    out.extend(local.iter().map(|p| pose.transform_point(p)));
}

/// Drops pairs farther apart than `factor` × the median distance, keeping all within `floor`.
pub fn trim(pairs: &mut Vec<Pair>, factor: f64, floor: f64, scratch: &mut Vec<f64>) {
    if factor == 0.0 || pairs.len() < 4 {
        return;
    }
    scratch.clear();
    scratch.extend(pairs.iter().map(|p| p.dist_sq));
    let mid = scratch.len() / 2;
    let median = *scratch.select_nth_unstable_by(mid, f64::total_cmp).1;
    let limit = (median * factor * factor).max(floor * floor);
    pairs.retain(|p| p.dist_sq <= limit);
}

/// Residual correlation distance: mean distance of the pairs under `pose` (m).
pub fn residual<I: SpatialIndex>(
    reference: &Reference<I>,
    local: &[Point2<f64>],
    pairs: &[Pair],
    pose: &Pose2,
) -> f64 {
    if pairs.is_empty() {
        return f64::NAN;
    }
    let pts = reference.index().points();
    let sum: f64 = pairs
        .iter()
        .map(|p| (pts[p.reference as usize] - pose.transform_point(&local[p.scan as usize])).norm())
        .sum();
    sum / pairs.len() as f64
}

/// Where an iteration is in the gate schedule.
#[derive(Debug, Clone, Copy)]
pub struct Schedule {
    /// Times the gate has shrunk.
    pub level: u32,
    in_stage: u32,
}

impl Schedule {
    /// A schedule whose gate has already shrunk `level` times.
    #[must_use]
    pub fn at(level: u32) -> Self {
        Self { level, in_stage: 0 }
    }

    /// Records one step; returns true when the iteration has converged (settled at the last
    /// gate). The gate shrinks when the estimate settles or the stage's budget is spent.
    pub fn advance(&mut self, icp: &IcpParams, settled: bool, final_stage: bool) -> bool {
        self.in_stage += 1;
        if settled && final_stage {
            return true;
        }
        if (settled || self.in_stage >= icp.stage_iterations) && !final_stage {
            self.level += 1;
            self.in_stage = 0;
        }
        false
    }
}
