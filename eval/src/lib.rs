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

mod ate;
mod load;
mod relations;

pub use ate::{
    AteOptions, AteReport, align_origin, associate, ate_rmse, evaluate_ate, origin_alignment,
};
pub use load::{LogPoses, load_trajectory};
pub mod stats;
pub use relations::{
    RelationError, RelationProbe, RelationsReport, SNAPPED_MAX_DT, evaluate_relations,
    relation_errors,
};
pub(crate) use stats::summary as stats;

use qicp_io::tum::Stamped;
use std::borrow::Cow;
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
pub(crate) fn time_sorted(traj: &[Stamped]) -> Cow<'_, [Stamped]> {
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

pub(crate) fn check_max_dt(max_dt: f64) -> Result<(), EvalError> {
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use qicp_core::Pose2;
    use qicp_io::relations::Relation;

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
            // In time order, and shuffled (a bag's scans come in bag order): the probe picks
            // what scoring the whole trajectory, sorted stably by time, picks.
            let mut shuffled = traj.clone();
            for i in (1..shuffled.len()).rev() {
                shuffled.swap(i, rng.random_range(0..=i));
            }
            let whole = evaluate_relations(&traj, &relations, 0.1).unwrap();
            for order in [&traj, &shuffled] {
                let mut probe = RelationProbe::new(&relations, 0.1).unwrap();
                for (t, p) in order {
                    probe.push(*t, *p).unwrap();
                }
                let whole_of_order = evaluate_relations(order, &relations, 0.1).unwrap();
                let probed = evaluate_relations(&probe.trajectory(), &relations, 0.1).unwrap();
                assert_eq!(
                    format!("{whole_of_order:?}"),
                    format!("{probed:?}"),
                    "round {round}"
                );
                assert!(probe.trajectory().len() <= 2 * relations.len());
            }
            // Shuffling moves only which of the poses at one time is picked.
            assert_eq!(
                whole.n,
                evaluate_relations(&shuffled, &relations, 0.1).unwrap().n
            );
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
    fn a_relation_probe_takes_poses_out_of_time_order_and_refuses_a_nan_time() {
        let relations = [Relation {
            t1: 1.0,
            t2: 2.0,
            delta: Pose2::new(1.0, 0.0, 0.0),
        }];
        let mut probe = RelationProbe::new(&relations, 0.1).unwrap();
        probe.push(2.0, Pose2::new(1.0, 0.0, 0.0)).unwrap();
        probe.push(1.0, Pose2::IDENTITY).unwrap();
        let report = evaluate_relations(&probe.trajectory(), &relations, 0.1).unwrap();
        assert_eq!(report.n, 1);
        assert!(report.trans_max < 1e-12);
        assert!(matches!(
            probe.push(f64::NAN, Pose2::IDENTITY),
            Err(EvalError::OutOfOrder { .. })
        ));
    }

    /// Snapping moves each relation time onto the record the probe matched it to, so that a
    /// run holding only some records is scored on those alone: on a straight drive of a record
    /// every 0.05 s, a perfect run of the even records scores exactly zero on the snapped
    /// relations, where the nearest-pose window of 0.1 s would charge it for the odd records'
    /// neighbours.
    #[test]
    fn snapped_relations_score_a_run_on_the_records_it_has_not_their_neighbours() {
        let records: Vec<Stamped> = (0..40)
            .map(|i| (0.05 * i as f64, Pose2::new(0.02 * i as f64, 0.0, 0.0)))
            .collect();
        // Relations a few milliseconds off the records' times (as another tool may write
        // them), ten records apart; one more far beyond the log.
        let mut relations: Vec<Relation> = (0..30)
            .map(|i| Relation {
                t1: 0.05 * i as f64 + 0.003,
                t2: 0.05 * (i + 10) as f64 - 0.002,
                delta: Pose2::new(0.2, 0.0, 0.0),
            })
            .collect();
        relations.push(Relation {
            t1: 100.0,
            t2: 101.0,
            delta: Pose2::IDENTITY,
        });
        let mut probe = RelationProbe::new(&relations, 0.1).unwrap();
        for (t, p) in &records {
            probe.push(*t, *p).unwrap();
        }
        let snapped = probe.snap(&relations);
        for (i, r) in snapped.iter().take(30).enumerate() {
            assert_eq!((r.t1, r.t2), (records[i].0, records[i + 10].0));
        }
        assert_eq!((snapped[30].t1, snapped[30].t2), (100.0, 101.0));
        // Every second record, estimated perfectly.
        let even: Vec<Stamped> = records.iter().step_by(2).copied().collect();
        let exact = evaluate_relations(&even, &snapped, SNAPPED_MAX_DT).unwrap();
        assert_eq!(exact.n, 15, "relations between two even records");
        assert_eq!(exact.missing, 16);
        assert!(exact.trans_max < 1e-12, "{exact:?}");
        // The wide window pairs an odd record's relation with its neighbour, 2 cm away.
        let near = evaluate_relations(&even, &relations, 0.1).unwrap();
        assert_eq!(near.n, 30);
        assert!(near.trans_mean > 0.01, "{near:?}");
    }

    /// With only the first records scanned, a relation about a later record stays off the
    /// scanned record beside it (within the 0.1 s window), and is missing from the runs.
    #[test]
    fn a_relation_about_a_record_past_those_scanned_is_not_snapped_onto_one() {
        let records: Vec<Stamped> = (0..20)
            .map(|i| (0.05 * i as f64, Pose2::new(0.02 * i as f64, 0.0, 0.0)))
            .collect();
        let relations = [
            Relation {
                t1: 0.0,
                t2: 0.45,
                delta: Pose2::new(0.18, 0.0, 0.0),
            },
            Relation {
                t1: 0.0,
                t2: 0.5,
                delta: Pose2::new(0.2, 0.0, 0.0),
            },
        ];
        let (mut scanned, mut all) = (
            RelationProbe::new(&relations, 0.1).unwrap(),
            RelationProbe::new(&relations, 0.1).unwrap(),
        );
        for (k, (t, p)) in records.iter().enumerate() {
            if k < 10 {
                scanned.push(*t, *p).unwrap();
            }
            all.push(*t, *p).unwrap();
        }
        let snapped = scanned.snap_within(&relations, &all);
        // Record 10 (0.5 s) was not scanned; record 9 (0.45 s) lies within 0.1 s of it.
        assert_eq!(snapped[0].t2, 0.45);
        assert_eq!(snapped[1].t2, 0.5);
        let run: Vec<Stamped> = records[..10].to_vec();
        let report = evaluate_relations(&run, &snapped, SNAPPED_MAX_DT).unwrap();
        assert_eq!((report.n, report.missing), (1, 1));
        // Snapping against itself would have taken it onto record 9.
        assert_eq!(scanned.snap(&relations)[1].t2, 0.45);
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

    /// `n` poses `step` m apart along x, and an estimate that reads every step 1 % long.
    fn one_percent_long(step: f64, n: i32) -> (Vec<Stamped>, Vec<Stamped>) {
        let truth: Vec<Stamped> = (0..n)
            .map(|i| (f64::from(i), Pose2::new(step * f64::from(i), 0.0, 0.0)))
            .collect();
        let est = truth
            .iter()
            .map(|(t, p)| (*t, Pose2::new(p.x * 1.01, 0.0, 0.0)))
            .collect();
        (truth, est)
    }

    #[test]
    fn rpe_measures_drift_per_metre() {
        // Odometry that reads every 6.25 cm step 1 % long: 1 cm of error per metre.
        let (truth, est) = one_percent_long(0.0625, 400);
        let r = evaluate_ate(&est, &truth, &AteOptions::default()).unwrap();
        assert!((r.rpe_trans_per_m - 0.01).abs() < 1e-9, "{r:?}");
        assert!((r.final_error_m - 0.01 * 0.0625 * 399.0).abs() < 1e-9);
        assert_eq!(r.rpe_segments, 400 - 16);
    }

    #[test]
    fn rpe_per_metre_divides_by_the_length_each_segment_covers() {
        // The same 1 % drift with poses 2 m and 0.3 m apart: every segment of 1 m overshoots
        // (to 2 m, and to 1.2 m), and divided by the nominal metre the drift read 2 % and
        // 1.2 %.
        for step in [2.0, 0.3] {
            let (truth, est) = one_percent_long(step, 60);
            let r = evaluate_ate(&est, &truth, &AteOptions::default()).unwrap();
            assert!((r.rpe_trans_per_m - 0.01).abs() < 1e-9, "{step}: {r:?}");
        }
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
