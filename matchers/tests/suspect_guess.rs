//! IDC checks its initial guess against the scan (`[matcher.idc] verify`): a guess that leaves
//! more than `suspect_guess` of the largest misfit (every point unexplained) is no prior, and
//! the match runs as if none had been given. At 1 or more no guess is dropped. The guess and
//! the prior are odometry's in the pipeline; these tests give them directly.

use qicp_core::testdata::SyntheticWorld;
use qicp_core::{
    ClosestPoint, MatchResult, Matrix3, Pose2, QuadTree, Reference, ScanMatcher, Vector3,
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

/// The room seen from two poses 0.3 m apart: the first scan is the reference, the second is
/// matched from `guess` (an offset from its true pose) under `prior`.
fn matched(params: IdcParams, offset: Pose2, prior: Option<Matrix3<f64>>) -> MatchResult {
    let world = SyntheticWorld::room();
    let from = Pose2::new(-1.0, -0.5, 0.1);
    let truth = from * Pose2::new(0.3, 0.05, 0.04);
    let mut reference = Reference::new(QuadTree::default());
    reference
        .insert_scan(&world.scan(&from, 0.01, 1), &from, None)
        .expect("finite points");
    let scan = world.scan(&truth, 0.01, 2);
    let mut idc: Idc<ClosestPoint> = Idc::new(IcpParams::default(), params);
    idc.match_with_prior(&reference, &scan, truth * offset, prior)
}

fn never_suspect() -> IdcParams {
    IdcParams {
        suspect_guess: 1.0,
        ..IdcParams::default()
    }
}

#[test]
fn a_guess_far_off_is_no_prior_unless_suspect_guess_says_never() {
    // 0.25 m and 6° off: most points lie more than 5 cm from the walls.
    let far = Pose2::new(0.25, -0.2, 6f64.to_radians());
    let dropped = matched(IdcParams::default(), far, Some(prior()));
    let without = matched(IdcParams::default(), far, None);
    assert!(dropped.fallback.is_none(), "{:?}", dropped.fallback);
    // The prior is left out: the same match, covariance and all, as with none given.
    assert_eq!(dropped.pose, without.pose);
    assert_eq!(dropped.covariance, without.covariance);
    // Never suspect: the prior sizes the first window and gate and is fused with each step,
    // and the match differs.
    let kept = matched(never_suspect(), far, Some(prior()));
    assert!(kept.fallback.is_none(), "{:?}", kept.fallback);
    assert_ne!(kept.pose, without.pose);
}

#[test]
fn a_guess_near_the_truth_is_the_prior_either_way() {
    let near = Pose2::new(0.01, -0.01, 0.2f64.to_radians());
    let default = matched(IdcParams::default(), near, Some(prior()));
    let never = matched(never_suspect(), near, Some(prior()));
    let without = matched(IdcParams::default(), near, None);
    assert_eq!(default.pose, never.pose);
    assert_eq!(default.covariance, never.covariance);
    assert_ne!(default.pose, without.pose);
}
