//! Iterative Dual Correspondence (Lu & Milios 1997).
use crate::icp::{IcpParams, Schedule, move_points, residual, trim};
use qicp_core::{
    ClosestPoint, CorrespondenceMetric, Fallback, MatchResult, MatchingRange, Matrix3, Pair,
    Point2, Pose2, PriorSource, Query, Reference, Scan, ScanMatcher, SpatialIndex, dist_sq,
};

mod params;
mod rules;

pub use params::{IdcAlgorithm, IdcParams};

/// IDC: each iteration pairs points by the closest-point rule (which fixes translation well)
/// and by the matching-range rule (which fixes rotation well), then takes the rotation of the
/// second and the translation of the first given that rotation.
///
/// `C` is the closest-point rule's metric: [`ClosestPoint`] for scan-to-scan matching, the
/// paper's [`MutualNearest`](qicp_core::MutualNearest) for matching against a map (Q-IDC).
#[derive(Debug, Clone, Default)]
pub struct Idc<C = ClosestPoint> {
    /// Iteration parameters.
    pub icp: IcpParams,
    /// IDC's parameters.
    pub params: IdcParams,
    closest: C,
    range_rule: MatchingRange,
    moved: Vec<Point2<f64>>,
    cp: Vec<Pair>,
    mr: Vec<Pair>,
    scratch: Vec<f64>,
    samples: Vec<(f64, f64)>,
    feet: Vec<(Point2<f64>, Point2<f64>)>,
}

impl<C: CorrespondenceMetric + Default> Idc<C> {
    /// IDC with the given parameters.
    #[must_use]
    pub fn new(icp: IcpParams, params: IdcParams) -> Self {
        Self {
            icp,
            params,
            ..Self::default()
        }
    }
}

/// Distance to the reference surface up to which the verification counts a point as
/// explained (m); farther points cost as much as this.
const VERIFY_DISTANCE: f64 = 0.05;

impl<C: CorrespondenceMetric> Idc<C> {
    /// Iterates both rules from `start` with the gate schedule at `first_level` until the
    /// estimate settles at the last gate: the estimate, the iterations run and whether it
    /// settled. `Err` when the first iteration finds too few pairs or the system is singular.
    #[allow(clippy::too_many_arguments)]
    fn iterate<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        start: Pose2,
        guess: &Pose2,
        prior: Option<&Matrix3<f64>>,
        (first_window_deg, end_deg): (f64, f64),
        first_level: u32,
    ) -> Result<(Pose2, u32, bool), Fallback> {
        let mut pose = start;
        let mut schedule = Schedule::at(first_level);
        let last_level = self.icp.last_level();
        for it in 0..self.icp.max_iterations {
            let gate = self.icp.gate(schedule.level);
            // Lu & Milios: the window Bw shrinks as the estimate converges.
            // The window narrows geometrically with the gate, from the first stage run to
            // the last gate.
            let progress = if first_level >= last_level {
                1.0
            } else {
                (f64::from(schedule.level - first_level) / f64::from(last_level - first_level))
                    .min(1.0)
            };
            let window_deg = first_window_deg * (end_deg / first_window_deg).powf(progress);
            move_points(&pose, local, &mut self.moved);
            let query = Query {
                local,
                points: &self.moved,
                pose,
                max_dist: gate,
            };
            // Lu & Milios Sec. 4.1: closest-point rule.
            self.closest.pair(reference.index(), &query, &mut self.cp);
            trim(
                &mut self.cp,
                self.icp.trim,
                self.icp.max_dist_end,
                &mut self.scratch,
            );
            if self.cp.len() < self.icp.min_correspondences {
                if it == 0 {
                    return Err(Fallback::TooFewCorrespondences {
                        found: self.cp.len(),
                    });
                }
                return Ok((pose, it, false));
            }
            // Lu & Milios Sec. 4.2: matching-range rule inside the window ±Bw. Its pairs set
            // the rotation while the window is still wider than its end value; then the
            // closest-point rule on the polyline, unbiased on curved trunks and corners too,
            // refines it (the range rule's interpolation assumes straight surfaces).
            let coarse = window_deg > end_deg;
            let mut range_theta = None;
            // The range rule's standard error, against a map only (see `stage_sigmas`).
            let mut range_se = 0.0;
            if coarse {
                self.range_rule.window = window_deg.to_radians();
                self.range_rule
                    .pair(reference.index(), &query, &mut self.mr);
                trim(
                    &mut self.mr,
                    self.icp.trim,
                    self.icp.max_dist_end,
                    &mut self.scratch,
                );
                if self.mr.len() >= self.icp.min_correspondences
                    && let Some((theta, se)) = self.range_rotation(reference, &pose)
                {
                    range_theta = Some(theta);
                    if reference.is_map() {
                        range_se = se;
                    }
                }
            }
            let Some(next) = self.closest_step(reference, local, &pose, range_theta, guess, prior)
            else {
                return Err(Fallback::Degenerate);
            };
            let (moved, turned) = (
                pose.distance(&next),
                qicp_core::normalize_angle(pose.theta - next.theta).abs(),
            );
            let settled = if coarse {
                let f = self.params.stage_tolerance;
                moved < gate * f
                    && (turned < window_deg.to_radians() * f
                        || turned < self.params.stage_sigmas * range_se)
            } else {
                self.icp.small_step(&pose, &next)
                    || (moved < self.params.settle_translation
                        && turned < self.params.settle_rotation_deg.to_radians())
            };
            pose = next;
            let final_stage = self.icp.at_last_gate(schedule.level);
            if schedule.advance(&self.icp, settled, final_stage) {
                return Ok((pose, it + 1, true));
            }
        }
        Ok((pose, self.icp.max_iterations, false))
    }

    /// How badly `pose` explains the scan: Σ min(d², D²) over the scan points, d the distance
    /// from the point to the reference surface through its nearest sample, D
    /// [`VERIFY_DISTANCE`] (also for points with no sample that near). Lower is better.
    fn misfit<I: SpatialIndex>(
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
    ) -> f64 {
        let cap = VERIFY_DISTANCE * VERIFY_DISTANCE;
        local
            .iter()
            .map(|b| {
                let p = pose.transform_point(b);
                reference
                    .surface_distance_sq(&p, 4.0 * cap)
                    .map_or(cap, |d_sq| d_sq.min(cap))
            })
            .sum()
    }
}

impl<C: CorrespondenceMetric> ScanMatcher for Idc<C> {
    fn name(&self) -> &'static str {
        "idc"
    }

    /// 0: the matching-range rule pairs by bearing, and needs the samples of every look at a
    /// wall inside its narrow angular window. With the band on, q-idc's Intel score with
    /// every second beam went from 0.027 to 0.088 m (0.025 to 0.146 m on the first 3,000
    /// scans).
    fn surface_band_sigmas(&self) -> f64 {
        0.0
    }

    /// 0.05: a relevant scan enters the map only where at least 5 % of its points (9 of a
    /// 181-beam scan) lie farther than `novelty_distance` (5 cm) from it. Without the gate,
    /// every pass over ground already mapped thickens the map, and the range rule's radius
    /// searches grow with its density: over 12 passes of the Intel log q-idc's map grew
    /// from 62k to 177k points and its median time per scan from 1.1 to 3.4 ms. With the gate
    /// a revisit that matches the map adds a few scans (see the README's robustness section).
    fn min_novelty(&self) -> f64 {
        0.05
    }

    /// The prior, taken as odometry's ([`PriorSource::Odometry`]), is fused with each
    /// iteration's estimate through the information of the closest-point pairs, and sizes
    /// the range rule's first window.
    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        self.match_with_prior_from(reference, scan, guess, prior, PriorSource::Odometry)
    }

    /// A suspect guess is matched with its prior as well only where the prior is odometry's
    /// ([`IdcParams::suspect_with_prior`]).
    fn match_with_prior_from<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
        source: PriorSource,
    ) -> MatchResult {
        if let Some(why) = self.icp.cannot_match(scan, reference) {
            return MatchResult::fallback(guess, why);
        }
        let local = scan.points();
        self.closest.begin_scan(local);
        self.range_rule.begin_scan(local);
        // A guess that explains the scan this badly may be wrong (odometry slipping in a fast
        // turn, a record out of time order): match without its prior, from a full window.
        let guess_misfit = Self::misfit(reference, local, &guess);
        let suspect = self.params.verify
            && guess_misfit
                > self.params.suspect_guess
                    * local.len() as f64
                    * VERIFY_DISTANCE
                    * VERIFY_DISTANCE;
        let given = prior.as_ref();
        let mut prior = if suspect { None } else { given };
        let end = self
            .params
            .end_window_deg(scan.geometry.angle_increment.to_degrees());
        let mut window = (self.params.first_window_deg(prior, end), end);
        let first_level = self.params.first_level(&self.icp, prior);
        let (mut pose, mut iterations, mut converged) =
            match self.iterate(reference, local, guess, &guess, prior, window, first_level) {
                Ok(found) => found,
                Err(why) => return MatchResult::fallback(guess, why),
            };
        if self.params.verify {
            let mut misfit = Self::misfit(reference, local, &pose);
            // Odometry that explains its scan badly may still be right where the scan fits the
            // map poorly anywhere (clutter, a fast turn): matched with its prior as well
            // (`suspect_with_prior`), the prior's match is kept where it explains the scan
            // better. A prediction without odometry is no measurement to look at again, and
            // scan to scan no map keeps a wrong match.
            if suspect
                && self.params.suspect_with_prior
                && source == PriorSource::Odometry
                && reference.is_map()
                && given.is_some()
            {
                let with = (self.params.first_window_deg(given, end), end);
                let level = self.params.first_level(&self.icp, given);
                if let Ok((again, more, settled)) =
                    self.iterate(reference, local, guess, &guess, given, with, level)
                {
                    iterations += more;
                    let again_misfit = Self::misfit(reference, local, &again);
                    // Two matches that no point of the scan tells apart by the check's
                    // distance are one, and a fit better by less than one point unexplained
                    // (a few trunks' five pairs) is no evidence: the first stands.
                    let apart = local.iter().any(|b| {
                        dist_sq(&pose.transform_point(b), &again.transform_point(b))
                            > VERIFY_DISTANCE * VERIFY_DISTANCE
                    });
                    if apart && again_misfit + VERIFY_DISTANCE * VERIFY_DISTANCE < misfit {
                        (pose, converged, misfit) = (again, settled, again_misfit);
                        (prior, window) = (given, with);
                    }
                }
            }
            // The initial guess explains the scan better than the result: the iteration went
            // astray (a wide window's range pairs, a local minimum). Refine the guess with the
            // closest-point rule alone, at the last gate, and keep whichever fits best.
            if guess_misfit < misfit {
                let last = self.icp.last_level();
                if let Ok((again, more, settled)) =
                    self.iterate(reference, local, guess, &guess, prior, window, last)
                {
                    iterations += more;
                    if Self::misfit(reference, local, &again) < misfit {
                        pose = again;
                        converged = settled;
                    }
                }
            }
        }
        // Covariance of the point-to-line least squares (pairs are polyline feet, so only the
        // normal direction carries information): σ² (JᵀWJ)⁻¹ with σ² from the residuals.
        move_points(&pose, local, &mut self.moved);
        let query = Query {
            local,
            points: &self.moved,
            pose,
            max_dist: self.icp.max_dist_end,
        };
        self.closest.pair(reference.index(), &query, &mut self.cp);
        let n = self.cp.len();
        if n < self.icp.min_correspondences {
            // The estimate lost its support on the way (pairs fell out of the shrinking
            // gate): it and its near-singular covariance would be noise.
            return MatchResult::fallback(guess, Fallback::TooFewCorrespondences { found: n });
        }
        let mut h = self.line_information(reference, local, &pose);
        if let Some(lambda) = prior {
            h += lambda;
        }
        // An information matrix that cannot be inverted leaves a direction open: no match to
        // trust (a placeholder covariance would pass for a real, very uncertain one).
        let Some(covariance) = h.try_inverse().filter(|c| c.iter().all(|v| v.is_finite())) else {
            return MatchResult::fallback(guess, Fallback::Degenerate);
        };
        MatchResult {
            pose,
            covariance,
            iterations,
            correspondences: n,
            residual: residual(reference, local, &self.cp, &pose),
            converged,
            fallback: None,
        }
    }
}
