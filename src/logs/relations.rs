//! Freiburg SLAM benchmark relations (Kümmerle et al. 2009): `t1 t2 x y z roll pitch yaw`,
//! the robot pose at `t2` expressed in the robot frame at `t1`.

use super::{LogError, next_line, parse_f64};
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
    let mut buf = Vec::new();
    let mut line_no = 0;
    while next_line(reader, &mut buf).map_err(|e| LogError::Io {
        path: name.to_string(),
        source: e,
    })? {
        line_no += 1;
        let line = std::str::from_utf8(&buf)
            .map_err(|_| LogError::malformed(name, line_no, "not UTF-8 text"))?
            .trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut v = [0.0; 8];
        let mut n = 0;
        for tok in line.split_ascii_whitespace() {
            if n == 8 {
                return Err(LogError::malformed(
                    name,
                    line_no,
                    "more than 8 fields (expected `t1 t2 x y z roll pitch yaw`)",
                ));
            }
            v[n] = parse_f64(tok).filter(|x| x.is_finite()).ok_or_else(|| {
                LogError::malformed(name, line_no, format!("not a finite number: `{tok}`"))
            })?;
            n += 1;
        }
        if n != 8 {
            return Err(LogError::malformed(
                name,
                line_no,
                format!("{n} fields, expected 8 (`t1 t2 x y z roll pitch yaw`)"),
            ));
        }
        let [t1, t2, x, y, _z, _roll, _pitch, yaw] = v;
        out.push(Relation {
            t1,
            t2,
            delta: Pose2::new(x, y, yaw),
        });
    }
    Ok(out)
}
