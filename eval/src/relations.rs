//! The Freiburg SLAM benchmark metric (Kümmerle et al. 2009): relations between poses of
//! the trajectory, scored whole or as the poses stream past ([`RelationProbe`]).

use crate::{EvalError, check_max_dt, nearest_index, stats, time_sorted};
use qicp_core::{Pose2, normalize_angle};
use qicp_io::relations::Relation;
use qicp_io::tum::Stamped;
use serde::Serialize;

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

/// Association window (s) of relations whose times are records' own ([`RelationProbe::snap`]):
/// wide enough for a time written to a file and read back, far narrower than any laser's
/// record spacing.
pub const SNAPPED_MAX_DT: f64 = 1e-6;

/// Picks from a streamed trajectory the poses that relations need, so that a long run is
/// scored in memory that grows with the relations, not with the poses.
///
/// [`RelationProbe::trajectory`] holds, for every relation time, the pose [`nearest_index`]
/// would pick from the whole trajectory sorted by time (a stable sort, so poses of one time
/// keep their order; the same tie rule), so [`evaluate_relations`] on it gives the figures of
/// the whole trajectory. Poses may come in any order: a ROS 2 bag's scans come in bag order,
/// which is not always time order.
#[derive(Debug, Clone)]
pub struct RelationProbe {
    /// Relation times, sorted, without repeats.
    times: Vec<f64>,
    /// Best pose so far for each time.
    best: Vec<Option<Stamped>>,
    /// The number of the push that gave each best pose (counted from 0).
    pushed_as: Vec<usize>,
    /// Poses offered so far.
    pushed: usize,
    max_dt: f64,
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
            pushed_as: vec![0; times.len()],
            pushed: 0,
            times,
            max_dt,
        })
    }

    /// Offers the next pose of the trajectory. A NaN time is refused.
    pub fn push(&mut self, t: f64, pose: Pose2) -> Result<(), EvalError> {
        if t.is_nan() {
            return Err(EvalError::OutOfOrder {
                t,
                previous: f64::NAN,
            });
        }
        let first = self.times.partition_point(|&w| w < t - self.max_dt);
        for i in first..self.times.len() {
            let want = self.times[i];
            if want > t + self.max_dt {
                break;
            }
            let d = (t - want).abs();
            let better = match self.best[i] {
                None => true,
                // As `nearest_index` on the stably sorted trajectory: the nearer pose wins; of
                // two as near, one before `want` beats one after it, and of two at one time
                // the later beats the earlier before `want`, not from `want` on.
                Some((s, _)) => {
                    let held = (s - want).abs();
                    d < held || (d == held && t < want)
                }
            };
            if better {
                self.best[i] = Some((t, pose));
                self.pushed_as[i] = self.pushed;
            }
        }
        self.pushed += 1;
        Ok(())
    }

    /// Moves the poses held: the pose the `k`-th push gave (counted from 0) is moved on the
    /// left (in the world) by `moved(k)`, where it gives one. For a trajectory corrected
    /// after the fact (a matcher's re-anchoring spread over the records before it).
    pub fn amend(&mut self, moved: impl Fn(usize) -> Option<Pose2>) {
        for (best, &k) in self.best.iter_mut().zip(&self.pushed_as) {
            if let Some((_, pose)) = best
                && let Some(by) = moved(k)
            {
                *pose = by * *pose;
            }
        }
    }

    /// Whether every relation time lies more than the probe's `max_dt` before `t`: a
    /// trajectory that starts at `t` can score none of them (relations of another log).
    #[must_use]
    pub fn all_before(&self, t: f64) -> bool {
        self.times.last().is_none_or(|&last| last < t - self.max_dt)
    }

    /// `relations` with each time moved to the time of the pose picked for it, where one was:
    /// fed the log's records, the record each relation is about. A run that matched only some
    /// records (every second one, say) is then scored on the records it has, within a window
    /// narrower than their spacing ([`SNAPPED_MAX_DT`]), never with a neighbour's pose as if it
    /// were taken at the relation's time. A time with no pose is kept as it is. Records that
    /// share one timestamp cannot be told apart: of those the probe keeps one, by its tie
    /// rule.
    #[must_use]
    pub fn snap(&self, relations: &[Relation]) -> Vec<Relation> {
        self.snap_within(relations, self)
    }

    /// [`snap`](Self::snap) for a probe fed only some of the log's records (the first N):
    /// a time moves only where `all`, the probe of the same relations fed every record, picked
    /// the same record. A relation about a record this probe was not fed is left at its time,
    /// not moved onto a fed record beside it.
    #[must_use]
    pub fn snap_within(&self, relations: &[Relation], all: &RelationProbe) -> Vec<Relation> {
        let at = |t: f64| {
            let i = self.times.binary_search_by(|w| w.total_cmp(&t)).ok();
            let picked = i.and_then(|i| self.best[i]);
            let overall = i.and_then(|i| all.best.get(i).copied().flatten());
            match (picked, overall) {
                (Some((s, _)), Some((o, _))) if s == o => s,
                _ => t,
            }
        };
        relations
            .iter()
            .map(|r| Relation {
                t1: at(r.t1),
                t2: at(r.t2),
                ..*r
            })
            .collect()
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
