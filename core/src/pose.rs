//! Rigid motions of the plane, SE(2).

use nalgebra::{Isometry2, Matrix2, Point2, Vector2};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::ops::Mul;

/// Normalises an angle to the half-open interval (−π, π].
#[must_use]
pub fn normalize_angle(a: f64) -> f64 {
    if !a.is_finite() {
        return a;
    }
    let mut r = a % (2.0 * PI);
    if r > PI {
        r -= 2.0 * PI;
    } else if r <= -PI {
        r += 2.0 * PI;
    }
    r
}

/// A pose in the plane: position `(x, y)` and heading `theta` (radians, normalised to (−π, π]).
///
/// Read `a * b` as "`b` expressed in frame `a`, brought into `a`'s parent frame": with robot
/// poses `P1`, `P2` in the world, `P1.inverse() * P2` is `P2` seen from `P1` (the Freiburg
/// relation convention) and `P1 * delta` applies a motion measured in the robot frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    /// x position (m).
    pub x: f64,
    /// y position (m).
    pub y: f64,
    /// Heading (rad).
    pub theta: f64,
}

impl Pose2 {
    /// The identity pose.
    pub const IDENTITY: Pose2 = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };

    /// A pose; `theta` is normalised.
    #[must_use]
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self {
            x,
            y,
            theta: normalize_angle(theta),
        }
    }

    /// The translation part.
    #[must_use]
    pub fn translation(&self) -> Vector2<f64> {
        Vector2::new(self.x, self.y)
    }

    /// The rotation matrix of the heading.
    #[must_use]
    pub fn rotation(&self) -> Matrix2<f64> {
        let (s, c) = self.theta.sin_cos();
        Matrix2::new(c, -s, s, c)
    }

    /// `self ∘ other`: `other` given in the frame of `self`.
    #[must_use]
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            self.theta + other.theta,
        )
    }

    /// The inverse motion: `p.compose(&p.inverse())` is the identity.
    #[must_use]
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            -(c * self.x + s * self.y),
            s * self.x - c * self.y,
            -self.theta,
        )
    }

    /// `other` expressed in the frame of `self`: `self.inverse() * other`.
    #[must_use]
    pub fn between(&self, other: &Pose2) -> Pose2 {
        self.inverse().compose(other)
    }

    /// Maps a point from this pose's frame into the parent frame.
    #[must_use]
    pub fn transform_point(&self, p: &Point2<f64>) -> Point2<f64> {
        let (s, c) = self.theta.sin_cos();
        Point2::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y)
    }

    /// Maps a point from the parent frame into this pose's frame.
    #[must_use]
    pub fn inverse_transform_point(&self, p: &Point2<f64>) -> Point2<f64> {
        let (s, c) = self.theta.sin_cos();
        let dx = p.x - self.x;
        let dy = p.y - self.y;
        Point2::new(c * dx + s * dy, -s * dx + c * dy)
    }

    /// Distance between the positions of two poses.
    #[must_use]
    pub fn distance(&self, other: &Pose2) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    /// True when every component is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// As a nalgebra isometry.
    #[must_use]
    pub fn to_isometry(&self) -> Isometry2<f64> {
        Isometry2::new(self.translation(), self.theta)
    }

    /// From a nalgebra isometry.
    #[must_use]
    pub fn from_isometry(iso: &Isometry2<f64>) -> Pose2 {
        Pose2::new(iso.translation.x, iso.translation.y, iso.rotation.angle())
    }
}

impl Mul for Pose2 {
    type Output = Pose2;
    fn mul(self, rhs: Pose2) -> Pose2 {
        self.compose(&rhs)
    }
}

impl Mul<Point2<f64>> for Pose2 {
    type Output = Point2<f64>;
    fn mul(self, rhs: Point2<f64>) -> Point2<f64> {
        self.transform_point(&rhs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pose() -> impl Strategy<Value = Pose2> {
        (-100.0..100.0f64, -100.0..100.0f64, -10.0..10.0f64)
            .prop_map(|(x, y, t)| Pose2::new(x, y, t))
    }

    fn close(a: &Pose2, b: &Pose2, tol: f64) -> bool {
        (a.x - b.x).abs() < tol
            && (a.y - b.y).abs() < tol
            && normalize_angle(a.theta - b.theta).abs() < tol
    }

    proptest! {
        #[test]
        fn compose_with_inverse_is_identity(p in pose()) {
            prop_assert!(close(&(p * p.inverse()), &Pose2::IDENTITY, 1e-9));
            prop_assert!(close(&(p.inverse() * p), &Pose2::IDENTITY, 1e-9));
        }

        #[test]
        fn between_round_trips(a in pose(), b in pose()) {
            prop_assert!(close(&(a * a.between(&b)), &b, 1e-9));
        }

        #[test]
        fn compose_is_associative(a in pose(), b in pose(), c in pose()) {
            prop_assert!(close(&((a * b) * c), &(a * (b * c)), 1e-8));
        }

        #[test]
        fn point_transform_round_trips(p in pose(), x in -50.0..50.0f64, y in -50.0..50.0f64) {
            let q = Point2::new(x, y);
            let back = p.inverse_transform_point(&p.transform_point(&q));
            prop_assert!((back - q).norm() < 1e-9);
            // Composition acts on points like applying the factors in turn.
            let r = Pose2::new(1.0, -2.0, 0.3);
            let lhs = (p * r) * q;
            let rhs = p * (r * q);
            prop_assert!((lhs - rhs).norm() < 1e-9);
        }

        #[test]
        fn agrees_with_nalgebra(a in pose(), b in pose()) {
            let ours = a * b;
            let theirs = Pose2::from_isometry(&(a.to_isometry() * b.to_isometry()));
            prop_assert!(close(&ours, &theirs, 1e-9));
        }

        #[test]
        fn normalised_angles_stay_in_range(t in -1e4..1e4f64) {
            let n = normalize_angle(t);
            prop_assert!(n > -PI - 1e-12 && n <= PI + 1e-12);
            prop_assert!(((n - t) / (2.0 * PI)).round() * 2.0 * PI - (n - t) < 1e-6);
        }
    }

    #[test]
    fn quarter_turn_moves_points() {
        let p = Pose2::new(1.0, 2.0, std::f64::consts::FRAC_PI_2);
        let q = p * Point2::new(1.0, 0.0);
        assert!((q - Point2::new(1.0, 3.0)).norm() < 1e-12);
    }
}
