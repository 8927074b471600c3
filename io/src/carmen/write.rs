//! Writing records as a CARMEN log (`FLASER` where the layout allows, `ROBOTLASER1` else).

use super::{DEFAULT_FLASER_FOV_DEG, DEFAULT_FLASER_MAX_RANGE, flaser_geometry};
use qicp_core::{Pose2, Record, Scan};
use std::io::Write;

/// Hostname written into every timed record.
const HOSTNAME: &str = "qicp";

/// How close (rad) a scan's beam layout must be to the `FLASER` layout to be written as
/// `FLASER`; the CARMEN text stores the fov in degrees, so the layout read back may differ by
/// a rounding error.
const LAYOUT_TOLERANCE: f64 = 1e-12;

/// The `FLASER` layout a scan fits, if any: `(fov_deg, max_range)`.
fn flaser_fit(scan: &Scan) -> Option<(f64, f64)> {
    let g = scan.geometry;
    let fov = -2.0 * g.angle_min;
    if fov.is_nan() || fov <= 0.0 {
        return None;
    }
    let fov_deg = fov.to_degrees();
    let back = flaser_geometry(scan.beams(), fov_deg.to_radians(), g.max_range, g.min_range);
    let fits = (back.angle_min - g.angle_min).abs() <= LAYOUT_TOLERANCE
        && (back.angle_increment - g.angle_increment).abs() <= LAYOUT_TOLERANCE;
    fits.then_some((fov_deg, g.max_range))
}

/// Writes records as a CARMEN log.
///
/// The header's `PARAM`s describe the `FLASER` layout of the first record that has one (field
/// of view, maximum range, laser offset); every record of that layout is written as an `ODOM`
/// line and a `FLASER` line, every other one (off-centre or uneven beams, another range or
/// laser offset) as an `ODOM` line and a `ROBOTLASER1` line, which carries its own geometry.
/// A `TRUEPOS` line follows when the record has a ground truth. Numbers are written in full
/// (shortest round-tripping) precision. CARMEN has no field for a minimum range: it is not
/// written (set [`CarmenOptions::min_range`](super::CarmenOptions::min_range) when reading back).
pub fn write_carmen<W: Write>(w: W, records: &[Record]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(w);
    let header = records.iter().find_map(|r| {
        flaser_fit(&r.scan).map(|(fov_deg, max_range)| (fov_deg, max_range, r.laser_offset))
    });
    let (fov_deg, max_range, offset) = header.unwrap_or((
        DEFAULT_FLASER_FOV_DEG,
        DEFAULT_FLASER_MAX_RANGE,
        Pose2::IDENTITY,
    ));
    writeln!(w, "# CARMEN log written by qicp")?;
    writeln!(
        w,
        "# message_name [message contents] ipc_timestamp ipc_hostname logger_timestamp"
    )?;
    writeln!(
        w,
        "# message formats defined: PARAM ODOM FLASER ROBOTLASER1 TRUEPOS"
    )?;
    writeln!(w, "# PARAM param_name param_value")?;
    writeln!(w, "# ODOM x y theta tv rv accel")?;
    writeln!(
        w,
        "# FLASER num_readings [range_readings] x y theta odom_x odom_y odom_theta"
    )?;
    writeln!(
        w,
        "# ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range \
         accuracy remission_mode num_readings [range_readings] num_remissions [remissions] \
         laser_pose_x laser_pose_y laser_pose_theta robot_pose_x robot_pose_y robot_pose_theta \
         laser_tv laser_rv forward_safety_dist side_safety_dist turn_axis"
    )?;
    writeln!(
        w,
        "# TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta"
    )?;
    writeln!(w, "PARAM robot_front_laser_max {max_range} {HOSTNAME} 0")?;
    writeln!(w, "PARAM laser_front_laser_fov {fov_deg} {HOSTNAME} 0")?;
    writeln!(w, "PARAM robot_frontlaser_offset {} {HOSTNAME} 0", offset.x)?;
    writeln!(
        w,
        "PARAM robot_frontlaser_side_offset {} {HOSTNAME} 0",
        offset.y
    )?;
    writeln!(
        w,
        "PARAM robot_frontlaser_angular_offset {} {HOSTNAME} 0",
        offset.theta
    )?;

    for r in records {
        let t = r.timestamp();
        let odom = r.odometry;
        let laser = odom * r.laser_offset;
        writeln!(
            w,
            "ODOM {} {} {} 0 0 0 {t} {HOSTNAME} {t}",
            odom.x, odom.y, odom.theta
        )?;
        let as_flaser =
            flaser_fit(&r.scan) == Some((fov_deg, max_range)) && r.laser_offset == offset;
        if as_flaser {
            write!(w, "FLASER {}", r.scan.beams())?;
            for x in r.scan.ranges() {
                write!(w, " {x}")?;
            }
            writeln!(
                w,
                " {} {} {} {} {} {} {t} {HOSTNAME} {t}",
                laser.x, laser.y, laser.theta, odom.x, odom.y, odom.theta
            )?;
        } else {
            let g = r.scan.geometry;
            let n = r.scan.beams();
            let fov = g.angle_increment * n.saturating_sub(1) as f64;
            write!(
                w,
                "ROBOTLASER1 0 {} {} {} {} 0.01 0 {n}",
                g.angle_min, fov, g.angle_increment, g.max_range
            )?;
            for x in r.scan.ranges() {
                write!(w, " {x}")?;
            }
            writeln!(
                w,
                " 0 {} {} {} {} {} {} 0 0 0 0 0 {t} {HOSTNAME} {t}",
                laser.x, laser.y, laser.theta, odom.x, odom.y, odom.theta
            )?;
        }
        if let Some(truth) = r.truth {
            writeln!(
                w,
                "TRUEPOS {} {} {} {} {} {} {t} {HOSTNAME} {t}",
                truth.x, truth.y, truth.theta, odom.x, odom.y, odom.theta
            )?;
        }
    }
    w.flush()
}
