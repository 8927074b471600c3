//! Freiburg SLAM benchmark relations (Kümmerle et al. 2009): `t1 t2 x y z roll pitch yaw`,
//! the robot pose at `t2` expressed in the robot frame at `t1`.

use super::{LogError, read_rows8};
use qicp_core::Pose2;
use std::io::BufRead;
use std::path::Path;

/// One relation: `delta` is `inv(P(t1)) · P(t2)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relation {
    /// Time of the first pose (s).
    pub t1: f64,
    /// Time of the second pose (s).
    pub t2: f64,
    /// The second pose seen from the first (z, roll and pitch, always 0 in 2D, dropped).
    pub delta: Pose2,
}

/// Reads a `.relations` file (blank lines and `#` comments skipped).
pub fn read_relations(path: &Path) -> Result<Vec<Relation>, LogError> {
    let mut reader = super::open_text(path)?;
    read_relations_from(&mut reader, &path.display().to_string())
}

/// Reads relations from any reader; `name` is used in errors.
pub fn read_relations_from<R: BufRead + ?Sized>(
    reader: &mut R,
    name: &str,
) -> Result<Vec<Relation>, LogError> {
    let mut out = Vec::new();
    read_rows8(reader, name, "t1 t2 x y z roll pitch yaw", |_, v| {
        let [t1, t2, x, y, _z, _roll, _pitch, yaw] = v;
        out.push(Relation {
            t1,
            t2,
            delta: Pose2::new(x, y, yaw),
        });
        Ok(())
    })?;
    Ok(out)
}
