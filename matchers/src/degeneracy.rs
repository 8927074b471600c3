//! Directions of the pose a scan does not fix keep the prior's estimate: solution remapping
//! (Zhang, Kaess and Singh, "On degeneracy of optimization-based state estimation problems",
//! ICRA 2016), as LOAM applies it along featureless corridors.
//!
//! A match is weighed against its prior (odometry, or a stall's constant-velocity
//! prediction) inside the matcher. Along a corridor whose walls run on beyond the laser's
//! reach, the walls say nothing about how far the robot went, but point-to-point pairs still
//! pull: the scan's far ends pair with the ends of the walls the map or the reference scan
//! holds, a few centimetres short of them, and WSM's along-surface term counts every pair
//! on a wall as independent. The pull wins over a loose prior, and the estimate creeps.
//!
//! The remedy asks what the scan can fix at all. The scan's points are paired with the
//! reference's nearest points; the direction of translation they constrain least (the
//! smallest eigenvector of Σ n nᵀ over the pairs' surface normals) is the candidate, along a
//! corridor its axis. What the scan knows along it (information, in units of 1/σ², σ² the
//! variance of the points' distances to their surfaces) is counted point by point, as WSM
//! models a pair:
//! - a point on a straight surface (linearity 1) tells the motion along its normal only,
//!   and counts (n·u)² where its normal lies within 60° of the direction (a door frame, a
//!   corner's other wall), nothing otherwise: a wall's fitted normals are tilted by a few
//!   degrees at random, and counted in full that tilt would claim a corridor's length known
//!   to a centimetre from the 140 points on its side walls;
//! - a normal is turned towards the direction only by what exceeds three times its
//!   deviation (σ over the root of its fit's scatter along the surface,
//!   [`qicp_core::PointInfo::normal_sigma`]): a dense laser (0.5°) samples a wall a metre
//!   away every 9 mm, and the line through five such samples turns by 20° at random, so
//!   that wall's noise alone would face every direction;
//! - a point on a curved surface (linearity 0: a trunk, a corner) counts 1 in every
//!   direction, and points in between in proportion (l (n·u)² + 1 − l);
//! - a point that counts less than a straight surface facing the direction at 60° (0.25)
//!   counts nothing, nor does a point without a normal (a surface of unknown direction: in
//!   a map most are a far wall's samples at a grazing angle, where the laser's reach cuts the
//!   wall short), and fewer than three points that count tell nothing.
//!
//! Where what the scan knows along the direction is below what the prior knows there, the
//! match keeps the prior's estimate along it, and its covariance the prior's; every other
//! direction, and every match that knows more than the prior along its weakest direction,
//! is left exactly as it was.

use crate::validation::Placed;
use nalgebra::{Matrix2, Vector2};
use qicp_core::{MatchResult, Matrix3, Pose2, Reference, SpatialIndex};

/// A surface tells the motion along a direction when its normal lies within this of it
/// (cos 60°).
const FACING_COS: f64 = 0.5;
/// A normal counts as turned towards a direction only by what exceeds this many of its
/// deviations ([`qicp_core::PointInfo::normal_sigma`]), a turn noise gives one normal in a
/// few hundred: a wall sampled every few millimetres (a dense laser close to it) fits
/// normals turned by tens of degrees at random, and without this its noise alone would face
/// any direction.
const FACING_SIGMAS: f64 = 3.0;
/// Fewer points than this telling a direction tell nothing along it: one or two normals
/// turned that far are a noisy fit, not a surface.
const MIN_FACING: usize = 3;

/// The direction of translation a scan constrains least, and what it knows along it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeakDirection {
    /// Unit direction in the reference frame.
    pub direction: Vector2<f64>,
    /// Information along it (1/m²) from the surfaces that face it.
    pub information: f64,
}

/// The direction of translation the scan `placed` constrains least, from its points with a
/// reference point within `reach` (the smallest eigenvector of Σ n nᵀ over their normals),
/// and the information along it of the points that tell it (see the module's doc), with the
/// variance of the points' distances to their surfaces, never below the laser's range
/// variance. `None` with fewer than three paired points whose surface has a normal. Reads
/// the look-ups `placed` made, so a reach beyond its own counts no more than its own.
#[must_use]
pub fn weak_direction<I: SpatialIndex>(
    reference: &Reference<I>,
    placed: &Placed,
    reach: f64,
) -> Option<WeakDirection> {
    let info = reference.info();
    // The pairs within reach, each with its reference point's surface.
    let paired = || {
        placed.points.iter().filter_map(move |(p, nearest)| {
            let n = nearest.filter(|n| n.dist_sq <= reach * reach)?;
            let at = &info[n.id as usize];
            Some((n.point - p, at.normal, at.linearity, at.normal_sigma))
        })
    };
    let (mut pairs, mut with_normal) = (0usize, 0usize);
    let mut sum_sq = 0.0;
    let mut spread = Matrix2::zeros();
    for (d, normal, _, _) in paired() {
        pairs += 1;
        if normal == Vector2::zeros() {
            sum_sq += d.norm_squared() / 2.0;
        } else {
            with_normal += 1;
            sum_sq += normal.dot(&d).powi(2);
            spread += normal * normal.transpose();
        }
    }
    // Without three surfaces of known direction there is no direction to judge (lone
    // points alone: a far post, a sparse fringe), and nothing is held.
    if with_normal < 3 {
        return None;
    }
    let floor = reference.noise().sigma_range.powi(2).max(1e-8);
    let sigma2 = (sum_sq / (pairs as f64 - 3.0).max(1.0)).max(floor);
    let eigen = spread.symmetric_eigen();
    let weakest = if eigen.eigenvalues[0] <= eigen.eigenvalues[1] {
        0
    } else {
        1
    };
    let u: Vector2<f64> = eigen.eigenvectors.column(weakest).into();
    // What each point tells along u, as a share of a point facing it head-on; a point
    // telling less than a straight surface at 60° does is noise (a far, sparse wall's fit).
    let (mut facing, mut count) = (0.0, 0);
    for (_, n, l, sigma_n) in paired() {
        // A point without a normal is a sample of a surface of unknown direction: in a map
        // most are a far wall's sparse samples at a grazing angle, not posts.
        if n == Vector2::zeros() {
            continue;
        }
        // How far the surface turns from running along u, less what its fit's noise turns it.
        let turned = n.dot(&u).abs().min(1.0).asin();
        let c = (turned - FACING_SIGMAS * sigma_n).max(0.0).sin();
        let w = l * c * c + (1.0 - l);
        if w >= FACING_COS * FACING_COS {
            facing += w;
            count += 1;
        }
    }
    if count < MIN_FACING {
        facing = 0.0;
    }
    Some(WeakDirection {
        direction: u,
        information: facing / sigma2,
    })
}

/// Keeps the prediction `predicted` along the weak direction where the scan knows less
/// there than the prior (`prior`, its information matrix, 1/m² and 1/rad²), and the match's
/// estimate in every other direction; the covariance takes the prior's variance along it.
/// Returns whether it held (the result is untouched otherwise).
pub fn hold_unobserved(
    result: &mut MatchResult,
    predicted: &Pose2,
    prior: &Matrix3<f64>,
    weak: &WeakDirection,
) -> bool {
    let u = weak.direction;
    let along = u.dot(&(prior.fixed_view::<2, 2>(0, 0) * u));
    // A NaN on either side (a prior that is not finite) holds nothing.
    if weak.information.partial_cmp(&along) != Some(std::cmp::Ordering::Less) {
        return false;
    }
    let slid = (result.pose.translation() - predicted.translation()).dot(&u);
    let t = result.pose.translation() - u * slid;
    result.pose = Pose2::new(t.x, t.y, result.pose.theta);
    // d' = A d with A = I − u uᵀ on x and y; the prior's variance along u.
    let mut a = Matrix3::identity();
    a.fixed_view_mut::<2, 2>(0, 0)
        .copy_from(&(Matrix2::identity() - u * u.transpose()));
    let mut held = Matrix3::zeros();
    held.fixed_view_mut::<2, 2>(0, 0)
        .copy_from(&(u * u.transpose() / along));
    result.covariance = a * result.covariance * a.transpose() + held;
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use qicp_core::{Fallback, Vector3};

    fn result(pose: Pose2) -> MatchResult {
        MatchResult {
            pose,
            covariance: Matrix3::identity() * 1e-4,
            iterations: 1,
            correspondences: 100,
            residual: 0.01,
            converged: true,
            fallback: None::<Fallback>,
        }
    }

    fn prior() -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::new(100.0, 100.0, 1000.0))
    }

    #[test]
    fn a_scan_that_knows_more_than_the_prior_leaves_the_match_as_it_was() {
        let weak = WeakDirection {
            direction: Vector2::x(),
            information: 101.0,
        };
        let before = result(Pose2::new(0.3, -0.1, 0.05));
        let mut after = before;
        assert!(!hold_unobserved(
            &mut after,
            &Pose2::IDENTITY,
            &prior(),
            &weak
        ));
        assert_eq!(after, before);
    }

    #[test]
    fn along_a_corridor_the_prior_holds_and_across_it_the_match() {
        let weak = WeakDirection {
            direction: Vector2::x(),
            information: 20.0,
        };
        let start = Pose2::new(1.0, 2.0, 0.3);
        let mut r = result(Pose2::new(1.4, 2.05, 0.31));
        assert!(hold_unobserved(&mut r, &start, &prior(), &weak));
        assert!((r.pose.x - 1.0).abs() < 1e-12, "{:?}", r.pose);
        assert!((r.pose.y - 2.05).abs() < 1e-12 && (r.pose.theta - 0.31).abs() < 1e-12);
        // The covariance is the prior's along x, the match's across.
        assert!(
            (r.covariance[(0, 0)] - 0.01).abs() < 1e-12,
            "{}",
            r.covariance
        );
        assert!((r.covariance[(1, 1)] - 1e-4).abs() < 1e-12);
    }

    #[test]
    fn a_corridor_turned_in_the_plane_holds_its_own_axis() {
        let weak = WeakDirection {
            direction: Vector2::new(1.0, 1.0) / 2f64.sqrt(),
            information: 0.0,
        };
        // A step along the axis is the prior's (none); across it the match's stays.
        let mut r = result(Pose2::new(0.3, 0.3, 0.0));
        assert!(hold_unobserved(&mut r, &Pose2::IDENTITY, &prior(), &weak));
        assert!(
            r.pose.x.abs() < 1e-12 && r.pose.y.abs() < 1e-12,
            "{:?}",
            r.pose
        );
        let mut across = result(Pose2::new(-0.1, 0.1, 0.0));
        assert!(hold_unobserved(
            &mut across,
            &Pose2::IDENTITY,
            &prior(),
            &weak
        ));
        assert!((across.pose.x + 0.1).abs() < 1e-12 && (across.pose.y - 0.1).abs() < 1e-12);
    }
}
