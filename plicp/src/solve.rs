//! The exact minimiser of a point-to-line cost (Censi 2008, appendix).
//!
//! With `x = (tx, ty, cos θ, sin θ)`, a scan point `p` moved by the pose is `Mᵢ x` with
//! `Mᵢ = [[1, 0, px, −py], [0, 1, py, px]]`, and the cost of pairs `(pᵢ, qᵢ)` with weights
//! `Wᵢ` (2×2) is `Σ (Mᵢx − qᵢ)ᵀ Wᵢ (Mᵢx − qᵢ) = xᵀMx + gᵀx + const`. Minimising it subject to
//! `cos²θ + sin²θ = 1` by a Lagrange multiplier λ: the translation is eliminated
//! (`t = −A⁻¹(Bc + g₁/2)` with `M = [[A, B], [Bᵀ, D]]`), leaving
//! `(S + λI) c = h` with `S = D − BᵀA⁻¹B` and `h = (BᵀA⁻¹g₁ − g₂)/2`, and `|c| = 1`.
//! In the eigenbasis of `S` (eigenvalues s₁ ≤ s₂) the constraint is the secular equation
//! `Σ h'ₖ² / (sₖ + λ)² = 1`; the minimum is its one root above −s₁ (where `S + λI` is
//! positive semidefinite). Censi finds it among the roots of the equivalent quartic; here it
//! is bracketed in `[−s₁ + |h'₁|, −s₁ + |h|]` and found by Newton's method, which converges
//! from the left without overshooting because the secular function is convex and
//! decreasing there.

use nalgebra::{Matrix2, Matrix2x4, Matrix3, Matrix4, SymmetricEigen, Vector2, Vector4};
use qicp_core::{Point2, Pose2};

/// The quadratic form `xᵀMx + gᵀx` of a point-to-line cost in `x = (tx, ty, cos θ, sin θ)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointToLine {
    /// `Σ Mᵢᵀ Wᵢ Mᵢ` (symmetric).
    pub m: Matrix4<f64>,
    /// `−2 Σ Mᵢᵀ Wᵢ qᵢ`.
    pub g: Vector4<f64>,
    /// Pairs added.
    pub pairs: usize,
}

impl Default for PointToLine {
    fn default() -> Self {
        Self {
            m: Matrix4::zeros(),
            g: Vector4::zeros(),
            pairs: 0,
        }
    }
}

impl PointToLine {
    /// Adds the pair of scan point `p` (in the scan's frame) and reference point `q` with
    /// weight `w`: for a line through `q` with unit normal `n`, `w = n nᵀ / σ²`.
    pub fn add(&mut self, p: &Point2<f64>, q: &Point2<f64>, w: &Matrix2<f64>) {
        #[rustfmt::skip]
        let mi = Matrix2x4::new(
            1.0, 0.0, p.x, -p.y,
            0.0, 1.0, p.y, p.x,
        );
        let wm = w * mi;
        self.m += mi.transpose() * wm;
        self.g -= 2.0 * wm.transpose() * q.coords;
        self.pairs += 1;
    }

    /// Adds a Gaussian prior on the pose with information `lambda` (x, y, θ) around `guess`:
    /// its translation block exactly, its rotation as `λθθ |c − c_guess|²`
    /// (`= 4 λθθ sin²(Δθ/2)`, Δθ² for small turns). The cross terms between translation and
    /// rotation are left out (the odometry motion model has none).
    pub fn add_prior(&mut self, lambda: &Matrix3<f64>, guess: &Pose2) {
        let a = lambda.fixed_view::<2, 2>(0, 0);
        let t = guess.translation();
        let at = a * t;
        let ltt = lambda[(2, 2)];
        let c = Vector2::new(guess.theta.cos(), guess.theta.sin());
        for i in 0..2 {
            for j in 0..2 {
                self.m[(i, j)] += a[(i, j)];
            }
            self.m[(i + 2, i + 2)] += ltt;
            self.g[i] -= 2.0 * at[i];
            self.g[i + 2] -= 2.0 * ltt * c[i];
        }
    }

    /// The cost `xᵀMx + gᵀx` at `pose` (without the constant).
    #[must_use]
    pub fn cost(&self, pose: &Pose2) -> f64 {
        let x = Vector4::new(pose.x, pose.y, pose.theta.cos(), pose.theta.sin());
        x.dot(&(self.m * x)) + self.g.dot(&x)
    }
}

/// The sums of [`PointToLine::add`] for symmetric weights, kept in scalars rather than a
/// 4×4 matrix in memory: the same products and sums of the same values in the same order,
/// so [`SymmetricSums::system`] is the [`PointToLine`] that `add` builds, bit for bit.
///
/// `add` multiplies `Mᵢ`'s ones and zeros in; those products only change the sign of a zero
/// term, and a sum that starts from +0 never keeps a −0 (+0 + −0 = +0), so leaving them out
/// changes no bit. With `W` symmetric, `Mᵢᵀ W Mᵢ` is symmetric bit for bit except for its
/// lower-right 2×2 block, whose two off-diagonal entries are summed in different orders
/// and are kept apart here.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct SymmetricSums {
    /// `M`'s entries 00, 01, 11, 02, 03, 12, 13, 22, 23, 32, 33, then `g`.
    sums: PairTerms,
    pairs: usize,
}

/// What one pair adds to [`SymmetricSums`] (`M`'s entries, then what `g` loses), a function
/// of the pair alone: computed once, it may be added again whenever the pair is formed again.
pub(crate) type PairTerms = [f64; 15];

impl SymmetricSums {
    /// [`PointToLine::add`] with `w = [[w00, w01], [w01, w11]]` given as `[w00, w01, w11]`.
    #[cfg(test)]
    pub(crate) fn add(&mut self, p: &Point2<f64>, q: &Point2<f64>, w: &[f64; 3]) {
        self.add_terms(&Self::terms(p, q, w));
    }

    /// The terms of the pair `(p, q)` with weight `[w00, w01, w11]`.
    #[inline]
    pub(crate) fn terms(p: &Point2<f64>, q: &Point2<f64>, w: &[f64; 3]) -> PairTerms {
        let [w00, w01, w11] = *w;
        let (px, py) = (p.x, p.y);
        let npy = -py;
        // W·Mᵢ: its first two columns are W's own.
        let wm02 = w00 * px + w01 * py;
        let wm12 = w01 * px + w11 * py;
        let wm03 = w00 * npy + w01 * px;
        let wm13 = w01 * npy + w11 * px;
        let (qx, qy) = (q.x, q.y);
        [
            // Mᵢᵀ·(W·Mᵢ): the first two rows are W·Mᵢ, the rows below mirror its columns.
            w00,
            w01,
            w11,
            wm02,
            wm03,
            wm12,
            wm13,
            px * wm02 + py * wm12,
            px * wm03 + py * wm13,
            npy * wm02 + px * wm12,
            npy * wm03 + px * wm13,
            // 2 (W·Mᵢ)ᵀ q, with the 2 on the matrix as `add` has it.
            (2.0 * w00) * qx + (2.0 * w01) * qy,
            (2.0 * w01) * qx + (2.0 * w11) * qy,
            (2.0 * wm02) * qx + (2.0 * wm12) * qy,
            (2.0 * wm03) * qx + (2.0 * wm13) * qy,
        ]
    }

    /// Adds one pair's terms.
    #[inline]
    pub(crate) fn add_terms(&mut self, terms: &PairTerms) {
        for (s, t) in self.sums[..11].iter_mut().zip(&terms[..11]) {
            *s += t;
        }
        for (s, t) in self.sums[11..].iter_mut().zip(&terms[11..]) {
            *s -= t;
        }
        self.pairs += 1;
    }

    /// The system of the pairs added.
    pub(crate) fn system(&self) -> PointToLine {
        let [
            m00,
            m01,
            m11,
            m02,
            m03,
            m12,
            m13,
            m22,
            m23,
            m32,
            m33,
            g0,
            g1,
            g2,
            g3,
        ] = self.sums;
        #[rustfmt::skip]
        let m = Matrix4::new(
            m00, m01, m02, m03,
            m01, m11, m12, m13,
            m02, m12, m22, m23,
            m03, m13, m32, m33,
        );
        PointToLine {
            m,
            g: Vector4::new(g0, g1, g2, g3),
            pairs: self.pairs,
        }
    }
}

/// The pose minimising `system`'s cost exactly; `None` when it does not fix the pose (a
/// singular translation block, or no information on the rotation).
#[must_use]
pub fn solve(system: &PointToLine) -> Option<Pose2> {
    let m = &system.m;
    let a: Matrix2<f64> = m.fixed_view::<2, 2>(0, 0).into();
    let b: Matrix2<f64> = m.fixed_view::<2, 2>(0, 2).into();
    let d: Matrix2<f64> = m.fixed_view::<2, 2>(2, 2).into();
    let g1 = Vector2::new(system.g[0], system.g[1]);
    let g2 = Vector2::new(system.g[2], system.g[3]);
    // A singular translation block: the pairs leave a direction free (one straight wall
    // without a prior).
    let scale = a.trace().abs().max(f64::MIN_POSITIVE);
    let det = a.determinant();
    if det.is_nan() || det <= 1e-12 * scale * scale {
        return None;
    }
    let a_inv = a.try_inverse()?;
    let s = d - b.transpose() * a_inv * b;
    let h = (b.transpose() * a_inv * g1 - g2) * 0.5;
    let c = on_unit_circle(
        &Matrix2::new(s[(0, 0)], s[(0, 1)], s[(0, 1)], s[(1, 1)]),
        &h,
    )?;
    let t = -(a_inv * (b * c + g1 * 0.5));
    let pose = Pose2::new(t.x, t.y, c.y.atan2(c.x));
    [pose.x, pose.y, pose.theta]
        .iter()
        .all(|v| v.is_finite())
        .then_some(pose)
}

/// The unit vector `c` minimising `cᵀSc − 2hᵀc` (S symmetric).
fn on_unit_circle(s: &Matrix2<f64>, h: &Vector2<f64>) -> Option<Vector2<f64>> {
    let norm = h.norm();
    if !(norm > 0.0 && norm.is_finite()) {
        return None;
    }
    let eig = SymmetricEigen::new(*s);
    let (k1, k2) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    let (s1, s2) = (eig.eigenvalues[k1], eig.eigenvalues[k2]);
    let (q1, q2) = (eig.eigenvectors.column(k1), eig.eigenvectors.column(k2));
    let (h1, h2) = (q1.dot(h), q2.dot(h));
    // The hard case: h has no component along the softest direction, and the constraint is
    // met at λ = −s₁ with some of that direction added.
    if h1.abs() <= 1e-12 * norm && s2 > s1 {
        let c2 = h2 / (s2 - s1);
        if c2 * c2 <= 1.0 {
            let c1 = (1.0 - c2 * c2).sqrt();
            return Some(q1 * c1 + q2 * c2);
        }
    }
    let secular = |l: f64| {
        let (e1, e2) = (h1 / (s1 + l), h2 / (s2 + l));
        let f = e1 * e1 + e2 * e2 - 1.0;
        let df = -2.0 * (e1 * e1 / (s1 + l) + e2 * e2 / (s2 + l));
        (f, df)
    };
    // φ(−s₁ + |h₁|) ≥ 0 ≥ φ(−s₁ + |h|): the root lies between; Newton from the left.
    let hi = -s1 + norm;
    let mut l = (-s1 + h1.abs()).max(-s1 + 1e-300_f64.max(norm * 1e-15));
    for _ in 0..200 {
        let (f, df) = secular(l);
        if f.is_nan() || f <= 0.0 || df == 0.0 {
            break;
        }
        let next = (l - f / df).min(hi);
        if next - l <= 1e-15 * (1.0 + l.abs()) {
            l = next;
            break;
        }
        l = next;
    }
    let c = q1 * (h1 / (s1 + l)) + q2 * (h2 / (s2 + l));
    let n = c.norm();
    (n.is_finite() && n > 0.0).then(|| c / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (the crate keeps its dependencies to qicp's own).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next()
        }
    }

    /// The brute-force twin: for each θ the best translation is a 2×2 linear solve, so the
    /// cost is a function of θ alone; scan it on a fine grid and refine by golden section.
    fn brute_force(system: &PointToLine) -> Pose2 {
        let a: Matrix2<f64> = system.m.fixed_view::<2, 2>(0, 0).into();
        let b: Matrix2<f64> = system.m.fixed_view::<2, 2>(0, 2).into();
        let g1 = Vector2::new(system.g[0], system.g[1]);
        let a_inv = a.try_inverse().expect("test systems fix the translation");
        let at = |theta: f64| {
            let c = Vector2::new(theta.cos(), theta.sin());
            let t = -(a_inv * (b * c + g1 * 0.5));
            Pose2::new(t.x, t.y, theta)
        };
        let cost = |theta: f64| system.cost(&at(theta));
        let n = 20_000;
        let step = std::f64::consts::TAU / n as f64;
        let best = (0..n)
            .map(|k| -std::f64::consts::PI + k as f64 * step)
            .min_by(|x, y| cost(*x).total_cmp(&cost(*y)))
            .unwrap();
        let (mut lo, mut hi) = (best - step, best + step);
        let r = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..200 {
            let (m1, m2) = (hi - r * (hi - lo), lo + r * (hi - lo));
            if cost(m1) < cost(m2) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        at(0.5 * (lo + hi))
    }

    fn random_system(rng: &mut Lcg, with_prior: bool) -> (PointToLine, Pose2) {
        let truth = Pose2::new(
            rng.range(-2.0, 2.0),
            rng.range(-2.0, 2.0),
            rng.range(-3.0, 3.0),
        );
        let mut system = PointToLine::default();
        let n = 3 + (rng.next() * 40.0) as usize;
        for _ in 0..n {
            let p = Point2::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0));
            let a = rng.range(0.0, std::f64::consts::TAU);
            let normal = Vector2::new(a.cos(), a.sin());
            // A noisy correspondence: the moved point, off its line by up to 5 cm.
            let q = truth.transform_point(&p) + normal * rng.range(-0.05, 0.05);
            let w = normal * normal.transpose() * rng.range(0.5, 2.0)
                + Matrix2::identity() * rng.range(0.0, 0.05);
            system.add(&p, &q, &w);
        }
        if with_prior {
            let lambda = Matrix3::from_diagonal(&nalgebra::Vector3::new(
                rng.range(1.0, 100.0),
                rng.range(1.0, 100.0),
                rng.range(1.0, 100.0),
            ));
            let guess = truth * Pose2::new(0.1, -0.05, 0.05);
            system.add_prior(&lambda, &guess);
        }
        (system, truth)
    }

    #[test]
    fn the_exact_solution_matches_the_brute_force_minimum_on_random_systems() {
        let mut rng = Lcg(7);
        for round in 0..300 {
            let (system, _) = random_system(&mut rng, round % 2 == 1);
            let exact = solve(&system).expect("random systems are well posed");
            let brute = brute_force(&system);
            let (ce, cb) = (system.cost(&exact), system.cost(&brute));
            assert!(
                ce <= cb + 1e-9 * (1.0 + cb.abs()),
                "round {round}: exact cost {ce} above brute force {cb}"
            );
            assert!(
                exact.distance(&brute) < 1e-6,
                "round {round}: {exact:?} vs {brute:?}"
            );
            let dt = qicp_core::normalize_angle(exact.theta - brute.theta).abs();
            assert!(
                dt < 1e-6,
                "round {round}: θ {} vs {}",
                exact.theta,
                brute.theta
            );
        }
    }

    /// A coordinate or weight, sometimes exactly ±0 or ±1 so that the terms `add` multiplies
    /// by `Mᵢ`'s zeros and ones meet signed zeros.
    fn value(rng: &mut Lcg, lo: f64, hi: f64) -> f64 {
        match (rng.next() * 8.0) as u32 {
            0 => 0.0,
            1 => -0.0,
            2 => 1.0,
            3 => -1.0,
            _ => rng.range(lo, hi),
        }
    }

    #[test]
    fn the_symmetric_sums_are_the_plain_system_bit_for_bit() {
        let mut rng = Lcg(11);
        for round in 0..2_000 {
            let mut plain = PointToLine::default();
            let mut sums = SymmetricSums::default();
            for _ in 0..(rng.next() * 60.0) as usize {
                let p = Point2::new(value(&mut rng, -30.0, 30.0), value(&mut rng, -30.0, 30.0));
                let q = Point2::new(value(&mut rng, -30.0, 30.0), value(&mut rng, -30.0, 30.0));
                let w = [
                    value(&mut rng, 0.0, 3000.0),
                    value(&mut rng, -3000.0, 3000.0),
                    value(&mut rng, 0.0, 3000.0),
                ];
                plain.add(&p, &q, &Matrix2::new(w[0], w[1], w[1], w[2]));
                sums.add(&p, &q, &w);
            }
            let fast = sums.system();
            assert_eq!(fast.pairs, plain.pairs);
            let bits = |s: &PointToLine| {
                (
                    s.m.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    s.g.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                )
            };
            assert_eq!(
                bits(&fast),
                bits(&plain),
                "round {round}: {fast:?} vs {plain:?}"
            );
        }
    }

    #[test]
    fn exact_pairs_give_the_true_pose_in_one_solve_however_far_the_turn() {
        for (k, theta) in [-3.1, -1.7, -0.4, 0.0, 0.9, 2.5, 3.1]
            .into_iter()
            .enumerate()
        {
            let truth = Pose2::new(1.5 - k as f64 * 0.3, -0.7, theta);
            let mut system = PointToLine::default();
            for i in 0..12 {
                let p = Point2::new((i as f64 * 1.3).sin() * 5.0, (i as f64 * 0.7).cos() * 4.0);
                let a = i as f64 * 0.9;
                let n = Vector2::new(a.cos(), a.sin());
                system.add(&p, &truth.transform_point(&p), &(n * n.transpose()));
            }
            let found = solve(&system).expect("twelve lines in all directions fix the pose");
            assert!(found.distance(&truth) < 1e-9, "{found:?} vs {truth:?}");
            assert!(qicp_core::normalize_angle(found.theta - truth.theta).abs() < 1e-9);
        }
    }

    #[test]
    fn one_wall_without_a_prior_leaves_the_pose_free() {
        let mut system = PointToLine::default();
        let n = Vector2::new(0.0, 1.0);
        for i in 0..20 {
            let p = Point2::new(i as f64 * 0.2, 1.0);
            system.add(&p, &p, &(n * n.transpose()));
        }
        assert_eq!(solve(&system), None);
        // The odometry prior fixes what the wall does not.
        system.add_prior(&Matrix3::identity(), &Pose2::new(0.3, 0.0, 0.0));
        let found = solve(&system).expect("the prior fixes the free direction");
        assert!(
            (found.x - 0.3).abs() < 1e-6 && found.y.abs() < 1e-9,
            "{found:?}"
        );
    }
}
