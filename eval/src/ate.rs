//! Against ground truth: ATE after origin alignment (evo's `--align_origin`), RPE per metre
//! driven, final error.

use crate::{
    DEFAULT_MAX_DT, DEFAULT_RPE_SEGMENT_M, EvalError, check_max_dt, nearest_index, stats,
    time_sorted,
};
use qicp_core::{Pose2, normalize_angle};

use qicp_io::tum::Stamped;
use serde::Serialize;

/// How to compare an estimate with ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AteOptions {
    /// Pose pairs are associated by nearest timestamp within this (s). `evo` uses 0.01 s;
    /// simulated estimates share the truth's timestamps exactly. Default [`DEFAULT_MAX_DT`].
    pub max_dt: f64,
    /// Length (m) of the segments of the relative pose error. Default
    /// [`DEFAULT_RPE_SEGMENT_M`].
    pub rpe_segment_m: f64,
}

impl Default for AteOptions {
    fn default() -> Self {
        Self {
            max_dt: DEFAULT_MAX_DT,
            rpe_segment_m: DEFAULT_RPE_SEGMENT_M,
        }
    }
}

/// Errors of an estimated trajectory against ground truth.
///
/// **Association.** As `evo` does: every pose of the shorter trajectory is paired with the
/// pose of the other nearest in time, if within `max_dt`; `missing` counts the poses of the
/// shorter one left without a partner.
///
/// **ATE** (absolute trajectory error, `evo_ape --align_origin`): the estimate is moved by
/// the rigid motion `T = truth₀ · inv(est₀)` that puts its first associated pose onto the
/// true one; the error of pair i is the distance between the positions of `T · estᵢ` and
/// `truthᵢ`; `ate_rmse_m` is their root mean square.
///
/// **RPE** (relative pose error per metre driven, the KITTI odometry metric of Geiger et al.
/// 2012 with a single segment length d = `rpe_segment_m`): from every associated pose i, the
/// segment ends at the first pose j whose true path length from i reaches d; the segment's
/// error is `E = inv(inv(truthᵢ)·truthⱼ) · (inv(estᵢ)·estⱼ)`; `rpe_trans_per_m` is the mean
/// of `|translation(E)| / Lᵢⱼ` (m per m; ×100 for %) and `rpe_rot_deg_per_m` the mean of
/// `|angle(E)| / Lᵢⱼ` in degrees per metre, with Lᵢⱼ the segment's own true path length.
/// KITTI's devkit divides by d, which its 10 Hz poses make the same; poses farther apart
/// overshoot d by up to their spacing, and dividing by d would count that overshoot as error
/// (poses 2 m apart at d = 1 m read a 1 % drift as 2 %). Independent of the alignment. NaN
/// when the drive is shorter than d.
///
/// **Final error**: the ATE error of the last pair, i.e. how far the aligned estimate ends
/// from the truth; `path_length_m` is the true path length over the associated poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AteReport {
    /// Associated pose pairs.
    pub n: usize,
    /// Poses of the shorter trajectory without a partner within `max_dt`.
    pub missing: usize,
    /// Root mean square of the position errors after origin alignment (m).
    pub ate_rmse_m: f64,
    /// Mean position error after origin alignment (m).
    pub ate_mean_m: f64,
    /// Largest position error after origin alignment (m).
    pub ate_max_m: f64,
    /// Position error of the last pair after origin alignment (m).
    pub final_error_m: f64,
    /// Heading error of the last pair after origin alignment (degrees, absolute).
    pub final_heading_error_deg: f64,
    /// True path length over the associated poses (m).
    pub path_length_m: f64,
    /// Segment length of the RPE (m).
    pub rpe_segment_m: f64,
    /// Segments of the RPE (one per start pose that has a complete segment after it).
    pub rpe_segments: usize,
    /// Mean translational RPE per metre driven (m/m).
    pub rpe_trans_per_m: f64,
    /// Mean rotational RPE per metre driven (degrees/m).
    pub rpe_rot_deg_per_m: f64,
}

/// Associates two trajectories like `evo` (see [`AteReport`]): pairs `(estimate, truth)` in
/// time order, and the number of poses of the shorter one left unpaired.
pub fn associate(
    est: &[Stamped],
    truth: &[Stamped],
    max_dt: f64,
) -> Result<(Vec<(Pose2, Pose2)>, usize), EvalError> {
    check_max_dt(max_dt)?;
    let est = time_sorted(est);
    let truth = time_sorted(truth);
    let est_shorter = est.len() < truth.len();
    let (short, long) = if est_shorter {
        (&*est, &*truth)
    } else {
        (&*truth, &*est)
    };
    let mut pairs = Vec::with_capacity(short.len());
    let mut rank = 0usize;
    for (k, (t, p)) in short.iter().enumerate() {
        // The k-th of equal timestamps pairs with the k-th of the other's, where it has as
        // many: a trajectory with repeated times compared with itself pairs each pose with
        // itself.
        rank = if k > 0 && short[k - 1].0 == *t {
            rank + 1
        } else {
            0
        };
        let nearest = nearest_index(long, *t, max_dt).map(|j| {
            if long[j].0 == *t {
                let repeats = long[j..].partition_point(|(s, _)| s <= t);
                j + rank.min(repeats - 1)
            } else {
                j
            }
        });
        match nearest {
            Some(j) if est_shorter => pairs.push((*p, long[j].1)),
            Some(j) => pairs.push((long[j].1, *p)),
            None => {}
        }
    }
    let missing = short.len() - pairs.len();
    Ok((pairs, missing))
}

/// evo's `--align_origin`: the transform `truth₀ · inv(est₀)` that puts an estimate's first
/// pose on the truth's.
#[must_use]
pub fn origin_alignment(est0: &Pose2, truth0: &Pose2) -> Pose2 {
    *truth0 * est0.inverse()
}

/// The estimates of `(estimate, truth)` pairs after [`origin_alignment`] of the first pair.
#[must_use]
pub fn align_origin(pairs: &[(Pose2, Pose2)]) -> Vec<Pose2> {
    let Some((e0, t0)) = pairs.first() else {
        return Vec::new();
    };
    let to_truth = origin_alignment(e0, t0);
    pairs.iter().map(|(e, _)| to_truth * *e).collect()
}

/// Root mean square of the position errors of `(estimate, truth)` pairs after
/// [`align_origin`] (m); NaN for no pairs.
#[must_use]
pub fn ate_rmse(pairs: &[(Pose2, Pose2)]) -> f64 {
    let aligned = align_origin(pairs);
    let sq: f64 = aligned
        .iter()
        .zip(pairs)
        .map(|(e, (_, t))| e.distance(t).powi(2))
        .sum();
    (sq / pairs.len() as f64).sqrt()
}

/// Compares an estimated trajectory with ground truth (see [`AteReport`] for definitions).
pub fn evaluate_ate(
    est: &[Stamped],
    truth: &[Stamped],
    opts: &AteOptions,
) -> Result<AteReport, EvalError> {
    let d = opts.rpe_segment_m;
    if !(d.is_finite() && d > 0.0) {
        return Err(EvalError::BadParameter {
            name: "rpe_segment_m",
            value: d,
            why: "must be finite and positive",
        });
    }
    let (pairs, missing) = associate(est, truth, opts.max_dt)?;
    if pairs.is_empty() {
        return Err(EvalError::NoAssociations {
            max_dt: opts.max_dt,
        });
    }
    let aligned = align_origin(&pairs);
    let errors: Vec<f64> = aligned
        .iter()
        .zip(&pairs)
        .map(|(e, (_, t))| e.distance(t))
        .collect();
    let n = errors.len();
    let ate_rmse_m = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
    let (ate_mean_m, _, ate_max_m) = stats(errors.iter().copied());
    let (last_est, (_, last_truth)) = (aligned[n - 1], pairs[n - 1]);

    // Cumulative true path length s[i] at pair i.
    let mut s = Vec::with_capacity(n);
    let mut acc = 0.0;
    for (k, (_, t)) in pairs.iter().enumerate() {
        if k > 0 {
            acc += pairs[k - 1].1.distance(t);
        }
        s.push(acc);
    }

    // KITTI-style RPE with one segment length d, per metre of each segment's own length.
    let (mut segments, mut trans_sum, mut rot_sum) = (0usize, 0.0, 0.0);
    for i in 0..n {
        let j = s.partition_point(|&sj| sj < s[i] + d);
        if j >= n {
            break; // s is non-decreasing: no later start has a full segment either.
        }
        let (ei, ti) = pairs[i];
        let (ej, tj) = pairs[j];
        let err = ti.between(&tj).inverse() * ei.between(&ej);
        // At least d: the segment ends where its path length reaches d.
        let length = s[j] - s[i];
        trans_sum += err.x.hypot(err.y) / length;
        rot_sum += err.theta.abs().to_degrees() / length;
        segments += 1;
    }
    let per_segment = |sum: f64| {
        if segments == 0 {
            f64::NAN
        } else {
            sum / segments as f64
        }
    };

    Ok(AteReport {
        n,
        missing,
        ate_rmse_m,
        ate_mean_m,
        ate_max_m,
        final_error_m: last_est.distance(&last_truth),
        final_heading_error_deg: normalize_angle(last_est.theta - last_truth.theta)
            .abs()
            .to_degrees(),
        path_length_m: acc,
        rpe_segment_m: d,
        rpe_segments: segments,
        rpe_trans_per_m: per_segment(trans_sum),
        rpe_rot_deg_per_m: per_segment(rot_sum),
    })
}
