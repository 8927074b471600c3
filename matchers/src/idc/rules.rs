//! The two rules' estimates: the rotation of the matching-range pairs (robust), the
//! closest-point step given a rotation, and the information of the closest-point pairs that
//! fuses it with the odometry prior.

use super::Idc;
use crate::lsq::{NormalEquations, align_points};
use qicp_core::{CorrespondenceMetric, Matrix2, Matrix3, Point2, Pose2, Reference, SpatialIndex};

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

impl<C: CorrespondenceMetric> Idc<C> {
    /// Information of the current closest-point pairs at `pose`: each pair constrains the
    /// pose along its surface normal (all directions where the normal is unknown), with the
    /// variance σ² of the pair distances.
    pub(super) fn line_information<I: SpatialIndex>(
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

/// Cauchy's tuning constant (95 % efficiency on Gaussian residuals).
const CAUCHY: f64 = 2.385;

/// A robust weighted mean of `(value, weight)` samples: starts from the weighted median and
/// reweights by Cauchy's function of the residual, scaled by the median absolute deviation
/// (at least `floor`), so a few wrong pairs cannot pull it far. Also its standard error: that
/// scale (σ, 1.4826 × the deviation, at least `floor`) over √n.
fn robust_mean(
    samples: &mut [(f64, f64)],
    scratch: &mut Vec<f64>,
    floor: f64,
) -> Option<(f64, f64)> {
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
    let sigma = (1.4826 * mad).max(floor);
    let c = CAUCHY * sigma;
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
    Some((m, sigma / (samples.len() as f64).sqrt()))
}

/// Reweighting rounds of the robust estimates.
const ROBUST_ITERATIONS: usize = 4;
/// The robust scale of the range rule's bearing differences never falls below this (rad).
const ROBUST_ANGLE_FLOOR: f64 = 0.1 * std::f64::consts::PI / 180.0;

impl<C: CorrespondenceMetric> Idc<C> {
    /// The rotation the matching-range pairs give at `pose` (Lu & Milios Eq. 11): the mean
    /// bearing difference, weighted by (r·tan β)² and made robust (Cauchy, see
    /// [`robust_mean`]): in clutter a few grazing-incidence pairs with huge weights used to
    /// swing it by degrees from one iteration to the next. Also the rotation's standard error
    /// (rad; see [`robust_mean`]).
    pub(super) fn range_rotation<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        pose: &Pose2,
    ) -> Option<(f64, f64)> {
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
            .map(|(d, se)| (pose.theta + d, se))
    }

    /// One closest-point step from `pose` with the current pairs: each scan point pairs with
    /// the foot of its perpendicular on the reference polyline (Lu & Milios pair with the
    /// closest point on the polyline, not the nearest sample); the rotation is `theta` when
    /// given (the range rule's), the pairs' own otherwise; the translation is the pairs'
    /// given that rotation; the result is fused with the odometry prior.
    pub(super) fn closest_step<I: SpatialIndex>(
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
