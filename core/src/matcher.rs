//! The scan-matcher plug-in point.

use crate::index::SpatialIndex;
use crate::reference::Reference;
use crate::{MatchResult, Pose2, Scan};

/// Estimates where a scan was taken, relative to a reference.
///
/// Generic over the reference's index so that the correspondence search, the hot loop, is
/// monomorphic. Failing to match is not an error: the result says so (`fallback`, `converged`).
pub trait ScanMatcher {
    /// Short name, e.g. `"wsm"`.
    fn name(&self) -> &'static str;

    /// The pose of `scan` in the frame of `reference`, starting from `guess`.
    fn match_scan<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
    ) -> MatchResult;
}
