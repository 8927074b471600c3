//! # qicp-eval
//!
//! Trajectory metrics, returning typed reports that serialise:
//!
//! - [`evaluate_relations`]: the Freiburg SLAM benchmark metric (Kümmerle et al., "On
//!   measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009) for real logs
//!   without ground truth.
//! - [`evaluate_ate`]: absolute trajectory error after the start poses coincide (the same
//!   number as `evo_ape tum truth est --align_origin`), relative error per metre driven and
//!   final position error, for simulated drives with ground truth.
//!
//! Trajectories are `(timestamp, robot pose)` slices; they need not be sorted.

#![warn(missing_docs)]

use qicp_core::{Pose2, normalize_angle};
use qicp_io::carmen::{CarmenOptions, read_carmen};
use qicp_io::relations::Relation;
use qicp_io::tum::{Stamped, read_tum};
use qicp_io::{LogError, next_line, open_text, parse_f64};
use serde::Serialize;
use std::borrow::Cow;
use std::path::Path;
use thiserror::Error;

/// How far (s) an estimated pose may lie from a requested time and still stand for it.
pub const DEFAULT_MAX_DT: f64 = 0.1;
/// Segment length (m) of the relative pose error.
pub const DEFAULT_RPE_SEGMENT_M: f64 = 1.0;

/// Why a trajectory could not be evaluated.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EvalError {
    /// No pose of one trajectory has a partner in the other within `max_dt`.
    #[error("no pose pairs within {max_dt} s: do the trajectories share a time base?")]
    NoAssociations {
        /// The association window (s).
        max_dt: f64,
    },
    /// A streamed trajectory went back in time.
    #[error("pose at {t} s comes after one at {previous} s: the trajectory must be in time order")]
    OutOfOrder {
        /// The pose's time (s).
        t: f64,
        /// The previous pose's time (s).
        previous: f64,
    },
    /// A parameter is not usable.
    #[error("`{name}` is {value}: {why}")]
    BadParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong with it.
        why: &'static str,
    },
}

// ---------------------------------------------------------------------------------------------
// Association

/// The trajectory in time order (borrowed when it already is).
fn time_sorted(traj: &[Stamped]) -> Cow<'_, [Stamped]> {
    if traj.windows(2).all(|w| w[0].0 <= w[1].0) {
        Cow::Borrowed(traj)
    } else {
        let mut v = traj.to_vec();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        Cow::Owned(v)
    }
}

/// Index of the pose of `sorted` nearest in time to `t`, if within `max_dt` (binary search).
#[must_use]
pub fn nearest_index(sorted: &[Stamped], t: f64, max_dt: f64) -> Option<usize> {
    let i = sorted.partition_point(|(s, _)| *s < t);
    let best = match (i.checked_sub(1), (i < sorted.len()).then_some(i)) {
        (Some(b), Some(a)) => {
            if t - sorted[b].0 <= sorted[a].0 - t {
                b
            } else {
                a
            }
        }
        (Some(b), None) => b,
        (None, Some(a)) => a,
        (None, None) => return None,
    };
    ((sorted[best].0 - t).abs() <= max_dt).then_some(best)
}

fn check_max_dt(max_dt: f64) -> Result<(), EvalError> {
    if max_dt.is_finite() && max_dt >= 0.0 {
        Ok(())
    } else {
        Err(EvalError::BadParameter {
            name: "max_dt",
            value: max_dt,
            why: "must be finite and non-negative",
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Freiburg relations

/// The error of one relation: estimated `inv(P1)·P2` minus the relation, component-wise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RelationError {
    /// Time of the first pose (s).
    pub t1: f64,
    /// Time of the second pose (s).
    pub t2: f64,
    /// x error (m).
    pub dx: f64,
    /// y error (m).
    pub dy: f64,
    /// Heading error, normalised (rad).
    pub dyaw: f64,
}

impl RelationError {
    /// Translational error `sqrt(dx² + dy²)` (m).
    #[must_use]
    pub fn trans(&self) -> f64 {
        self.dx.hypot(self.dy)
    }

    /// Rotational error `|dyaw|` (rad).
    #[must_use]
    pub fn rot(&self) -> f64 {
        self.dyaw.abs()
    }
}

/// The Freiburg benchmark summary of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RelationsReport {
    /// Relations evaluated.
    pub n: usize,
    /// Relations skipped because the trajectory has no pose within `max_dt` of `t1` or `t2`.
    pub missing: usize,
    /// Mean translational error (m).
    pub trans_mean: f64,
    /// Standard deviation of the translational error (m; population, divided by n).
    pub trans_std: f64,
    /// Largest translational error (m).
    pub trans_max: f64,
    /// Mean rotational error (degrees).
    pub rot_mean_deg: f64,
    /// Standard deviation of the rotational error (degrees; population).
    pub rot_std_deg: f64,
    /// Largest rotational error (degrees).
    pub rot_max_deg: f64,
}

/// Mean, population standard deviation and maximum; NaN for no values.
fn stats(v: impl Iterator<Item = f64> + Clone) -> (f64, f64, f64) {
    let (mut n, mut sum, mut max) = (0usize, 0.0, f64::NAN);
    for x in v.clone() {
        n += 1;
        sum += x;
        max = x.max(max);
    }
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mean = sum / n as f64;
    let var = v.map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64;
    (mean, var.sqrt(), max)
}

/// The error of every relation whose two poses the trajectory has (nearest in time, within
/// `max_dt`), and the number of relations it has not.
pub fn relation_errors(
    traj: &[Stamped],
    relations: &[Relation],
    max_dt: f64,
) -> Result<(Vec<RelationError>, usize), EvalError> {
    check_max_dt(max_dt)?;
    let traj = time_sorted(traj);
    let mut errors = Vec::with_capacity(relations.len());
    let mut missing = 0;
    for r in relations {
        let (Some(i), Some(j)) = (
            nearest_index(&traj, r.t1, max_dt),
            nearest_index(&traj, r.t2, max_dt),
        ) else {
            missing += 1;
            continue;
        };
        // Kümmerle et al. 2009: ε(δ) = δ_est ⊖ δ*, here component-wise.
        let est = traj[i].1.between(&traj[j].1);
        errors.push(RelationError {
            t1: r.t1,
            t2: r.t2,
            dx: est.x - r.delta.x,
            dy: est.y - r.delta.y,
            dyaw: normalize_angle(est.theta - r.delta.theta),
        });
    }
    Ok((errors, missing))
}

/// Picks from a trajectory streamed in time order the poses that relations need, so that a
/// long run is scored in memory that grows with the relations, not with the poses.
///
/// [`RelationProbe::trajectory`] holds, for every relation time, the pose
/// [`nearest_index`] would pick from the whole trajectory (the same tie rule), so
/// [`evaluate_relations`] on it gives the figures of the whole trajectory.
#[derive(Debug, Clone)]
pub struct RelationProbe {
    /// Relation times, sorted, without repeats.
    times: Vec<f64>,
    /// Best pose so far for each time.
    best: Vec<Option<Stamped>>,
    /// First time a later pose can still improve.
    lo: usize,
    max_dt: f64,
    last: f64,
}

impl RelationProbe {
    /// A probe for `relations`, taking poses within `max_dt` of their times.
    pub fn new(relations: &[Relation], max_dt: f64) -> Result<Self, EvalError> {
        check_max_dt(max_dt)?;
        let mut times: Vec<f64> = relations.iter().flat_map(|r| [r.t1, r.t2]).collect();
        times.sort_by(f64::total_cmp);
        times.dedup();
        Ok(Self {
            best: vec![None; times.len()],
            times,
            lo: 0,
            max_dt,
            last: f64::NEG_INFINITY,
        })
    }

    /// Offers the next pose of the trajectory; poses must come in time order.
    pub fn push(&mut self, t: f64, pose: Pose2) -> Result<(), EvalError> {
        if t < self.last || t.is_nan() {
            return Err(EvalError::OutOfOrder {
                t,
                previous: self.last,
            });
        }
        self.last = t;
        while self.lo < self.times.len() && self.times[self.lo] < t - self.max_dt {
            self.lo += 1;
        }
        for i in self.lo..self.times.len() {
            let want = self.times[i];
            if want > t + self.max_dt {
                break;
            }
            let d = (t - want).abs();
            let better = match self.best[i] {
                None => true,
                // As `nearest_index`: the last pose before `want` wins a tie with one after.
                Some((s, _)) => {
                    let held = (s - want).abs();
                    if t < want { d <= held } else { d < held }
                }
            };
            if better {
                self.best[i] = Some((t, pose));
            }
        }
        Ok(())
    }

    /// The poses picked, in time order.
    #[must_use]
    pub fn trajectory(&self) -> Vec<Stamped> {
        let mut picked: Vec<Stamped> = self.best.iter().flatten().copied().collect();
        picked.dedup_by(|a, b| a.0 == b.0 && a.1 == b.1);
        picked
    }
}

/// Scores a trajectory with benchmark relations: mean, standard deviation and maximum of the
/// translational and rotational errors. With no relation evaluated the statistics are NaN.
pub fn evaluate_relations(
    traj: &[Stamped],
    relations: &[Relation],
    max_dt: f64,
) -> Result<RelationsReport, EvalError> {
    let (errors, missing) = relation_errors(traj, relations, max_dt)?;
    let (trans_mean, trans_std, trans_max) = stats(errors.iter().map(RelationError::trans));
    let (rot_mean, rot_std, rot_max) = stats(errors.iter().map(RelationError::rot));
    Ok(RelationsReport {
        n: errors.len(),
        missing,
        trans_mean,
        trans_std,
        trans_max,
        rot_mean_deg: rot_mean.to_degrees(),
        rot_std_deg: rot_std.to_degrees(),
        rot_max_deg: rot_max.to_degrees(),
    })
}

// ---------------------------------------------------------------------------------------------
// Ground truth: ATE, RPE, final error

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
/// of `|translation(E)| / d` (m per m; ×100 for %) and `rpe_rot_deg_per_m` the mean of
/// `|angle(E)| / d` in degrees per metre. Independent of the alignment. NaN when the drive is
/// shorter than d.
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

    // KITTI-style RPE with one segment length d.
    let (mut segments, mut trans_sum, mut rot_sum) = (0usize, 0.0, 0.0);
    for i in 0..n {
        let j = s.partition_point(|&sj| sj < s[i] + d);
        if j >= n {
            break; // s is non-decreasing: no later start has a full segment either.
        }
        let (ei, ti) = pairs[i];
        let (ej, tj) = pairs[j];
        let err = ti.between(&tj).inverse() * ei.between(&ej);
        trans_sum += err.x.hypot(err.y) / d;
        rot_sum += err.theta.abs().to_degrees() / d;
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

// ---------------------------------------------------------------------------------------------
// Loading trajectories

/// Which poses of a CARMEN log stand for its trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogPoses {
    /// The odometry of the laser records.
    Odometry,
    /// The ground truth (`TRUEPOS`) attached to the laser records.
    Truth,
}

/// Reads a trajectory from a TUM file or a CARMEN log (plain or bzip2), told apart by their
/// first record: a number opens a TUM line, a word a CARMEN record. From a CARMEN log it takes
/// the laser records' poses named by `poses`.
pub fn load_trajectory(path: &Path, poses: LogPoses) -> Result<Vec<Stamped>, LogError> {
    if is_tum(path)? {
        return read_tum(path);
    }
    let log = read_carmen(path, &CarmenOptions::default())?;
    Ok(match poses {
        LogPoses::Odometry => log.laser_odometry(),
        LogPoses::Truth => log.laser_truth(),
    })
}

fn is_tum(path: &Path) -> Result<bool, LogError> {
    let mut reader = open_text(path)?;
    let mut buf = Vec::new();
    while next_line(&mut reader, &mut buf).map_err(|e| LogError::Io {
        path: path.display().to_string(),
        source: e,
    })? {
        let line = String::from_utf8_lossy(&buf);
        let Some(first) = line.split_ascii_whitespace().next() else {
            continue;
        };
        if first.starts_with('#') {
            continue;
        }
        return Ok(parse_f64(first).is_some());
    }
    Ok(true)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The probe is the streaming twin of scoring the whole trajectory: on seeded random
    /// trajectories (with repeated timestamps and exact ties) and relations, the figures agree.
    #[test]
    fn relation_probe_scores_like_the_whole_trajectory() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for round in 0..50 {
            let n = rng.random_range(1..300);
            let mut t = 0.0;
            let traj: Vec<Stamped> = (0..n)
                .map(|_| {
                    // Steps of 0, 0.05 or 0.1 s: repeats and ties at half steps.
                    t += 0.05 * rng.random_range(0..3) as f64;
                    let pose = Pose2::new(rng.random(), rng.random(), rng.random());
                    (t, pose)
                })
                .collect();
            let relations: Vec<Relation> = (0..rng.random_range(1..40))
                .map(|_| {
                    let at = |rng: &mut rand_chacha::ChaCha8Rng| {
                        (rng.random_range(-0.5..t + 0.5) * 40.0).round() / 40.0
                    };
                    Relation {
                        t1: at(&mut rng),
                        t2: at(&mut rng),
                        delta: Pose2::new(0.1, 0.0, 0.01),
                    }
                })
                .collect();
            let mut probe = RelationProbe::new(&relations, 0.1).unwrap();
            for (t, p) in &traj {
                probe.push(*t, *p).unwrap();
            }
            let whole = evaluate_relations(&traj, &relations, 0.1).unwrap();
            let probed = evaluate_relations(&probe.trajectory(), &relations, 0.1).unwrap();
            assert_eq!(format!("{whole:?}"), format!("{probed:?}"), "round {round}");
            assert!(probe.trajectory().len() <= 2 * relations.len());
        }
    }

    #[test]
    fn ate_of_a_trajectory_with_repeated_times_against_itself_is_zero() {
        let traj: Vec<Stamped> = (0..40)
            .map(|i| {
                (
                    (i / 4) as f64,
                    Pose2::new(i as f64, (i % 3) as f64, 0.1 * i as f64),
                )
            })
            .collect();
        let report = evaluate_ate(&traj, &traj, &AteOptions::default()).unwrap();
        assert_eq!(report.ate_max_m, 0.0);
        assert_eq!(report.missing, 0);
    }

    #[test]
    fn relation_probe_refuses_poses_out_of_time_order() {
        let mut probe = RelationProbe::new(&[], 0.1).unwrap();
        probe.push(2.0, Pose2::IDENTITY).unwrap();
        assert!(matches!(
            probe.push(1.0, Pose2::IDENTITY),
            Err(EvalError::OutOfOrder { .. })
        ));
    }

    /// A drive along a gently curving path, one pose every 0.1 s.
    fn drive(n: usize) -> Vec<Stamped> {
        let mut p = Pose2::IDENTITY;
        (0..n)
            .map(|i| {
                let t = 100.0 + i as f64 * 0.1;
                let out = (t, p);
                p = p * Pose2::new(0.05, 0.0, 0.02 * ((i as f64) * 0.05).sin());
                out
            })
            .collect()
    }

    fn relations_of(traj: &[Stamped], step: usize) -> Vec<Relation> {
        (0..traj.len() - step)
            .step_by(3)
            .map(|i| Relation {
                t1: traj[i].0,
                t2: traj[i + step].0,
                delta: traj[i].1.between(&traj[i + step].1),
            })
            .collect()
    }

    #[test]
    fn exact_trajectory_scores_zero() {
        let traj = drive(200);
        let rels = relations_of(&traj, 10);
        let r = evaluate_relations(&traj, &rels, DEFAULT_MAX_DT).unwrap();
        assert_eq!(r.n, rels.len());
        assert_eq!(r.missing, 0);
        assert!(r.trans_max < 1e-12 && r.rot_max_deg < 1e-9, "{r:?}");
    }

    #[test]
    fn known_perturbation_is_measured() {
        let traj = drive(200);
        let rels = relations_of(&traj, 1);
        // Every estimated step is 0.01 m too long and turns 0.5° too far: each relation of
        // one step then errs by the perturbation seen in the first pose's frame.
        let bias = Pose2::new(0.01, 0.0, 0.5f64.to_radians());
        let mut est = vec![traj[0]];
        for w in traj.windows(2) {
            let step = w[0].1.between(&w[1].1);
            let last = est.last().unwrap().1;
            est.push((w[1].0, last * step * bias));
        }
        let r = evaluate_relations(&est, &rels, DEFAULT_MAX_DT).unwrap();
        assert_eq!(r.n, rels.len());
        // inv(P1)·P2 = step·bias, whose heading exceeds the step's by the bias.
        assert!((r.rot_mean_deg - 0.5).abs() < 1e-9, "{r:?}");
        assert!(r.rot_std_deg < 1e-9);
        // Translation error: |step·bias − step| = |R(step)·(0.01, 0)| = 0.01 m.
        assert!((r.trans_mean - 0.01).abs() < 1e-9, "{r:?}");
        assert!(r.trans_std < 1e-9);
    }

    #[test]
    fn poses_are_taken_nearest_in_time_and_missing_ones_counted() {
        let traj = drive(100);
        let mut rels = relations_of(&traj, 5);
        let n = rels.len();
        // Shifted by 0.03 s: the nearest pose is still the right one.
        for r in &mut rels {
            r.t1 += 0.03;
            r.t2 -= 0.03;
        }
        rels.push(Relation {
            t1: 0.0,
            t2: 100.0,
            delta: Pose2::IDENTITY,
        });
        rels.push(Relation {
            t1: 100.0,
            t2: 1e6,
            delta: Pose2::IDENTITY,
        });
        // Unsorted trajectories are sorted first.
        let mut shuffled = traj.clone();
        shuffled.reverse();
        let r = evaluate_relations(&shuffled, &rels, DEFAULT_MAX_DT).unwrap();
        assert_eq!((r.n, r.missing), (n, 2));
        assert!(r.trans_max < 1e-12);
        let none = evaluate_relations(&traj, &rels[n..], DEFAULT_MAX_DT).unwrap();
        assert_eq!((none.n, none.missing), (0, 2));
        assert!(none.trans_mean.is_nan());
        assert!(evaluate_relations(&traj, &rels, -1.0).is_err());
    }

    #[test]
    fn rigidly_moved_copy_has_zero_ate() {
        let truth = drive(300);
        let moved = Pose2::new(12.0, -3.0, 2.0);
        let est: Vec<Stamped> = truth.iter().map(|(t, p)| (*t, moved * *p)).collect();
        let r = evaluate_ate(&est, &truth, &AteOptions::default()).unwrap();
        assert_eq!((r.n, r.missing), (300, 0));
        assert!(r.ate_rmse_m < 1e-9 && r.final_error_m < 1e-9, "{r:?}");
        assert!(r.rpe_trans_per_m < 1e-9 && r.rpe_rot_deg_per_m < 1e-9);
        assert!((r.path_length_m - 299.0 * 0.05).abs() < 1e-9);
        // 15 m of path, segments of 1 m (20 steps): every start up to the last metre.
        assert!((279..=280).contains(&r.rpe_segments), "{}", r.rpe_segments);
    }

    #[test]
    fn constant_offset_after_the_start_is_the_ate() {
        // The estimate agrees at the start, then sits 0.2 m to the side of the truth.
        let truth = drive(50);
        let mut est = truth.clone();
        for (_, p) in est.iter_mut().skip(1) {
            *p = *p * Pose2::new(0.0, 0.2, 0.0);
        }
        let r = evaluate_ate(&est, &truth, &AteOptions::default()).unwrap();
        let expect = (0.04f64 * 49.0 / 50.0).sqrt();
        assert!((r.ate_rmse_m - expect).abs() < 1e-12, "{r:?}");
        assert!((r.ate_max_m - 0.2).abs() < 1e-12);
        assert!((r.final_error_m - 0.2).abs() < 1e-12);
    }

    #[test]
    fn rpe_measures_drift_per_metre() {
        // Odometry that reads every 6.25 cm step 1 % long: 1 cm of error per metre.
        let truth: Vec<Stamped> = (0..400)
            .map(|i| (f64::from(i), Pose2::new(0.0625 * f64::from(i), 0.0, 0.0)))
            .collect();
        let est: Vec<Stamped> = truth
            .iter()
            .map(|(t, p)| (*t, Pose2::new(p.x * 1.01, 0.0, 0.0)))
            .collect();
        let r = evaluate_ate(&est, &truth, &AteOptions::default()).unwrap();
        assert!((r.rpe_trans_per_m - 0.01).abs() < 1e-9, "{r:?}");
        assert!((r.final_error_m - 0.01 * 0.0625 * 399.0).abs() < 1e-9);
        assert_eq!(r.rpe_segments, 400 - 16);
    }

    #[test]
    fn association_pairs_the_shorter_trajectory() {
        let truth = drive(100); // 10 Hz
        let est: Vec<Stamped> = truth
            .iter()
            .step_by(5)
            .map(|x| (x.0 + 0.004, x.1))
            .collect();
        let (pairs, missing) = associate(&est, &truth, 0.01).unwrap();
        assert_eq!((pairs.len(), missing), (20, 0));
        let far: Vec<Stamped> = truth.iter().map(|x| (x.0 + 50.0, x.1)).collect();
        assert_eq!(
            evaluate_ate(&far, &truth, &AteOptions::default()),
            Err(EvalError::NoAssociations { max_dt: 0.1 })
        );
    }
}
