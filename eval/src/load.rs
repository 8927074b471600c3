//! Trajectories from files: TUM, or the poses of a CARMEN log.

use qicp_io::carmen::{CarmenOptions, read_carmen};
use qicp_io::tum::{Stamped, read_tum};
use qicp_io::{LogError, next_line, open_text, parse_f64, without_bom};
use std::path::Path;

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
/// A file that yields no pose is an error naming what it lacks.
pub fn load_trajectory(path: &Path, poses: LogPoses) -> Result<Vec<Stamped>, LogError> {
    let no_poses = |why: String| LogError::NoPoses {
        path: path.display().to_string(),
        why,
    };
    if is_tum(path)? {
        let trajectory = read_tum(path)?;
        if trajectory.is_empty() {
            return Err(no_poses(
                "holds no poses (TUM: timestamp x y z qx qy qz qw)".into(),
            ));
        }
        return Ok(trajectory);
    }
    let log = read_carmen(path, &CarmenOptions::default())?;
    let trajectory = match poses {
        LogPoses::Odometry => log.laser_odometry(),
        LogPoses::Truth => log.laser_truth(),
    };
    if trajectory.is_empty() {
        return Err(no_poses(match poses {
            LogPoses::Odometry => "holds no laser records, so no odometry at them".into(),
            LogPoses::Truth => format!(
                "no TRUEPOS record lies at any of its {} laser records: the log has no ground \
                 truth",
                log.records.len()
            ),
        }));
    }
    Ok(trajectory)
}

fn is_tum(path: &Path) -> Result<bool, LogError> {
    let mut reader = open_text(path)?;
    let mut buf = Vec::new();
    while next_line(&mut reader, &mut buf).map_err(|e| LogError::Io {
        path: path.display().to_string(),
        cause: e,
    })? {
        let line = String::from_utf8_lossy(&buf);
        let line = without_bom(&line);
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
