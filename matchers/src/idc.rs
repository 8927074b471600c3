//! Iterative Dual Correspondence (Lu & Milios 1997).

use crate::ConfigError;
use crate::icp::{IcpParams, Schedule, move_points, residual, trim};
use crate::lsq::{NormalEquations, align_points};
use crate::params::{Param, Range, check_section};
use crate::registry::{Algorithm, Metric};
use qicp_core::{
    ClosestPoint, CorrespondenceMetric, Fallback, MatchResult, MatchingRange, Matrix2, Matrix3,
    Pair, Point2, Pose2, Query, Reference, Scan, ScanMatcher, SpatialIndex,
};
use serde::{Deserialize, Serialize};

/// IDC's own parameters (TOML section `[matcher.idc]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdcParams {
    /// Half-width of the matching-range rule's angular window in the first iteration (deg).
    /// Default 15.
    pub window_start_deg: f64,
    /// … shrinking with the gate down to this (deg). Default 1.
    pub window_end_deg: f64,
    /// With an odometry prior, the first window is this many of the prior's rotation standard
    /// deviations instead (within window_end_deg…window_start_deg): Lu & Milios size Bw to the
    /// rotation error they expect, and a window far wider than odometry's error only lets
    /// the range rule jump to wrong rotations. 0 always starts at window_start_deg.
    /// Default 2.
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
    /// Default 0.02.
    pub stage_tolerance: f64,
    /// The last stage also settles when a step moves less than this (m)… Below it the steps
    /// are the jitter of pairs switching between the overlapping samples of a map.
    /// Default 0.001.
    pub settle_translation: f64,
    /// … and turns less than this (deg). Default 0.06.
    pub settle_rotation_deg: f64,
    /// Check the initial guess against the scan (squared distances of the points to the
    /// reference surface, truncated at 5 cm): one that explains it very badly is not used as a
    /// prior; after the iteration, when the guess explains the scan better than the result,
    /// it is refined with the closest-point rule alone and whichever explains the scan best
    /// is kept. One wrong match must not enter a map that is never forgotten. Default true.
    pub verify: bool,
}

impl Default for IdcParams {
    fn default() -> Self {
        Self {
            window_start_deg: 15.0,
            window_end_deg: 1.0,
            window_sigmas: 2.0,
            gate_sigmas: 5.0,
            stage_tolerance: 0.02,
            settle_translation: 0.001,
            settle_rotation_deg: 0.06,
            verify: true,
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

    /// The first window (deg): `window_sigmas` standard deviations of the prior's rotation
    /// when there is a prior, clamped to the configured windows.
    #[must_use]
    pub fn first_window_deg(&self, prior: Option<&Matrix3<f64>>) -> f64 {
        match prior {
            Some(lambda) if self.window_sigmas > 0.0 && lambda[(2, 2)] > 0.0 => {
                (self.window_sigmas / lambda[(2, 2)].sqrt())
                    .to_degrees()
                    .clamp(self.window_end_deg, self.window_start_deg)
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

/// Incidence angles beyond acos of this (about 75°) count as 75° in the range rule's weights.
const MIN_INCIDENCE_COS: f64 = 0.26;

/// The point of the reference surface through point `id` at range `r` from the sensor `o`
/// (Lu & Milios interpolate the reference polyline the same way): the intersection of the
/// circle of radius `r` with the sample's tangent, within one spacing; the sample itself when
/// there is none.
fn same_range_point<I: SpatialIndex>(
    reference: &Reference<I>,
    id: u32,
    o: &Point2<f64>,
    r: f64,
) -> Point2<f64> {
    let c = reference.index().points()[id as usize];
    let info = &reference.info()[id as usize];
    let t = qicp_core::Vector2::new(-info.normal.y, info.normal.x);
    let d = c - o;
    let b = d.dot(&t);
    let disc = b * b - (d.norm_squared() - r * r);
    if info.normal == qicp_core::Vector2::zeros() || disc < 0.0 {
        return c;
    }
    let root = disc.sqrt();
    let s = if (-b + root).abs() < (-b - root).abs() {
        -b + root
    } else {
        -b - root
    };
    if s.abs() > info.spacing { c } else { c + t * s }
}

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

impl<C: CorrespondenceMetric> Idc<C> {
    /// Information of the current closest-point pairs at `pose`: each pair constrains the
    /// pose along its surface normal (all directions where the normal is unknown), with the
    /// variance σ² of the pair distances.
    fn line_information<I: SpatialIndex>(
        &self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
    ) -> Matrix3<f64> {
        let refs = reference.index().points();
        let info = reference.info();
        let n = self.cp.len();
        let sum_sq: f64 = self.cp.iter().map(|p| p.dist_sq).sum();
        let sigma2 = (sum_sq / (2.0 * n as f64 - 3.0).max(1.0)).max(1e-8);
        let rot = pose.rotation();
        let t = pose.translation();
        let mut ne = NormalEquations::default();
        for p in &self.cp {
            let normal = info[p.reference as usize].normal;
            let w = if normal == qicp_core::Vector2::zeros() {
                Matrix2::identity() / sigma2
            } else {
                normal * normal.transpose() / sigma2
            };
            ne.add(
                &refs[p.reference as usize],
                &(rot * local[p.scan as usize].coords),
                &t,
                &w,
            );
        }
        ne.information()
    }
}

/// Distance to the reference surface up to which the verification counts a point as
/// explained (m); farther points cost as much as this.
const VERIFY_DISTANCE: f64 = 0.05;
/// An initial guess whose misfit exceeds this fraction of the largest possible (every point
/// unexplained) is not trusted as a prior. On the Intel log the results' misfits have median
/// 0.07 and 99th percentile 0.27 of it.
const SUSPECT_GUESS: f64 = 0.4;

/// Cauchy's tuning constant (95 % efficiency on Gaussian residuals).
const CAUCHY: f64 = 2.385;

/// A robust weighted mean of `(value, weight)` samples: starts from the weighted median and
/// reweights by Cauchy's function of the residual, scaled by the median absolute deviation
/// (at least `floor`), so a few wrong pairs cannot pull it far.
fn robust_mean(samples: &mut [(f64, f64)], scratch: &mut Vec<f64>, floor: f64) -> Option<f64> {
    let total: f64 = samples.iter().map(|s| s.1).sum();
    if samples.is_empty() || total.is_nan() || total <= 0.0 {
        return None;
    }
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0;
    let mut m = samples[samples.len() - 1].0;
    for (v, w) in samples.iter() {
        acc += w;
        if acc >= 0.5 * total {
            m = *v;
            break;
        }
    }
    scratch.clear();
    scratch.extend(samples.iter().map(|s| (s.0 - m).abs()));
    let mid = scratch.len() / 2;
    let mad = *scratch.select_nth_unstable_by(mid, f64::total_cmp).1;
    let c = CAUCHY * (1.4826 * mad).max(floor);
    for _ in 0..ROBUST_ITERATIONS {
        let (mut sum, mut weight) = (0.0, 0.0);
        for (v, w) in samples.iter() {
            let e = (v - m) / c;
            let w = w / (1.0 + e * e);
            sum += w * v;
            weight += w;
        }
        m = sum / weight;
    }
    Some(m)
}

/// Reweighting rounds of the robust estimates.
const ROBUST_ITERATIONS: usize = 4;
/// The robust scale of the range rule's bearing differences never falls below this (rad).
const ROBUST_ANGLE_FLOOR: f64 = 0.1 * std::f64::consts::PI / 180.0;

impl<C: CorrespondenceMetric> Idc<C> {
    /// The rotation the matching-range pairs give at `pose` (Lu & Milios Eq. 11): the mean
    /// bearing difference, weighted by (r·tan β)² and made robust (Cauchy, see
    /// [`robust_mean`]): in clutter a few grazing-incidence pairs with huge weights used to
    /// swing it by degrees from one iteration to the next.
    fn range_rotation<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        pose: &Pose2,
    ) -> Option<f64> {
        let o = Point2::new(pose.x, pose.y);
        let info = reference.info();
        self.samples.clear();
        for p in &self.mr {
            let b = self.moved[p.scan as usize] - o;
            let r = b.norm();
            let a = same_range_point(reference, p.reference, &o, r) - o;
            let n = info[p.reference as usize].normal;
            let cos = (a.dot(&n) / a.norm().max(1e-9))
                .abs()
                .max(MIN_INCIDENCE_COS);
            let w = r * r * (1.0 - cos * cos) / (cos * cos);
            if w > 0.0 {
                self.samples.push((
                    qicp_core::normalize_angle(a.y.atan2(a.x) - b.y.atan2(b.x)),
                    w,
                ));
            }
        }
        robust_mean(&mut self.samples, &mut self.scratch, ROBUST_ANGLE_FLOOR)
            .map(|d| pose.theta + d)
    }

    /// One closest-point step from `pose` with the current pairs: each scan point pairs with
    /// the foot of its perpendicular on the reference polyline (Lu & Milios pair with the
    /// closest point on the polyline, not the nearest sample); the rotation is `theta` when
    /// given (the range rule's), the pairs' own otherwise; the translation is the pairs'
    /// given that rotation; the result is fused with the odometry prior.
    fn closest_step<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
        theta: Option<f64>,
        guess: &Pose2,
        prior: Option<&Matrix3<f64>>,
    ) -> Option<Pose2> {
        self.feet.clear();
        for p in &self.cp {
            let b = local[p.scan as usize];
            let a = reference.surface_foot(p.reference, &pose.transform_point(&b));
            self.feet.push((a, b));
        }
        let by_cp = align_points(self.feet.iter().copied())?;
        let theta = theta.unwrap_or(by_cp.theta);
        // Translation of the closest-point rule given that rotation: t = ā − R·b̄.
        let n = self.feet.len() as f64;
        let (mut ca, mut cb) = (Point2::origin().coords, Point2::origin().coords);
        for (a, b) in &self.feet {
            ca += a.coords;
            cb += b.coords;
        }
        let r = Pose2::new(0.0, 0.0, theta).rotation();
        let t = ca / n - r * (cb / n);
        let mut next = Pose2::new(t.x, t.y, theta);
        if let Some(lambda) = prior {
            // Fuse with the odometry prior through the information of the pairs: the
            // directions the scan leaves open (one trunk in view) keep odometry's estimate.
            let h = self.line_information(reference, local, &next);
            let d = qicp_core::Vector3::new(
                guess.x - next.x,
                guess.y - next.y,
                qicp_core::normalize_angle(guess.theta - next.theta),
            );
            if let Some(step) = (h + lambda).cholesky().map(|c| c.solve(&(lambda * d))) {
                next = crate::lsq::apply_step(&next, &step);
            }
        }
        Some(next)
    }
}

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
        first_window_deg: f64,
        first_level: u32,
    ) -> Result<(Pose2, u32, bool), Fallback> {
        let mut pose = start;
        let mut schedule = Schedule::at(first_level);
        let last_level = self.icp.last_level();
        let end_deg = self.params.window_end_deg;
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
                if self.mr.len() >= self.icp.min_correspondences {
                    range_theta = self.range_rotation(reference, &pose);
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
                moved < gate * f && turned < window_deg.to_radians() * f
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

    /// The prior (odometry) is fused with each iteration's estimate through the information
    /// of the closest-point pairs, and sizes the range rule's first window.
    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        if let Some(why) = self.icp.cannot_match(scan, reference) {
            return MatchResult::fallback(guess, why);
        }
        let local = scan.points();
        self.closest.begin_scan(local);
        self.range_rule.begin_scan(local);
        // Odometry that explains the scan this badly is wrong (the Intel log has records whose
        // timestamps put them out of order): match without its prior, from a full window.
        let guess_misfit = Self::misfit(reference, local, &guess);
        let suspect = self.params.verify
            && guess_misfit
                > SUSPECT_GUESS * local.len() as f64 * VERIFY_DISTANCE * VERIFY_DISTANCE;
        let prior = if suspect { None } else { prior.as_ref() };
        let window = self.params.first_window_deg(prior);
        let first_level = self.params.first_level(&self.icp, prior);
        let (mut pose, mut iterations, mut converged) =
            match self.iterate(reference, local, guess, &guess, prior, window, first_level) {
                Ok(found) => found,
                Err(why) => return MatchResult::fallback(guess, why),
            };
        if self.params.verify {
            // The initial guess explains the scan better than the result: the iteration went
            // astray (a wide window's range pairs, a local minimum). Refine the guess with the
            // closest-point rule alone, at the last gate, and keep whichever fits best.
            let misfit = Self::misfit(reference, local, &pose);
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
        let covariance = h
            .try_inverse()
            .filter(|c| c.iter().all(|v| v.is_finite()))
            .unwrap_or_else(|| Matrix3::from_diagonal_element(1.0));
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
