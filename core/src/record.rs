//! One laser record as every source delivers it: simulator, CARMEN log or bridge.

use crate::{Pose2, Scan};

/// A scan with the robot's odometry at the same instant and, where known, its true pose.
///
/// Poses are of the robot; `laser_offset` is the laser's pose in the robot frame (identity for
/// a laser at the robot's origin), so the laser's pose in the world is `robot * laser_offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The sweep; its timestamp is the record's.
    pub scan: Scan,
    /// Robot pose by odometry (drifting) at the scan's time.
    pub odometry: Pose2,
    /// Robot pose by ground truth, where a simulator or a reference provides it.
    pub truth: Option<Pose2>,
    /// Pose of the laser in the robot frame.
    pub laser_offset: Pose2,
}

impl Record {
    /// Time of the record (s).
    #[must_use]
    pub fn timestamp(&self) -> f64 {
        self.scan.timestamp
    }
}
