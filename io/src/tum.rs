//! TUM trajectories: `timestamp x y z qx qy qz qw`, the convention of the `evo` tool.
//!
//! Planar poses are written with z = 0 and the quaternion of a rotation about z by the
//! heading θ: `qx = qy = 0`, `qz = sin(θ/2)`, `qw = cos(θ/2)`.

use super::{LogError, read_rows8};
use qicp_core::Pose2;
use qicp_core::index::MAX_COORDINATE;
use std::io::{BufRead, Write};
use std::path::Path;

/// A timestamped pose.
pub type Stamped = (f64, Pose2);

/// Writes a trajectory in TUM format, every number in full (round-tripping) precision.
pub fn write_tum<W: Write>(w: W, poses: &[Stamped]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(w);
    for (t, p) in poses {
        write_tum_pose(&mut w, *t, p)?;
    }
    w.flush()
}

/// Writes one pose as a TUM line (unbuffered: give it a buffered writer).
pub fn write_tum_pose<W: Write>(mut w: W, t: f64, p: &Pose2) -> std::io::Result<()> {
    let (qz, qw) = (p.theta / 2.0).sin_cos();
    writeln!(w, "{t} {} {} 0 0 0 {qz} {qw}", p.x, p.y)
}

/// Reads a TUM trajectory (planar poses: z, roll and pitch ignored). Blank lines and lines
/// starting with `#` are skipped; poses are returned in file order.
pub fn read_tum(path: &Path) -> Result<Vec<Stamped>, LogError> {
    let mut reader = super::open_text(path)?;
    read_tum_from(&mut reader, &path.display().to_string())
}

/// Reads a TUM trajectory from any reader; `name` is used in errors.
pub fn read_tum_from<R: BufRead + ?Sized>(
    reader: &mut R,
    name: &str,
) -> Result<Vec<Stamped>, LogError> {
    let mut poses = Vec::new();
    read_rows8(reader, name, "timestamp x y z qx qy qz qw", |line_no, v| {
        let [t, x, y, _z, qx, qy, qz, qw] = v;
        if x.abs() > MAX_COORDINATE || y.abs() > MAX_COORDINATE {
            return Err(LogError::malformed(
                name,
                line_no,
                format!("position ({x}, {y}) lies beyond ±{MAX_COORDINATE} m"),
            ));
        }
        // A rotation's quaternion at any scale: scaled to unit length first (by its largest
        // component, so that 1e200 does not overflow the norm into infinity).
        let m = qx.abs().max(qy.abs()).max(qz.abs()).max(qw.abs());
        if m < 1e-6 {
            return Err(LogError::malformed(name, line_no, "zero quaternion"));
        }
        let [qx, qy, qz, qw] = [qx / m, qy / m, qz / m, qw / m];
        let norm = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        let [qx, qy, qz, qw] = [qx / norm, qy / norm, qz / norm, qw / norm];
        // Yaw of the quaternion (z-y-x Euler angles); for a planar pose 2·atan2(qz, qw).
        let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
        poses.push((t, Pose2::new(x, y, yaw)));
        Ok(())
    })?;
    Ok(poses)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A quaternion of components near 1e200 used to overflow into a NaN heading, and a
    /// position of 1e308 gave an RPE of 3e291 against itself.
    #[test]
    fn quaternions_at_any_scale_give_their_heading_and_far_positions_are_refused() {
        let read = |text: &str| read_tum_from(&mut text.as_bytes(), "t.tum");
        let poses = read("1 0 0 0 0 0 1e200 1e200\n2 0 0 0 0 0 3e-3 0\n").unwrap();
        assert!((poses[0].1.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((poses[1].1.theta.abs() - std::f64::consts::PI).abs() < 1e-12);
        let why = read("1 1e308 1e308 0 0 0 0 1\n").unwrap_err().to_string();
        assert!(why.contains("t.tum:1") && why.contains("beyond"), "{why}");
        let why = read("1 0 0 0 0 0 1e-7 0\n").unwrap_err().to_string();
        assert!(why.contains("zero quaternion"), "{why}");
    }

    #[test]
    fn round_trips_in_full_precision() {
        let poses: Vec<Stamped> = (0..50)
            .map(|i| {
                let f = f64::from(i);
                (
                    1e9 + f * 0.123_456_789,
                    Pose2::new(f.sin() * 7.1, f.cos() / 3.0, f * 0.37),
                )
            })
            .collect();
        let mut out = Vec::new();
        write_tum(&mut out, &poses).unwrap();
        let back = read_tum_from(&mut out.as_slice(), "mem").unwrap();
        assert_eq!(back.len(), poses.len());
        for ((t, p), (tb, pb)) in poses.iter().zip(&back) {
            assert_eq!(t, tb);
            assert_eq!(p.x, pb.x);
            assert_eq!(p.y, pb.y);
            assert!(qicp_core::normalize_angle(p.theta - pb.theta).abs() < 1e-14);
        }
    }

    #[test]
    fn comments_blank_lines_and_errors() {
        let text = "# header\n\n1 2 3 0 0 0 0 1\n  # indented comment\n2 1 1 0 0 0 1 0\n";
        let v = read_tum_from(&mut text.as_bytes(), "t.txt").unwrap();
        assert_eq!(v.len(), 2);
        assert!((v[1].1.theta.abs() - std::f64::consts::PI).abs() < 1e-12);
        let bad = "1 2 3 0 0 0 0 1\n\n2 1 1 0 0 x 1 0\n";
        let e = read_tum_from(&mut bad.as_bytes(), "t.txt").unwrap_err();
        assert!(matches!(e, LogError::Malformed { line: 3, .. }), "{e}");
        let short = "1 2 3 0 0 0 1\n";
        let e = read_tum_from(&mut short.as_bytes(), "t.txt").unwrap_err();
        assert!(e.to_string().contains("t.txt:1"), "{e}");
    }
}
