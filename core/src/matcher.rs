//! The scan-matcher plug-in point.

use crate::index::SpatialIndex;
use crate::reference::Reference;
use crate::{MatchResult, Pose2, Scan};
use nalgebra::Matrix3;

/// Where a match's prior comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PriorSource {
    /// Odometry: a measurement of the motion since the last scan.
    Odometry,
    /// A motion model's prediction where no odometry moves (a log without odometry): the
    /// motion at the last velocity, no measurement.
    Prediction,
}

/// Estimates where a scan was taken, relative to a reference.
///
/// Generic over the reference's index so that the correspondence search, the hot loop, is
/// monomorphic. Failing to match is not an error: the result says so (`fallback`, `converged`).
pub trait ScanMatcher {
    /// Short name, e.g. `"wsm"`.
    fn name(&self) -> &'static str;

    /// The pose of `scan` in the frame of `reference`, starting from `guess`. `prior`, when
    /// given, is the information matrix (inverse covariance, in the reference frame's x, y, θ)
    /// of the guess itself, e.g. from an odometry motion model; matchers that weigh their
    /// pairs add it to their least squares, the others may ignore it.
    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult;

    /// [`match_with_prior`](Self::match_with_prior), told where the prior comes from
    /// ([`match_with_prior`](Self::match_with_prior) stands for odometry's). Matchers that
    /// trust a measured prior further than a prediction override it; by default the source
    /// is ignored.
    fn match_with_prior_from<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
        source: PriorSource,
    ) -> MatchResult {
        let _ = source;
        self.match_with_prior(reference, scan, guess, prior)
    }

    /// The spacing (m) below which a new map point adds nothing this matcher can use, for a
    /// laser of `noise`: the default density bound of a map it matches against
    /// (`matcher.relevance.map_resolution`). Default 0.02.
    fn map_resolution(&self, _noise: &crate::LaserNoise) -> f64 {
        0.02
    }

    /// How many laser range-noise σ a new map point may lie from the surface through its
    /// nearest held point and still add nothing this matcher can use: the default of
    /// `matcher.relevance.surface_band_sigmas` ([`Merge::surface_band`](crate::Merge)). Default
    /// 1: a matcher that measures against the map's surfaces loses nothing when a wall seen
    /// again is not sampled again within its noise. 0 for a matcher that needs every sample.
    fn surface_band_sigmas(&self) -> f64 {
        1.0
    }

    /// The share of a relevant scan's points that must lie off the map for the scan to enter
    /// it: the default of `matcher.relevance.min_novelty` (keyframe selection by overlap).
    /// Default 0: every relevant scan enters, as the paper's Alg. 1 reads.
    fn min_novelty(&self) -> f64 {
        0.0
    }

    /// The pose of `scan` in the frame of `reference`, starting from `guess`, trusting the
    /// scan alone.
    fn match_scan<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
    ) -> MatchResult {
        self.match_with_prior(reference, scan, guess, None)
    }
}
