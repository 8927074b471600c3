//! Least-squares pose solvers shared by the matchers.

use nalgebra::{Matrix2, Matrix3, Point2, Vector2, Vector3};
use qicp_core::Pose2;

/// Closed-form rigid alignment (2D Horn / Umeyama without scale): the pose `T` minimising
/// Σ |aᵢ − T·bᵢ|², where `a` are reference points and `b` scan points in the scan frame.
/// `None` with fewer than two pairs or coincident points.
#[must_use]
pub fn align_points(
    pairs: impl Iterator<Item = (Point2<f64>, Point2<f64>)> + Clone,
) -> Option<Pose2> {
    let mut n = 0.0;
    let (mut ca, mut cb) = (Vector2::zeros(), Vector2::zeros());
    for (a, b) in pairs.clone() {
        ca += a.coords;
        cb += b.coords;
        n += 1.0;
    }
    if n < 2.0 {
        return None;
    }
    ca /= n;
    cb /= n;
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for (a, b) in pairs {
        let (a, b) = (a.coords - ca, b.coords - cb);
        sxx += b.x * a.x + b.y * a.y;
        sxy += b.x * a.y - b.y * a.x;
    }
    if sxx == 0.0 && sxy == 0.0 {
        return None;
    }
    let theta = sxy.atan2(sxx);
    let (s, c) = theta.sin_cos();
    let t = ca - Matrix2::new(c, -s, s, c) * cb;
    Some(Pose2::new(t.x, t.y, theta))
}

/// Accumulates the normal equations of a weighted Gauss–Newton step on SE(2).
///
/// Residual of a pair: ξ = a − (R·b + t) with weight W (a 2×2 information matrix). The step
/// δ = (δx, δy, δθ) solves (Σ Jᵀ W J) δ = Σ Jᵀ W ξ with J = ∂(R·b + t)/∂(x, y, θ)
/// (Pfister et al. 2002, Eq. 13–15 in this parametrisation).
#[derive(Debug, Clone, Copy, Default)]
pub struct NormalEquations {
    /// Σ Jᵀ W J: the information matrix of the estimate.
    pub h: Matrix3<f64>,
    /// Σ Jᵀ W ξ.
    pub g: Vector3<f64>,
    /// Number of pairs added.
    pub n: usize,
    /// Σ ξᵀ W ξ: the weighted squared residual (χ²) at the linearisation point.
    pub chi2: f64,
    /// Residual components behind `chi2` (2 per pair, plus any prior's).
    pub dof: usize,
}

impl NormalEquations {
    /// Adds one pair: `a` reference point, `rb` the scan point already rotated by R (but not
    /// translated), `t` the current translation, `w` the pair's information matrix.
    #[inline]
    pub fn add(&mut self, a: &Point2<f64>, rb: &Vector2<f64>, t: &Vector2<f64>, w: &Matrix2<f64>) {
        let xi = a.coords - rb - t;
        // Columns of J: ∂/∂x = (1, 0), ∂/∂y = (0, 1), ∂/∂θ = (−(Rb)y, (Rb)x).
        let jt = Vector2::new(-rb.y, rb.x);
        let wj_t = w * jt;
        let wxi = w * xi;
        self.h[(0, 0)] += w[(0, 0)];
        self.h[(0, 1)] += w[(0, 1)];
        self.h[(1, 1)] += w[(1, 1)];
        self.h[(0, 2)] += wj_t.x;
        self.h[(1, 2)] += wj_t.y;
        self.h[(2, 2)] += jt.dot(&wj_t);
        self.g.x += wxi.x;
        self.g.y += wxi.y;
        self.g.z += jt.dot(&wxi);
        self.chi2 += xi.dot(&wxi);
        self.n += 1;
        self.dof += 2;
    }

    /// The a-posteriori variance factor χ² / (m − 3) of a fit with m residual components:
    /// 1 when the noise model is right, below 1 when the fit is tighter than modelled.
    #[must_use]
    pub fn variance_factor(&self) -> f64 {
        if self.dof > 3 {
            self.chi2 / (self.dof - 3) as f64
        } else {
            1.0
        }
    }

    /// The full symmetric information matrix.
    #[must_use]
    pub fn information(&self) -> Matrix3<f64> {
        let mut h = self.h;
        h[(1, 0)] = h[(0, 1)];
        h[(2, 0)] = h[(0, 2)];
        h[(2, 1)] = h[(1, 2)];
        h
    }

    /// The covariance of the estimate: H⁻¹ (Pfister et al.), scaled up by the a-posteriori
    /// variance factor where the pairs fit worse than their noise model says, never down: a
    /// factor below 1 is no evidence of a better fit. WSM's along-surface slide is in its
    /// model but not in its residuals (nearest samples lie within half a spacing), so its
    /// factor sits near 0.35 on a good match, and scaling by it made the covariance two to
    /// three times too small (NEES 5-33 against 3 on seeded rooms, corridors and posts).
    /// `None` when H cannot be inverted (or its inverse is not finite): the pairs leave a
    /// direction of the pose open, and the match is degenerate.
    #[must_use]
    pub fn covariance(&self) -> Option<Matrix3<f64>> {
        self.information()
            .try_inverse()
            .map(|c| c * self.variance_factor().max(1.0))
            .filter(|c| c.iter().all(|v| v.is_finite()))
    }

    /// Solves for the step; `None` if the system is singular or the step not finite.
    #[must_use]
    pub fn solve(&self) -> Option<Vector3<f64>> {
        let h = self.information();
        let step = h.cholesky()?.solve(&self.g);
        step.iter().all(|v| v.is_finite()).then_some(step)
    }
}

/// Applies a Gauss–Newton step (global parametrisation: t += δt, θ += δθ).
#[must_use]
pub fn apply_step(pose: &Pose2, step: &Vector3<f64>) -> Pose2 {
    Pose2::new(pose.x + step.x, pose.y + step.y, pose.theta + step.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_information_matrix_that_cannot_be_inverted_gives_no_covariance() {
        // Pairs all on one point pin the translation but leave the rotation about it open:
        // no covariance (the identity that stood in for one passed for a real match's).
        let mut ne = NormalEquations::default();
        for _ in 0..5 {
            ne.add(
                &Point2::new(0.0, 0.0),
                &Vector2::new(0.0, 0.0),
                &Vector2::new(0.0, 0.0),
                &Matrix2::identity(),
            );
        }
        assert_eq!(ne.covariance(), None);
        // With a second point the pose is fixed, and the covariance is H⁻¹ (the fit is exact,
        // so the variance factor does not scale it down).
        ne.add(
            &Point2::new(1.0, 0.0),
            &Vector2::new(1.0, 0.0),
            &Vector2::new(0.0, 0.0),
            &Matrix2::identity(),
        );
        let c = ne.covariance().expect("a covariance");
        let h_inv = ne.information().try_inverse().expect("invertible");
        assert!((c - h_inv).norm() < 1e-12, "{c} against {h_inv}");
    }

    #[test]
    fn align_recovers_a_known_motion() {
        let truth = Pose2::new(0.4, -0.2, 0.3);
        let b: Vec<Point2<f64>> = (0..20)
            .map(|k| Point2::new(k as f64 * 0.3, (k * k) as f64 * 0.05))
            .collect();
        let pairs: Vec<_> = b.iter().map(|p| (truth * *p, *p)).collect();
        let est = align_points(pairs.iter().copied()).unwrap();
        assert!((est.x - truth.x).abs() < 1e-12 && (est.theta - truth.theta).abs() < 1e-12);
    }

    #[test]
    fn gauss_newton_converges_to_the_same_motion() {
        let truth = Pose2::new(0.4, -0.2, 0.3);
        let b: Vec<Point2<f64>> = (0..20)
            .map(|k| Point2::new(k as f64 * 0.3, (k * k) as f64 * 0.05))
            .collect();
        let mut pose = Pose2::IDENTITY;
        for _ in 0..10 {
            let mut ne = NormalEquations::default();
            let r = pose.rotation();
            for p in &b {
                ne.add(
                    &(truth * *p),
                    &(r * p.coords),
                    &pose.translation(),
                    &Matrix2::identity(),
                );
            }
            pose = apply_step(&pose, &ne.solve().unwrap());
        }
        assert!(pose.distance(&truth) < 1e-10 && (pose.theta - truth.theta).abs() < 1e-10);
    }
}
