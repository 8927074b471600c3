//! What a matcher returns.

use crate::Pose2;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// Why a match fell back to the initial guess (odometry). Not an error: data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Fallback {
    /// The scan has fewer valid beams than the matcher needs.
    TooFewPoints {
        /// Valid beams in the scan.
        valid: usize,
    },
    /// Fewer correspondences than the matcher needs were found.
    TooFewCorrespondences {
        /// Correspondences found in the last iteration.
        found: usize,
    },
    /// There is nothing to match against yet (first scan, empty map).
    EmptyReference,
    /// The least-squares system was singular or produced a non-finite step.
    Degenerate,
    /// The match was refused by validation and the initial guess stands (see the matchers'
    /// validation): it explained the scan worse than the recent level and the guess explains
    /// it at least as well, or odometry contradicted it beyond its uncertainty and the points
    /// it explains beyond the guess's do not outweigh that disagreement.
    Refused,
}

impl std::fmt::Display for Fallback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fallback::TooFewPoints { valid } => write!(f, "too few valid beams ({valid})"),
            Fallback::TooFewCorrespondences { found } => {
                write!(f, "too few correspondences ({found})")
            }
            Fallback::EmptyReference => write!(f, "empty reference"),
            Fallback::Degenerate => write!(f, "degenerate least-squares system"),
            Fallback::Refused => write!(f, "match refused by validation"),
        }
    }
}

/// The outcome of matching one scan against a reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchResult {
    /// Pose of the scan in the reference frame.
    pub pose: Pose2,
    /// 3×3 covariance of `pose` (x, y, θ).
    pub covariance: Matrix3<f64>,
    /// Iterations run.
    pub iterations: u32,
    /// Correspondences in the final iteration.
    pub correspondences: usize,
    /// Residual correlation distance: mean distance of the final pairs after the estimate is
    /// applied (m). The paper's Fig. 4a-b, there in mm.
    pub residual: f64,
    /// Whether the iteration met its convergence test.
    pub converged: bool,
    /// Set when the pose is the initial guess because matching was not possible.
    pub fallback: Option<Fallback>,
}

impl MatchResult {
    /// A result that keeps the initial guess, with a covariance that says "unknown".
    #[must_use]
    pub fn fallback(guess: Pose2, why: Fallback) -> Self {
        Self {
            pose: guess,
            covariance: Matrix3::from_diagonal_element(1.0),
            iterations: 0,
            correspondences: 0,
            residual: f64::NAN,
            converged: false,
            fallback: Some(why),
        }
    }

    /// Matching certainty of the paper's Fig. 4c-d: its two on-diagonal position elements
    /// σxx, σyy (variances) combined into a Euclidean distance, `sqrt(σxx² + σyy²)` (m²).
    /// Smaller is more certain. A ratio of two certainties is about the square of the ratio of
    /// their [`position_sigma`](Self::position_sigma).
    #[must_use]
    pub fn certainty(&self) -> f64 {
        self.covariance[(0, 0)]
            .max(0.0)
            .hypot(self.covariance[(1, 1)].max(0.0))
    }

    /// Position standard deviation `sqrt(σxx + σyy)` (m): the root of the covariance's
    /// position trace, in the units of the pose.
    #[must_use]
    pub fn position_sigma(&self) -> f64 {
        (self.covariance[(0, 0)].max(0.0) + self.covariance[(1, 1)].max(0.0)).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn certainty_combines_the_position_variances() {
        let mut r = MatchResult::fallback(Pose2::IDENTITY, Fallback::EmptyReference);
        r.covariance = Matrix3::new(3e-4, 1e-5, 0.0, 1e-5, 4e-4, 0.0, 0.0, 0.0, 9.0);
        assert!((r.certainty() - 5e-4).abs() < 1e-15);
        assert!((r.position_sigma() - 7e-4f64.sqrt()).abs() < 1e-15);
    }
}
