//! Parsing one CARMEN line into its fields: every check a line can fail names the field.

use super::super::parse_f64;
use qicp_core::Pose2;
use qicp_core::index::MAX_COORDINATE;

/// A laser line parsed but not yet turned into a [`Scan`](qicp_core::Scan): `FLASER` geometry
/// comes from `PARAM` lines and the options.
pub(super) struct RawLaser {
    pub line: usize,
    pub timestamp: f64,
    pub ranges: Vec<f64>,
    pub odometry: Pose2,
    pub layout: Layout,
}

pub(super) enum Layout {
    /// Geometry from the options and `PARAM`s.
    Flaser,
    /// Geometry and laser pose from the line.
    Robot {
        angle_min: f64,
        angle_increment: f64,
        max_range: f64,
        laser_offset: Pose2,
    },
}

/// One line, parsed.
pub(super) enum Parsed {
    Laser(RawLaser),
    Odom((f64, Pose2)),
    TruePos((f64, Pose2)),
    Param((String, String)),
}

/// A cursor over a line's fields that names what it expected when it runs out.
struct Fields<'a, 'b> {
    fields: &'b [&'a str],
    at: usize,
    /// The most readings a laser line may announce.
    max_beams: usize,
}

impl<'a, 'b> Fields<'a, 'b> {
    fn new(fields: &'b [&'a str], max_beams: usize) -> Self {
        Self {
            fields,
            at: 0,
            max_beams,
        }
    }

    fn token(&mut self, what: &str) -> Result<&'a str, String> {
        let t = self
            .fields
            .get(self.at)
            .ok_or_else(|| format!("too few fields: `{what}` missing (field {})", self.at + 1))?;
        self.at += 1;
        Ok(t)
    }

    fn num(&mut self, what: &str) -> Result<f64, String> {
        let t = self.token(what)?;
        parse_f64(t).ok_or_else(|| format!("`{what}` is not a number: `{t}`"))
    }

    /// A number that must be finite (poses, timestamps, geometry; ranges may be NaN).
    fn finite(&mut self, what: &str) -> Result<f64, String> {
        let x = self.num(what)?;
        if x.is_finite() {
            Ok(x)
        } else {
            Err(format!("`{what}` is not finite: {x}"))
        }
    }

    fn count(&mut self, what: &str) -> Result<usize, String> {
        let t = self.token(what)?;
        t.parse::<usize>()
            .map_err(|_| format!("`{what}` is not a count: `{t}`"))
    }

    fn pose(&mut self, what: &str) -> Result<Pose2, String> {
        let x = self.finite(&format!("{what}_x"))?;
        let y = self.finite(&format!("{what}_y"))?;
        let t = self.finite(&format!("{what}_theta"))?;
        if x.abs() > MAX_COORDINATE || y.abs() > MAX_COORDINATE {
            return Err(format!(
                "{what} pose ({x}, {y}) lies beyond ±{MAX_COORDINATE} m, the largest coordinate \
                 a map holds"
            ));
        }
        Ok(Pose2::new(x, y, t))
    }

    fn left(&self) -> usize {
        self.fields.len() - self.at
    }

    /// `ipc_timestamp ipc_hostname logger_timestamp`, the end of every timed record.
    fn stamp(&mut self) -> Result<f64, String> {
        let t = self.finite("ipc_timestamp")?;
        self.token("ipc_hostname")?;
        self.num("logger_timestamp")?;
        if self.left() > 0 {
            return Err(format!(
                "{} unexpected fields after logger_timestamp",
                self.left()
            ));
        }
        Ok(t)
    }

    /// `n r_1..r_n`, checking that the line holds at least `n + after` fields more.
    fn ranges(&mut self, after: usize) -> Result<Vec<f64>, String> {
        let n = self.count("num_readings")?;
        if n == 0 {
            return Err("a laser line needs at least one reading".into());
        }
        if n > self.max_beams {
            return Err(format!(
                "{n} readings announced, above the limit of {} beams per scan (`max_beams`)",
                self.max_beams
            ));
        }
        // n ≤ max_beams, so the sum cannot overflow.
        if self.left() < n + after {
            return Err(format!(
                "beam count mismatch: {n} readings announced, but only {} fields follow ({} needed)",
                self.left(),
                n + after
            ));
        }
        let mut ranges = Vec::with_capacity(n);
        for i in 0..n {
            let t = self.fields[self.at + i];
            // NaN and inf readings are kept: the scan marks them invalid.
            ranges.push(
                parse_f64(t).ok_or_else(|| format!("range {} is not a number: `{t}`", i + 1))?,
            );
        }
        self.at += n;
        Ok(ranges)
    }
}

pub(super) fn parse_flaser(
    fields: &[&str],
    line: usize,
    max_beams: usize,
) -> Result<RawLaser, String> {
    let mut f = Fields::new(fields, max_beams);
    let ranges = f.ranges(9)?;
    if f.left() != 9 {
        return Err(format!(
            "beam count mismatch: {} readings announced, {} fields follow them instead of 9",
            ranges.len(),
            f.left()
        ));
    }
    let _laser_pose = f.pose("laser")?;
    let odometry = f.pose("odom")?;
    let timestamp = f.stamp()?;
    Ok(RawLaser {
        line,
        timestamp,
        ranges,
        odometry,
        layout: Layout::Flaser,
    })
}

pub(super) fn parse_robotlaser1(
    fields: &[&str],
    line: usize,
    max_beams: usize,
) -> Result<RawLaser, String> {
    let mut f = Fields::new(fields, max_beams);
    f.token("laser_type")?;
    let angle_min = f.finite("start_angle")?;
    if angle_min.abs() > std::f64::consts::TAU + 1e-9 {
        return Err(format!(
            "`start_angle` is {angle_min} rad: a bearing lies within ±2π"
        ));
    }
    // The bearings come from start_angle and angular_res (interleaved scans keep one fov for
    // two layouts); a fov outside (0, 2π] is a broken line all the same.
    let fov = f.finite("fov")?;
    if !(fov > 0.0 && fov <= std::f64::consts::TAU + 1e-9) {
        return Err(format!("`fov` is {fov} rad: needs 0 < fov ≤ 2π"));
    }
    let angle_increment = f.finite("angular_res")?;
    if angle_increment == 0.0 {
        return Err("`angular_res` is 0: the beams would all point one way".into());
    }
    let max_range = f.finite("max_range")?;
    f.num("accuracy")?;
    f.token("remission_mode")?;
    // After the ranges: n_remissions, then (with no remissions) 14 fields: laser and robot
    // poses, five velocity/safety fields, the time stamp.
    let ranges = f.ranges(1 + 14)?;
    let span = angle_increment.abs() * (ranges.len() - 1) as f64;
    if span > std::f64::consts::TAU + 1e-9 {
        return Err(format!(
            "{} beams {angle_increment} rad apart span {:.1}°, more than a full turn",
            ranges.len(),
            span.to_degrees()
        ));
    }
    let n_rem = f.count("num_remissions")?;
    if n_rem.checked_add(14) != Some(f.left()) {
        return Err(format!(
            "field count mismatch: {n_rem} remissions announced, {} fields follow instead of \
             that many and 14",
            f.left(),
        ));
    }
    f.at += n_rem;
    let laser = f.pose("laser")?;
    let robot = f.pose("robot")?;
    for what in ["tv", "rv", "forward_safety", "side_safety", "turn_axis"] {
        f.num(what)?;
    }
    let timestamp = f.stamp()?;
    Ok(RawLaser {
        line,
        timestamp,
        ranges,
        odometry: robot,
        layout: Layout::Robot {
            angle_min,
            angle_increment,
            max_range,
            laser_offset: robot.between(&laser),
        },
    })
}

pub(super) fn parse_odom(fields: &[&str]) -> Result<(f64, Pose2), String> {
    let mut f = Fields::new(fields, 0);
    let pose = f.pose("odom")?;
    for what in ["tv", "rv", "accel"] {
        f.num(what)?;
    }
    Ok((f.stamp()?, pose))
}

pub(super) fn parse_truepos(fields: &[&str]) -> Result<(f64, Pose2), String> {
    let mut f = Fields::new(fields, 0);
    let truth = f.pose("true")?;
    f.pose("odom")?;
    Ok((f.stamp()?, truth))
}

pub(super) fn parse_param(fields: &[&str]) -> Result<(String, String), String> {
    let mut f = Fields::new(fields, 0);
    let name = f.token("param_name")?;
    let value = f.token("param_value")?;
    Ok((name.to_string(), value.to_string()))
}
