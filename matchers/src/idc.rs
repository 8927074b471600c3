//! Iterative Dual Correspondence (Lu & Milios 1997).

use crate::ConfigError;
use crate::icp::{IcpParams, move_points, positive, residual, trim};
use crate::lsq::{NormalEquations, align_points};
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
}

impl Default for IdcParams {
    fn default() -> Self {
        Self {
            window_start_deg: 15.0,
            window_end_deg: 1.0,
        }
    }
}

impl IdcParams {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("matcher.idc.window_start_deg", self.window_start_deg)?;
        positive("matcher.idc.window_end_deg", self.window_end_deg)?;
        if self.window_start_deg > 90.0 || self.window_end_deg > self.window_start_deg {
            return Err(ConfigError::invalid(
                "matcher.idc.window_end_deg",
                "windows must satisfy 0 < window_end_deg ≤ window_start_deg ≤ 90",
            ));
        }
        Ok(())
    }
}

/// The point of the reference surface through point `id` closest to `p`: the sample slid
/// along its tangent, at most one sample spacing either way (a polyline through the samples).
fn surface_foot<I: SpatialIndex>(
    reference: &Reference<I>,
    id: u32,
    p: &Point2<f64>,
) -> Point2<f64> {
    let c = reference.index().points()[id as usize];
    let info = &reference.info()[id as usize];
    let tangent = qicp_core::Vector2::new(-info.normal.y, info.normal.x);
    let slide = (p - c).dot(&tangent).clamp(-info.spacing, info.spacing);
    c + tangent * slide
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

impl<C: CorrespondenceMetric> ScanMatcher for Idc<C> {
    fn name(&self) -> &'static str {
        "idc"
    }

    /// The prior (odometry) is fused with each iteration's estimate through the information
    /// of the closest-point pairs.
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
        let mut pose = guess;
        let mut converged = false;
        let mut iterations = 0;
        let mut schedule = self.icp.schedule();
        for it in 0..self.icp.max_iterations {
            iterations = it + 1;
            let gate = self.icp.gate(schedule.level);
            // Lu & Milios: the window Bw shrinks as the estimate converges.
            // The window narrows geometrically with the gate, reaching its end with it.
            let progress = (schedule.level as f64 / self.icp.last_level().max(1) as f64).min(1.0);
            let window_deg = self.params.window_start_deg
                * (self.params.window_end_deg / self.params.window_start_deg).powf(progress);
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
            // Lu & Milios Sec. 4.2: matching-range rule inside the window ±Bw.
            self.range_rule.window = window_deg.to_radians();
            self.range_rule
                .pair(reference.index(), &query, &mut self.mr);
            trim(
                &mut self.mr,
                self.icp.trim,
                self.icp.max_dist_end,
                &mut self.scratch,
            );
            if self.cp.len() < self.icp.min_correspondences {
                if it == 0 {
                    return MatchResult::fallback(
                        guess,
                        Fallback::TooFewCorrespondences {
                            found: self.cp.len(),
                        },
                    );
                }
                break;
            }
            // Lu & Milios pair with the closest point on the reference *polyline*, not the
            // nearest sample: slide the sample along its surface to the foot of the point.
            let foot = |p: &Pair| {
                (
                    surface_foot(reference, p.reference, &self.moved[p.scan as usize]),
                    local[p.scan as usize],
                )
            };
            let cp_pairs = self.cp.iter().map(foot);
            let Some(by_cp) = align_points(cp_pairs.clone()) else {
                return MatchResult::fallback(guess, Fallback::Degenerate);
            };
            // The rotation of the matching-range rule, when it found enough pairs.
            // Lu & Milios Eq. (11): pairs of equal range differ by a rotation about the sensor.
            // In least squares each bearing difference counts with (dr/dφ)² = (r·tan β)², β the
            // incidence angle: where range barely changes with bearing (a wall seen head-on)
            // equal ranges say little about rotation. The interpolation assumes straight
            // surfaces, so once the window is at its narrowest the closest-point rule on the
            // polyline, unbiased on curved trunks and corners too, refines the rotation.
            let coarse = window_deg > self.params.window_end_deg;
            let theta = if coarse && self.mr.len() >= self.icp.min_correspondences {
                let o = Point2::new(pose.x, pose.y);
                let info = reference.info();
                let (mut sum, mut weight) = (0.0, 0.0);
                for p in &self.mr {
                    let b = self.moved[p.scan as usize] - o;
                    let r = b.norm();
                    let a = same_range_point(reference, p.reference, &o, r) - o;
                    let n = info[p.reference as usize].normal;
                    let cos = (a.dot(&n) / a.norm().max(1e-9))
                        .abs()
                        .max(MIN_INCIDENCE_COS);
                    let w = r * r * (1.0 - cos * cos) / (cos * cos);
                    sum += w * qicp_core::normalize_angle(a.y.atan2(a.x) - b.y.atan2(b.x));
                    weight += w;
                }
                if weight > 0.0 {
                    pose.theta + sum / weight
                } else {
                    by_cp.theta
                }
            } else {
                by_cp.theta
            };
            // Translation of the closest-point rule given that rotation: t = ā − R·b̄.
            let n = self.cp.len() as f64;
            let (mut ca, mut cb) = (Point2::origin().coords, Point2::origin().coords);
            for (a, b) in cp_pairs {
                ca += a.coords;
                cb += b.coords;
            }
            let r = Pose2::new(0.0, 0.0, theta).rotation();
            let t = ca / n - r * (cb / n);
            let mut next = Pose2::new(t.x, t.y, theta);
            if let Some(lambda) = &prior {
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
            let settled = self.icp.small_step(&pose, &next);
            pose = next;
            let final_stage = self.icp.at_last_gate(schedule.level);
            if schedule.advance(&self.icp, settled, final_stage) {
                converged = true;
                break;
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
        let mut h = self.line_information(reference, local, &pose);
        if let Some(lambda) = &prior {
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
