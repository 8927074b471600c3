//! TUM trajectories: `timestamp x y z qx qy qz qw`, the convention of the `evo` tool.
//! (Owned by the log helper; signatures fixed, bodies to come.)

use super::LogError;
use qicp_core::Pose2;
use std::io::Write;
use std::path::Path;

/// A timestamped pose.
pub type Stamped = (f64, Pose2);

/// Writes a trajectory in TUM format.
pub fn write_tum<W: Write>(_w: W, _poses: &[Stamped]) -> std::io::Result<()> {
    Err(std::io::Error::other("writer not implemented yet"))
}

/// Reads a TUM trajectory (planar poses: z, roll and pitch ignored).
pub fn read_tum(path: &Path) -> Result<Vec<Stamped>, LogError> {
    Err(LogError::Malformed {
        path: path.display().to_string(),
        line: 0,
        why: "reader not implemented yet".into(),
    })
}
