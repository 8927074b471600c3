//! Freiburg SLAM benchmark relations (Kümmerle et al. 2009): `t1 t2 x y z roll pitch yaw`,
//! the robot pose at `t2` expressed in the robot frame at `t1`.

use super::{LogError, read_rows8};
use qicp_core::Pose2;
use std::io::{BufRead, Write};
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

/// Writes relations as a `.relations` file reads them, one `t1 t2 x y 0 0 0 yaw` line each,
/// every number in its shortest form that reads back to the same value.
pub fn write_relations<W: Write>(w: W, relations: &[Relation]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(w);
    for r in relations {
        let Relation { t1, t2, delta } = r;
        writeln!(w, "{t1} {t2} {} {} 0 0 0 {}", delta.x, delta.y, delta.theta)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What is written reads back bit for bit: a sweep's relations drawn along a run travel
    /// through a file to the runs that are scored with them.
    #[test]
    fn written_relations_read_back_to_the_same_values() {
        let relations: Vec<Relation> = (0..50)
            .map(|k| {
                let k = f64::from(k);
                Relation {
                    t1: 976_052_000.123_456_7 + k * 0.1 / 3.0,
                    t2: 976_052_001.987_654_3 + k / 7.0,
                    delta: Pose2::new((k * 0.37).sin() * 1e-3, -k / 9.0, (k * 1.1).cos() * 0.5),
                }
            })
            .collect();
        let mut bytes = Vec::new();
        write_relations(&mut bytes, &relations).expect("written");
        let back = read_relations_from(&mut bytes.as_slice(), "mem").expect("read");
        assert_eq!(back, relations);
    }
}
