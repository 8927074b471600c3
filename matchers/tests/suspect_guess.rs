//! IDC checks its initial guess against the scan (`[matcher.idc] verify`): a guess that leaves
//! more than `suspect_guess` of the largest misfit (every point unexplained) is no prior, and
//! the match runs as if none had been given. At 1 or more no guess is dropped. With
//! `suspect_with_prior` a suspect guess is matched both ways, and where the two matches lie
//! apart the better fit is kept. The guess and the prior are odometry's in the pipeline; these
//! tests give them directly.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{
    ClosestPoint, MatchResult, Matrix3, Pose2, QuadTree, Reference, Scan, ScanMatcher, Vector3,
};
use qicp_matchers::{IcpParams, Idc, IdcParams};

/// Odometry's prior of 5 cm and 1°.
fn prior() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(
        0.05f64.powi(-2),
        0.05f64.powi(-2),
        1f64.to_radians().powi(-2),
    ))
}

/// The room seen from two poses: the first scan is the reference, the second is matched.
struct View {
    reference: Reference<QuadTree>,
    truth: Pose2,
    scan: Scan,
}

impl View {
    /// The robot drives 0.3 m and turns 2.3° between the scans.
    fn plain() -> Self {
        Self::new(
            Pose2::new(-1.0, -0.5, 0.1),
            Pose2::new(0.3, 0.05, 0.04),
            1.0,
        )
    }

    /// The robot drives 0.3 m and turns 17°, and every beam of the second scan's middle 100
    /// but every fifth returns from something the reference never saw, at 80 % of the wall's
    /// range, as people standing in front of the walls would.
    fn cluttered() -> Self {
        Self::new(Pose2::IDENTITY, Pose2::new(0.3, 0.02, 0.3), 0.8)
    }

    fn new(from: Pose2, motion: Pose2, clutter: f64) -> Self {
        let world = SyntheticWorld::room();
        let truth = from * motion;
        let mut reference = Reference::new(QuadTree::default());
        reference
            .insert_scan(&world.scan(&from, 0.01, 1), &from, None)
            .expect("finite points");
        let clear = world.scan(&truth, 0.01, 2);
        let mut ranges = clear.ranges().to_vec();
        for (i, r) in ranges.iter_mut().enumerate().skip(40).take(100) {
            if i % 5 != 0 {
                *r *= clutter;
            }
        }
        let scan = Scan::new(0.0, clear.geometry, ranges).expect("the scan's own geometry");
        Self {
            reference,
            truth,
            scan,
        }
    }

    /// The scan matched from `offset` off its true pose, under `prior`.
    fn matched(
        &self,
        params: IdcParams,
        offset: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        let mut idc: Idc<ClosestPoint> = Idc::new(IcpParams::default(), params);
        idc.match_with_prior(&self.reference, &self.scan, self.truth * offset, prior)
    }

    /// The share of the largest misfit `pose` leaves: the scan's points' squared distances to
    /// the reference surface, capped at 5 cm, over the cap's, as IDC's check measures it.
    fn misfit_share(&self, pose: &Pose2) -> f64 {
        let cap = 0.05f64 * 0.05;
        let points = self.scan.points();
        let sum: f64 = points
            .iter()
            .map(|b| {
                self.reference
                    .surface_distance_sq(&pose.transform_point(b), 4.0 * cap)
                    .map_or(cap, |d| d.min(cap))
            })
            .sum();
        sum / (points.len() as f64 * cap)
    }

    /// How far `pose` lies from the truth (m, deg).
    fn error(&self, pose: &Pose2) -> (f64, f64) {
        let e = pose.inverse() * self.truth;
        (e.translation().norm(), e.theta.to_degrees().abs())
    }
}

fn never_suspect() -> IdcParams {
    IdcParams {
        suspect_guess: 1.0,
        ..IdcParams::default()
    }
}

fn both_ways() -> IdcParams {
    IdcParams {
        suspect_with_prior: true,
        ..IdcParams::default()
    }
}

/// 0.25 m and 6° off: most points lie more than 5 cm from the walls.
fn far() -> Pose2 {
    Pose2::new(0.25, -0.2, 6f64.to_radians())
}

fn near() -> Pose2 {
    Pose2::new(0.01, -0.01, 0.2f64.to_radians())
}

#[test]
fn a_guess_far_off_is_no_prior_unless_suspect_guess_says_never() {
    let view = View::plain();
    let dropped = view.matched(IdcParams::default(), far(), Some(prior()));
    let without = view.matched(IdcParams::default(), far(), None);
    assert!(dropped.fallback.is_none(), "{:?}", dropped.fallback);
    // The prior is left out: the same match, covariance and all, as with none given.
    assert_eq!(dropped.pose, without.pose);
    assert_eq!(dropped.covariance, without.covariance);
    // Never suspect: the prior sizes the first window and gate and is fused with each step,
    // and the match differs.
    let kept = view.matched(never_suspect(), far(), Some(prior()));
    assert!(kept.fallback.is_none(), "{:?}", kept.fallback);
    assert_ne!(kept.pose, without.pose);
}

#[test]
fn a_guess_near_the_truth_is_the_prior_either_way() {
    let view = View::plain();
    let default = view.matched(IdcParams::default(), near(), Some(prior()));
    let never = view.matched(never_suspect(), near(), Some(prior()));
    let without = view.matched(IdcParams::default(), near(), None);
    assert_eq!(default.pose, never.pose);
    assert_eq!(default.covariance, never.covariance);
    assert_ne!(default.pose, without.pose);
    // Not suspect: matched once, as by default.
    let both = view.matched(both_ways(), near(), Some(prior()));
    assert_eq!(both.pose, default.pose);
    assert_eq!(both.iterations, default.iterations);
}

#[test]
fn a_right_guess_in_clutter_keeps_its_prior_when_matched_both_ways() {
    let view = View::cluttered();
    // 3° off, where odometry's turn of 17° put it: the clutter makes the guess suspect.
    let offset = Pose2::new(0.02, -0.02, 3f64.to_radians());
    assert!(view.misfit_share(&(view.truth * offset)) > 0.4);
    // Without its prior, from the widest window, the match lands far off; with it, on the
    // truth, fitting the scan better.
    let dropped = view.matched(IdcParams::default(), offset, Some(prior()));
    let kept = view.matched(never_suspect(), offset, Some(prior()));
    let (off, on) = (view.error(&dropped.pose), view.error(&kept.pose));
    assert!(off.0 > 0.5 && off.1 > 5.0, "{off:?}");
    assert!(on.0 < 0.02 && on.1 < 0.5, "{on:?}");
    assert!(view.misfit_share(&kept.pose) < view.misfit_share(&dropped.pose));
    // Both ways: the prior's match, with the prior in its covariance.
    let both = view.matched(both_ways(), offset, Some(prior()));
    assert_eq!(both.pose, kept.pose);
    assert_eq!(both.covariance, kept.covariance);
    assert!(both.iterations > kept.iterations);
}

#[test]
fn a_wrong_guess_matched_both_ways_keeps_the_match_without_its_prior() {
    let view = View::plain();
    let without = view.matched(IdcParams::default(), far(), None);
    let kept = view.matched(never_suspect(), far(), Some(prior()));
    let both = view.matched(both_ways(), far(), Some(prior()));
    // The match without the prior, from the widest window, stands: the prior's lies no
    // farther from it than the check's 5 cm, or fits worse.
    assert!(view.error(&without.pose).0 < 0.02);
    assert_eq!(both.pose, without.pose);
    assert_eq!(both.covariance, without.covariance);
    assert!(both.iterations > without.iterations);
    assert_ne!(kept.pose, without.pose);
}

#[test]
fn two_matches_no_point_tells_apart_are_one_and_the_first_stands() {
    // In the plain view a guess 5 cm and 3° off is suspect; both ways end about a millimetre
    // apart, the prior's fitting a little better, and the match without the prior stands:
    // a choice between two such matches would be a choice by the scan's noise.
    let view = View::plain();
    let offset = Pose2::new(0.0, 0.05, 3f64.to_radians());
    assert!(view.misfit_share(&(view.truth * offset)) > 0.4);
    let dropped = view.matched(IdcParams::default(), offset, Some(prior()));
    let kept = view.matched(never_suspect(), offset, Some(prior()));
    let both = view.matched(both_ways(), offset, Some(prior()));
    let apart = (dropped.pose.inverse() * kept.pose).translation().norm();
    assert!(apart > 0.0 && apart < 0.005, "{apart}");
    assert!(view.misfit_share(&kept.pose) < view.misfit_share(&dropped.pose));
    assert_eq!(both.pose, dropped.pose);
    assert_eq!(both.covariance, dropped.covariance);
}
