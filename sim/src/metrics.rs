//! Scores of a simulated drive against its ground truth (DESIGN.md, "Simulation ground truth").

use qicp_core::{BeamStatus, Pose2, Record};

/// How far odometry strays from the truth, and what the laser saw.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveScores {
    /// Records scored.
    pub scans: usize,
    /// Length of the true path through the record poses (m).
    pub path_length_m: f64,
    /// Distance between the last odometry and the last true position (m).
    pub odometry_final_error_m: f64,
    /// Absolute trajectory error of odometry: RMSE of positions after the start poses
    /// coincide (m).
    pub odometry_ate_m: f64,
    /// Distance between the true start and end positions (m).
    pub loop_gap_m: f64,
    /// Share of all beams that hit something within range.
    pub returns_fraction: f64,
}

impl DriveScores {
    /// Scores records that carry ground truth; records without truth are skipped.
    #[must_use]
    pub fn of(records: &[Record]) -> Self {
        let pairs: Vec<(Pose2, Pose2)> = records
            .iter()
            .filter_map(|r| r.truth.map(|t| (t, r.odometry)))
            .collect();
        let mut s = DriveScores {
            scans: records.len(),
            ..DriveScores::default()
        };
        let beams: usize = records.iter().map(|r| r.scan.beams()).sum();
        let valid: usize = records
            .iter()
            .map(|r| {
                r.scan
                    .status()
                    .iter()
                    .filter(|b| **b == BeamStatus::Valid)
                    .count()
            })
            .sum();
        if beams > 0 {
            s.returns_fraction = valid as f64 / beams as f64;
        }
        let (Some(first), Some(last)) = (pairs.first(), pairs.last()) else {
            return s;
        };
        s.path_length_m = pairs.windows(2).map(|w| w[0].0.distance(&w[1].0)).sum();
        s.loop_gap_m = first.0.distance(&last.0);
        // Odometry's start brought onto the truth's start, as `qicp eval ate` does.
        let estimated: Vec<(Pose2, Pose2)> = pairs.iter().map(|(t, o)| (*o, *t)).collect();
        s.odometry_ate_m = qicp_eval::ate_rmse(&estimated);
        let aligned = qicp_eval::align_origin(&estimated);
        s.odometry_final_error_m = aligned.last().map_or(f64::NAN, |o| last.0.distance(o));
        s
    }
}
