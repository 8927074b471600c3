//! IDC's parameters ([`IdcParams`], TOML section `[matcher.idc]`) and its registry entry
//! ([`IdcAlgorithm`]).

use super::Idc;
use crate::ConfigError;
use crate::icp::IcpParams;
use crate::params::{Param, Range, check_section};
use crate::registry::{Algorithm, Metric};
use qicp_core::Matrix3;
use serde::{Deserialize, Serialize};

/// IDC's own parameters (TOML section `[matcher.idc]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdcParams {
    /// Half-width of the matching-range rule's angular window in the first iteration (deg).
    /// Default 15.
    pub window_start_deg: f64,
    /// … shrinking with the gate down to this (deg), but never below the laser's bearing
    /// step ([`IdcParams::end_window_deg`]). Default 1.
    pub window_end_deg: f64,
    /// With an odometry prior, the first window is this many of the prior's rotation standard
    /// deviations instead (between the end window, [`IdcParams::end_window_deg`], and
    /// window_start_deg): Lu & Milios size Bw to the
    /// rotation error they expect, and a window far wider than odometry's error only lets
    /// the range rule jump to wrong rotations. 0 always starts at window_start_deg.
    /// Default 2. The range rule runs only in stages whose window is wider than the end
    /// window: where the first window is clamped to it (a prior tighter than half the end
    /// window), or the schedule has one gate (`matcher.icp.max_dist_start` equal to
    /// `max_dist_end`), IDC matches by the closest-point rule alone.
    pub window_sigmas: f64,
    /// With an odometry prior, the first gate is the narrowest of the schedule that still
    /// holds this many of the prior's translation standard deviations (yet at least one
    /// stage with a window wider than window_end_deg runs): the wide gates of the schedule
    /// exist for large initial errors, and odometry says how large they can be. 0 always
    /// starts at matcher.icp.max_dist_start. Default 5.
    pub gate_sigmas: f64,
    /// A stage whose window is still wider than window_end_deg ends once a step moves less
    /// than this fraction of the gate and turns less than this fraction of the window: the
    /// two rules never agree to 0.1 mm, and refining a wide stage is wasted work.
    /// Default 0.02. Wider stages cost more than they save: at 0.1 q-idc's sweeps of Intel,
    /// mirrored and played backwards stayed as they are (0, 0 and 1 of 68 variants over the
    /// bound), at 0.12 its three default runs took 26.3 s against 36.5 s, but idc scan to scan
    /// scored 0.684 m on Intel against 0.174 m (its coarse stages set the heading the last
    /// one keeps), and with 0.1 against a map only, q-idc's sweep of the Freiburg clinic had
    /// 41 of 68 variants over the bound against 4 (median 0.062 against 0.039 m).
    pub stage_tolerance: f64,
    /// Against a map, a wide stage also settles when its step moves less than
    /// `stage_tolerance` of the gate and turns less than this many standard errors of the
    /// range rule's rotation (the robust spread of its pairs' bearing differences over √n):
    /// a turn within the estimate's own noise is the jitter of pairs switching between the
    /// map's overlapping samples, not progress. Default 0 (off). At 2, q-idc runs 0.82 of the
    /// iterations on Intel's first 3,000 records, and its sweeps of Intel, mirrored, played
    /// backwards, MIT CSAIL and the Freiburg clinic keep the variants over the bound they
    /// had; but Intel's default run scores 0.0190 m against 0.0169 m, and without odometry
    /// 0.309 m against 0.025 m, where the run without the rule loses its way at the same
    /// records under a 2 % change of `settle_rotation_deg` (docs/robustness.md, "IDC's wide
    /// stages ending within the range rule's noise"). Scan to scan it never acts: there the
    /// wide stages set the heading the last one keeps (idc scored 0.437 m on Intel with it,
    /// against 0.174 m).
    pub stage_sigmas: f64,
    /// The last stage also settles when a step moves less than this (m)… Below it the steps
    /// are the jitter of pairs switching between the overlapping samples of a map.
    /// Default 0.001.
    pub settle_translation: f64,
    /// … and turns less than this (deg). Default 0.06.
    pub settle_rotation_deg: f64,
    /// Check the initial guess against the scan (squared distances of the points to the
    /// reference surface, truncated at 5 cm): one that explains it very badly is not used as a
    /// prior (`suspect_guess`); after the iteration, when the guess explains the scan better
    /// than the result, it is refined with the closest-point rule alone and whichever explains
    /// the scan best is kept. One wrong match must not enter a map that is never forgotten.
    /// Default true.
    pub verify: bool,
    /// With `verify`, an initial guess whose misfit (as `verify` measures it) exceeds this
    /// share of the largest, every point unexplained, is no prior: the match runs as if none
    /// had been given, from the widest window and gate. 1 or more never drops it. Default
    /// 0.4: on Intel the results' misfits have median 0.06 and 99th percentile 0.2, and 2.4 %
    /// of the guesses lie above 0.4; on MIT CSAIL the results' median is 0.09, the guesses'
    /// 0.23, and 28 % lie above. Never dropping the prior keeps q-idc on MIT CSAIL played
    /// backwards and gains in the park, but costs Intel 2.4 mm, and Intel without odometry 5
    /// sweep variants above 0.05 m (docs/limits.md, "IDC drops odometry's prior").
    pub suspect_guess: f64,
    /// With `verify`, against a map and under odometry's prior, a guess found suspect
    /// (`suspect_guess`) is matched twice, without its prior and with it. The prior's match
    /// replaces the first only where the two lie apart (some scan point farther from itself
    /// than the check's 5 cm) and it leaves less misfit by more than one point unexplained
    /// (5 cm squared): a guess that misfits because it is wrong loses to the search from the
    /// widest window, one that misfits because the scan fits the map poorly (clutter, a fast
    /// turn) keeps its prior. Two matches closer than that are one, and a fit better by less
    /// than one point is no evidence (a park scan's five pairs): the first stands. A motion
    /// model's prediction in a log without odometry is no measurement and is not matched
    /// again, nor is a scan matched to one scan, where no map keeps a wrong match.
    /// Costs one more match per suspect guess. Default true: MIT CSAIL played backwards has 3
    /// of 68 sweep variants above 0.05 m against 28 without it, Intel played backwards none
    /// over the sweep's bound against 1, and the park's ten worlds no world missing the ATE
    /// target for q-idc (docs/robustness.md, "A suspect odometry guess matched both ways").
    /// False matches a suspect guess without its prior alone.
    pub suspect_with_prior: bool,
}

impl Default for IdcParams {
    fn default() -> Self {
        Self {
            window_start_deg: 15.0,
            window_end_deg: 1.0,
            window_sigmas: 2.0,
            gate_sigmas: 5.0,
            stage_tolerance: 0.02,
            stage_sigmas: 0.0,
            settle_translation: 0.001,
            settle_rotation_deg: 0.06,
            verify: true,
            suspect_guess: 0.4,
            suspect_with_prior: true,
        }
    }
}

/// IDC in the registry (`algorithm = "idc"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct IdcAlgorithm;

impl Algorithm for IdcAlgorithm {
    const NAME: &'static str = "idc";
    const SUMMARY: &'static str = "Iterative Dual Correspondence (Lu & Milios 1997)";
    const PARAMETERS: &'static [Param] = &[
        Param::steering(
            "window_start_deg",
            Range::Positive,
            "half-width of the matching-range window in the first iteration (deg)",
        ),
        Param::new(
            "window_end_deg",
            Range::Positive,
            "… shrinking down to this (deg)",
        ),
        Param::steering(
            "window_sigmas",
            Range::NonNegative,
            "with a prior, the first window in its rotation σ (0: window_start_deg)",
        ),
        Param::steering(
            "gate_sigmas",
            Range::NonNegative,
            "with a prior, the first gate holds this many translation σ (0: max_dist_start)",
        ),
        Param::new(
            "stage_tolerance",
            Range::Open(0.0, 1.0),
            "a wide stage ends when a step is below this fraction of gate and window",
        ),
        Param::new(
            "stage_sigmas",
            Range::NonNegative,
            "against a map, … or turns less than this many standard errors of the range rule's rotation (0: off)",
        ),
        Param::new(
            "settle_translation",
            Range::NonNegative,
            "the last stage settles below this step (m)",
        ),
        Param::new(
            "settle_rotation_deg",
            Range::NonNegative,
            "… and below this turn (deg)",
        ),
        Param::new(
            "verify",
            Range::Flag,
            "check the guess against the scan and keep whichever explains it best",
        ),
        Param::new(
            "suspect_guess",
            Range::Positive,
            "with verify, a guess whose misfit exceeds this share of the largest is no prior (1: never)",
        ),
        Param::new(
            "suspect_with_prior",
            Range::Flag,
            "with verify, against a map, a suspect odometry guess is also matched with its prior, kept where apart and better by one point",
        ),
    ];
    type Params = IdcParams;
    type Matcher<C: Metric> = Idc<C>;

    fn matcher<C: Metric>(icp: IcpParams, params: &IdcParams) -> Idc<C> {
        Idc::new(icp, *params)
    }

    fn check(params: &IdcParams) -> Result<(), ConfigError> {
        if params.window_start_deg > 90.0 || params.window_end_deg > params.window_start_deg {
            return Err(ConfigError::invalid(
                "matcher.idc.window_end_deg",
                "windows must satisfy 0 < window_end_deg ≤ window_start_deg ≤ 90",
            ));
        }
        Ok(())
    }
}

impl IdcParams {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_section("matcher.idc", self, IdcAlgorithm::PARAMETERS)?;
        IdcAlgorithm::check(self)
    }

    /// The last window (deg) for a scan whose beams are `bearing_step_deg` apart:
    /// `window_end_deg`, widened to one bearing step where the laser is coarser (at most
    /// `window_start_deg`). A window narrower than the step between the laser's beams holds
    /// reference points of one bearing only, and the range rule then pairs by chance: on the
    /// Intel log with every second beam (2° apart), q-idc's relation error was 0.147 m at a
    /// 1° end window and is 0.027 m at 2°. Lasers at 1° or finer keep `window_end_deg`. A
    /// laser whose beams lie `window_start_deg` or more apart gets no narrowing window, so
    /// the closest-point rule alone matches it.
    #[must_use]
    pub fn end_window_deg(&self, bearing_step_deg: f64) -> f64 {
        let step = bearing_step_deg.abs();
        // A step equal to the end window up to rounding keeps it (π/180 rad is not 1° exactly).
        if step.is_finite() && step > self.window_end_deg + 1e-9 {
            step.min(self.window_start_deg)
        } else {
            self.window_end_deg
        }
    }

    /// The first window (deg): `window_sigmas` standard deviations of the prior's rotation
    /// when there is a prior, clamped between `end_deg` (from [`IdcParams::end_window_deg`])
    /// and `window_start_deg`.
    #[must_use]
    pub fn first_window_deg(&self, prior: Option<&Matrix3<f64>>, end_deg: f64) -> f64 {
        match prior {
            Some(lambda) if self.window_sigmas > 0.0 && lambda[(2, 2)] > 0.0 => {
                (self.window_sigmas / lambda[(2, 2)].sqrt())
                    .to_degrees()
                    .clamp(end_deg.min(self.window_start_deg), self.window_start_deg)
            }
            _ => self.window_start_deg,
        }
    }

    /// The level of the gate schedule to start at: with a prior, the last one whose gate
    /// still holds `gate_sigmas` of its translation standard deviations, at most one before
    /// the last level; 0 otherwise.
    #[must_use]
    pub fn first_level(&self, icp: &IcpParams, prior: Option<&Matrix3<f64>>) -> u32 {
        icp.first_level(prior, self.gate_sigmas)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_end_window_is_never_narrower_than_the_lasers_bearing_step() {
        let p = IdcParams::default();
        // A 1° laser (π/180 rad, rounded) keeps the configured end window exactly.
        assert_eq!(
            p.end_window_deg((std::f64::consts::PI / 180.0).to_degrees()),
            1.0
        );
        assert_eq!(p.end_window_deg(0.5), 1.0);
        // Every second beam of it: the window widens to the 2° step.
        assert_eq!(p.end_window_deg(2.0), 2.0);
        assert_eq!(p.end_window_deg(-2.0), 2.0);
        // Never wider than the first window, nor fooled by a broken geometry.
        assert_eq!(p.end_window_deg(40.0), p.window_start_deg);
        assert_eq!(p.end_window_deg(f64::NAN), 1.0);
        assert_eq!(p.end_window_deg(f64::INFINITY), 1.0);
        // The first window with a prior is clamped to the widened end.
        let tight = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 1e12));
        assert_eq!(p.first_window_deg(Some(&tight), 2.0), 2.0);
        assert_eq!(p.first_window_deg(None, 2.0), p.window_start_deg);
    }
}
