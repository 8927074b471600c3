//! CARMEN text logs: `FLASER`, `ROBOTLASER1`, `ODOM`, `PARAM`, `TRUEPOS` (plain or `.bz2`).
//!
//! Record formats (whitespace-separated, one per line, `#` starts a comment line):
//!
//! ```text
//! ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp
//! FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp
//! ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
//!     n r_1..r_n n_remissions [remissions] laser_x laser_y laser_theta
//!     robot_x robot_y robot_theta tv rv forward_safety side_safety turn_axis
//!     ipc_timestamp ipc_hostname logger_timestamp
//! TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp
//! PARAM name value [ipc_hostname logger_timestamp]
//! ```
//!
//! Every laser line becomes one [`Record`], sorted by `ipc_timestamp` (stable: logs such as
//! Intel's are not written in time order). Its odometry is the robot pose of the line (the
//! `odom_*` fields of `FLASER`, the `robot_*` fields of `ROBOTLASER1`); `TRUEPOS` lines give
//! the ground truth of the laser record nearest in time.
//!
//! `FLASER` lines carry no beam angles. They are laid out like CARMEN's own reader
//! (`carmen_laser_guess_angle_increment`) and GMapping do: the first beam at −fov/2 and, for
//! the 180- and 360-beam SICK layouts that drop the last beam of the sweep, a step of fov/n
//! (1° and 0.5° over 180°); any other beam count spreads evenly over the fov (step
//! fov/(n−1)). See [`flaser_geometry`].
//!
//! `PARAM`s hold for the whole log wherever they appear (the last value of a name wins):
//! `laser_front_laser_fov` (degrees), `robot_front_laser_max` (m), `robot_frontlaser_offset`,
//! `robot_frontlaser_side_offset` (m) and `robot_frontlaser_angular_offset` (rad) shape the
//! `FLASER` scans; [`CarmenOptions`] set explicitly override them. Unknown record types
//! (`RLASER`, `SYNC`, `RAWLASER1`, …) are skipped and counted in
//! [`CarmenLog::unknown_types`]; [`CarmenLog::report`] lists them.

use super::{LogError, next_line, parse_f64};
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::Path;

/// Field of view assumed for `FLASER` lines when neither the options nor a `PARAM` give one.
pub const DEFAULT_FLASER_FOV_DEG: f64 = 180.0;
/// Maximum range assumed for `FLASER` lines when neither the options nor a `PARAM` give one:
/// SICK LMS no-returns read about 81.9 m.
pub const DEFAULT_FLASER_MAX_RANGE: f64 = 81.0;
/// How far (s) a `TRUEPOS` may lie from a laser record and still be its ground truth.
pub const DEFAULT_TRUEPOS_MAX_DT: f64 = 0.1;

/// How to read a CARMEN log.
///
/// Fields left `None` come from the log's `PARAM` lines, else from the documented default:
/// an explicit option always wins over the log.
#[derive(Debug, Clone, PartialEq)]
pub struct CarmenOptions {
    /// Skip and count malformed lines instead of failing on the first.
    pub lenient: bool,
    /// Field of view of `FLASER` scans (degrees). Else `PARAM laser_front_laser_fov`, else
    /// [`DEFAULT_FLASER_FOV_DEG`].
    pub flaser_fov_deg: Option<f64>,
    /// Readings at or above this are no-returns (m). Applies to `FLASER` (else
    /// `PARAM robot_front_laser_max`, else [`DEFAULT_FLASER_MAX_RANGE`]) and, when set, to
    /// `ROBOTLASER1` too (else the line's own `max_range` field).
    pub max_range: Option<f64>,
    /// Readings below this are discarded (m); CARMEN logs carry no minimum range. Default 0.
    pub min_range: f64,
    /// Pose of the front laser in the robot frame for `FLASER` lines. Else
    /// `PARAM robot_frontlaser_offset` (x), `robot_frontlaser_side_offset` (y) and
    /// `robot_frontlaser_angular_offset` (rad), each 0 when absent. `ROBOTLASER1` lines carry
    /// their own laser pose.
    pub laser_offset: Option<Pose2>,
    /// How far (s) a `TRUEPOS` may lie from a laser record and still be attached as its ground
    /// truth. Default [`DEFAULT_TRUEPOS_MAX_DT`].
    pub truepos_max_dt: f64,
}

impl Default for CarmenOptions {
    fn default() -> Self {
        Self {
            lenient: false,
            flaser_fov_deg: None,
            max_range: None,
            min_range: 0.0,
            laser_offset: None,
            truepos_max_dt: DEFAULT_TRUEPOS_MAX_DT,
        }
    }
}

impl CarmenOptions {
    /// Refuses options that cannot describe a laser.
    pub fn validate(&self) -> Result<(), LogError> {
        let bad = |name, why: &str| {
            Err(LogError::InvalidOption {
                name,
                why: why.to_string(),
            })
        };
        if let Some(fov) = self.flaser_fov_deg
            && !(fov.is_finite() && fov > 0.0 && fov <= 360.0)
        {
            return bad("flaser_fov_deg", "must lie in (0, 360]");
        }
        if let Some(m) = self.max_range
            && !(m.is_finite() && m > 0.0)
        {
            return bad("max_range", "must be finite and positive");
        }
        if !(self.min_range.is_finite() && self.min_range >= 0.0) {
            return bad("min_range", "must be finite and non-negative");
        }
        if let Some(o) = self.laser_offset
            && !o.is_finite()
        {
            return bad("laser_offset", "must be finite");
        }
        if self.truepos_max_dt.is_nan() || self.truepos_max_dt < 0.0 {
            return bad("truepos_max_dt", "must be non-negative");
        }
        Ok(())
    }
}

/// A log read into memory, laser records sorted by timestamp.
#[derive(Debug, Clone, Default)]
pub struct CarmenLog {
    /// Laser records in time order.
    pub records: Vec<Record>,
    /// Malformed lines skipped (lenient mode only).
    pub skipped_lines: usize,
    /// Why the first few skipped lines were skipped (`file:line: why`).
    pub skipped_examples: Vec<String>,
    /// `ODOM` records `(ipc_timestamp, pose)` in time order.
    pub odometry: Vec<(f64, Pose2)>,
    /// `TRUEPOS` records `(ipc_timestamp, true pose)` in time order.
    pub truepos: Vec<(f64, Pose2)>,
    /// `PARAM` lines, name → value (the last one wins).
    pub params: BTreeMap<String, String>,
    /// Lines of each record type read (known types only).
    pub counts: BTreeMap<String, usize>,
    /// Lines of record types this reader does not know, skipped, per type.
    pub unknown_types: BTreeMap<String, usize>,
    /// Laser lines whose timestamp is earlier than the previous laser line's.
    pub out_of_order: usize,
}

impl CarmenLog {
    /// Laser records with ground truth attached.
    #[must_use]
    pub fn records_with_truth(&self) -> usize {
        self.records.iter().filter(|r| r.truth.is_some()).count()
    }

    /// The odometry of the laser records: `(timestamp, robot pose)` in time order.
    #[must_use]
    pub fn laser_odometry(&self) -> Vec<(f64, Pose2)> {
        self.records
            .iter()
            .map(|r| (r.timestamp(), r.odometry))
            .collect()
    }

    /// The ground truth of the laser records that have one, in time order.
    #[must_use]
    pub fn laser_truth(&self) -> Vec<(f64, Pose2)> {
        self.records
            .iter()
            .filter_map(|r| r.truth.map(|t| (r.timestamp(), t)))
            .collect()
    }

    /// A human-readable summary: what was read, what was skipped and why.
    #[must_use]
    pub fn report(&self) -> String {
        let mut s = format!("{} laser records", self.records.len());
        if let Some(first) = self.records.first() {
            let last = self.records.last().map_or(0.0, Record::timestamp);
            s += &format!(
                " ({} beams, {:.1} s)",
                first.scan.beams(),
                last - first.timestamp()
            );
        }
        for (k, v) in &self.counts {
            s += &format!(", {v} {k}");
        }
        if self.out_of_order > 0 {
            s += &format!(
                "; {} laser lines out of time order (sorted)",
                self.out_of_order
            );
        }
        if !self.unknown_types.is_empty() {
            let list: Vec<String> = self
                .unknown_types
                .iter()
                .map(|(k, v)| format!("{v} {k}"))
                .collect();
            s += &format!("; skipped unknown record types: {}", list.join(", "));
        }
        if self.skipped_lines > 0 {
            s += &format!("; skipped {} malformed lines", self.skipped_lines);
            for e in &self.skipped_examples {
                s += &format!("\n  {e}");
            }
        }
        s
    }
}

/// The beam layout of a `FLASER` scan of `beams` beams over `fov` radians (see the module
/// documentation): first beam at −fov/2; step fov/n for the 180- and 360-beam SICK layouts
/// (CARMEN's `carmen_laser_guess_angle_increment`), fov/(n−1) otherwise.
#[must_use]
pub fn flaser_geometry(beams: usize, fov: f64, max_range: f64, min_range: f64) -> BeamGeometry {
    let angle_increment = match beams {
        180 | 360 => fov / beams as f64,
        0 | 1 => 0.0,
        n => fov / (n - 1) as f64,
    };
    BeamGeometry {
        angle_min: -fov / 2.0,
        angle_increment,
        max_range,
        min_range,
    }
}

/// How many skipped lines [`CarmenLog::skipped_examples`] keeps.
const SKIPPED_EXAMPLES: usize = 10;

/// A laser line parsed but not yet turned into a [`Scan`]: `FLASER` geometry depends on
/// `PARAM` lines that may come anywhere in the log.
struct RawLaser {
    line: usize,
    timestamp: f64,
    ranges: Vec<f64>,
    odometry: Pose2,
    layout: Layout,
}

enum Layout {
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

/// Reads a CARMEN log for a command: strict, or with `lenient` skipping malformed lines and
/// warning on stderr how many it skipped.
pub fn load_for_command(path: &Path, lenient: bool) -> Result<CarmenLog, LogError> {
    let log = read_carmen(
        path,
        &CarmenOptions {
            lenient,
            ..CarmenOptions::default()
        },
    )?;
    if log.skipped_lines > 0 {
        eprintln!(
            "warning: skipped {} malformed lines of {} (--lenient)",
            log.skipped_lines,
            path.display()
        );
    }
    Ok(log)
}

/// Reads a CARMEN log, plain or bzip2-compressed.
pub fn read_carmen(path: &Path, opts: &CarmenOptions) -> Result<CarmenLog, LogError> {
    let mut reader = super::open_text(path)?;
    read_carmen_from(&mut reader, &path.display().to_string(), opts)
}

/// Reads a CARMEN log from any reader (already decompressed); `name` is used in errors.
pub fn read_carmen_from<R: BufRead + ?Sized>(
    reader: &mut R,
    name: &str,
    opts: &CarmenOptions,
) -> Result<CarmenLog, LogError> {
    opts.validate()?;
    let mut log = CarmenLog::default();
    let mut raw: Vec<RawLaser> = Vec::new();
    let mut truepos: Vec<(f64, Pose2)> = Vec::new();
    let mut buf = Vec::with_capacity(4096);
    let mut line_no = 0usize;
    let mut last_laser_time = f64::NEG_INFINITY;

    let skip = |log: &mut CarmenLog, err: LogError| -> Result<(), LogError> {
        if !opts.lenient {
            return Err(err);
        }
        log.skipped_lines += 1;
        if log.skipped_examples.len() < SKIPPED_EXAMPLES {
            log.skipped_examples.push(err.to_string());
        }
        Ok(())
    };

    loop {
        let more = next_line(reader, &mut buf).map_err(|e| LogError::Io {
            path: name.to_string(),
            source: e,
        })?;
        if !more {
            break;
        }
        line_no += 1;
        let line = match std::str::from_utf8(&buf) {
            Ok(l) => l,
            Err(_) => {
                skip(
                    &mut log,
                    LogError::malformed(name, line_no, "not UTF-8 text"),
                )?;
                continue;
            }
        };
        let mut tokens = line.split_ascii_whitespace();
        let Some(kind) = tokens.next() else { continue };
        if kind.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = tokens.collect();
        let fail = |why: String| LogError::malformed(name, line_no, format!("{kind}: {why}"));
        let parsed = match kind {
            "FLASER" => parse_flaser(&fields, line_no).map(Parsed::Laser),
            "ROBOTLASER1" => parse_robotlaser1(&fields, line_no).map(Parsed::Laser),
            "ODOM" => parse_odom(&fields).map(Parsed::Odom),
            "TRUEPOS" => parse_truepos(&fields).map(Parsed::TruePos),
            "PARAM" => parse_param(&fields).map(Parsed::Param),
            other => {
                *log.unknown_types.entry(other.to_string()).or_insert(0) += 1;
                continue;
            }
        };
        match parsed {
            Err(why) => skip(&mut log, fail(why))?,
            Ok(p) => {
                *log.counts.entry(kind.to_string()).or_insert(0) += 1;
                match p {
                    Parsed::Laser(l) => {
                        if l.timestamp < last_laser_time {
                            log.out_of_order += 1;
                        }
                        last_laser_time = l.timestamp;
                        raw.push(l);
                    }
                    Parsed::Odom(o) => log.odometry.push(o),
                    Parsed::TruePos(t) => truepos.push(t),
                    Parsed::Param((k, v)) => {
                        log.params.insert(k, v);
                    }
                }
            }
        }
    }

    let flaser = flaser_settings(&log.params, opts, name)?;
    log.records.reserve(raw.len());
    for l in raw {
        let (geometry, laser_offset) = match l.layout {
            Layout::Flaser => (
                flaser_geometry(l.ranges.len(), flaser.fov, flaser.max_range, opts.min_range),
                flaser.offset,
            ),
            Layout::Robot {
                angle_min,
                angle_increment,
                max_range,
                laser_offset,
            } => (
                BeamGeometry {
                    angle_min,
                    angle_increment,
                    max_range: opts.max_range.unwrap_or(max_range),
                    min_range: opts.min_range,
                },
                laser_offset,
            ),
        };
        match Scan::new(l.timestamp, geometry, l.ranges) {
            Ok(scan) => log.records.push(Record {
                scan,
                odometry: l.odometry,
                truth: None,
                laser_offset,
            }),
            Err(e) => skip(&mut log, LogError::malformed(name, l.line, e.to_string()))?,
        }
    }

    // Stable: records with equal timestamps keep their order in the file.
    log.records
        .sort_by(|a, b| a.timestamp().total_cmp(&b.timestamp()));
    log.odometry.sort_by(|a, b| a.0.total_cmp(&b.0));
    truepos.sort_by(|a, b| a.0.total_cmp(&b.0));
    for r in &mut log.records {
        r.truth = nearest(&truepos, r.timestamp(), opts.truepos_max_dt).map(|(_, p)| p);
    }
    log.truepos = truepos;
    Ok(log)
}

/// The `FLASER` layout in force: options, else `PARAM`s, else defaults.
struct FlaserSettings {
    fov: f64,
    max_range: f64,
    offset: Pose2,
}

fn flaser_settings(
    params: &BTreeMap<String, String>,
    opts: &CarmenOptions,
    name: &str,
) -> Result<FlaserSettings, LogError> {
    let param = |key: &str| -> Result<Option<f64>, LogError> {
        match params.get(key) {
            None => Ok(None),
            Some(v) => match parse_f64(v) {
                Some(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(LogError::Malformed {
                    path: name.to_string(),
                    line: 0,
                    why: format!("PARAM {key} {v}: not a finite number"),
                }),
            },
        }
    };
    let fov_deg = match opts.flaser_fov_deg {
        Some(f) => f,
        None => param("laser_front_laser_fov")?.unwrap_or(DEFAULT_FLASER_FOV_DEG),
    };
    let max_range = match opts.max_range {
        Some(m) => m,
        None => param("robot_front_laser_max")?.unwrap_or(DEFAULT_FLASER_MAX_RANGE),
    };
    let offset = match opts.laser_offset {
        Some(o) => o,
        None => Pose2::new(
            param("robot_frontlaser_offset")?.unwrap_or(0.0),
            param("robot_frontlaser_side_offset")?.unwrap_or(0.0),
            param("robot_frontlaser_angular_offset")?.unwrap_or(0.0),
        ),
    };
    Ok(FlaserSettings {
        fov: fov_deg.to_radians(),
        max_range,
        offset,
    })
}

/// The entry of `sorted` nearest in time to `t`, if within `max_dt`.
fn nearest(sorted: &[(f64, Pose2)], t: f64, max_dt: f64) -> Option<(f64, Pose2)> {
    let i = sorted.partition_point(|(s, _)| *s < t);
    let before = i.checked_sub(1).map(|j| sorted[j]);
    let after = sorted.get(i).copied();
    let best = match (before, after) {
        (Some(b), Some(a)) => {
            if (t - b.0) <= (a.0 - t) {
                Some(b)
            } else {
                Some(a)
            }
        }
        (b, a) => b.or(a),
    };
    best.filter(|(s, _)| (s - t).abs() <= max_dt)
}

enum Parsed {
    Laser(RawLaser),
    Odom((f64, Pose2)),
    TruePos((f64, Pose2)),
    Param((String, String)),
}

/// A cursor over a line's fields that names what it expected when it runs out.
struct Fields<'a, 'b> {
    fields: &'b [&'a str],
    at: usize,
}

impl<'a, 'b> Fields<'a, 'b> {
    fn new(fields: &'b [&'a str]) -> Self {
        Self { fields, at: 0 }
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

fn parse_flaser(fields: &[&str], line: usize) -> Result<RawLaser, String> {
    let mut f = Fields::new(fields);
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

fn parse_robotlaser1(fields: &[&str], line: usize) -> Result<RawLaser, String> {
    let mut f = Fields::new(fields);
    f.token("laser_type")?;
    let angle_min = f.finite("start_angle")?;
    f.finite("fov")?;
    let angle_increment = f.finite("angular_res")?;
    let max_range = f.finite("max_range")?;
    f.num("accuracy")?;
    f.token("remission_mode")?;
    // After the ranges: n_remissions, then (with no remissions) 14 fields: laser and robot
    // poses, five velocity/safety fields, the time stamp.
    let ranges = f.ranges(1 + 14)?;
    let n_rem = f.count("num_remissions")?;
    if f.left() != n_rem + 14 {
        return Err(format!(
            "field count mismatch: {n_rem} remissions announced, {} fields follow instead of {}",
            f.left(),
            n_rem + 14
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

fn parse_odom(fields: &[&str]) -> Result<(f64, Pose2), String> {
    let mut f = Fields::new(fields);
    let pose = f.pose("odom")?;
    for what in ["tv", "rv", "accel"] {
        f.num(what)?;
    }
    Ok((f.stamp()?, pose))
}

fn parse_truepos(fields: &[&str]) -> Result<(f64, Pose2), String> {
    let mut f = Fields::new(fields);
    let truth = f.pose("true")?;
    f.pose("odom")?;
    Ok((f.stamp()?, truth))
}

fn parse_param(fields: &[&str]) -> Result<(String, String), String> {
    let mut f = Fields::new(fields);
    let name = f.token("param_name")?;
    let value = f.token("param_value")?;
    Ok((name.to_string(), value.to_string()))
}

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
/// written (set [`CarmenOptions::min_range`] when reading back).
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn intel_layout_is_carmens() {
        let g = flaser_geometry(180, std::f64::consts::PI, 81.0, 0.0);
        assert!((g.angle(0) + std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((g.angle(179) - 89f64.to_radians()).abs() < 1e-12);
        let g = flaser_geometry(181, std::f64::consts::PI, 81.0, 0.0);
        assert!((g.angle(180) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let g = flaser_geometry(361, std::f64::consts::PI, 81.0, 0.0);
        assert!((g.angle_increment - 0.5f64.to_radians()).abs() < 1e-15);
    }

    #[test]
    fn nearest_respects_the_window() {
        let p = Pose2::IDENTITY;
        let v = [(1.0, p), (2.0, p), (3.0, p)];
        assert_eq!(nearest(&v, 2.04, 0.1).map(|x| x.0), Some(2.0));
        assert_eq!(nearest(&v, 2.6, 0.1), None);
        assert_eq!(nearest(&v, 0.95, 0.1).map(|x| x.0), Some(1.0));
        assert_eq!(nearest(&v, 3.05, 0.1).map(|x| x.0), Some(3.0));
        assert_eq!(nearest(&[], 3.05, 0.1), None);
    }

    #[test]
    fn bad_options_are_refused() {
        let o = CarmenOptions {
            flaser_fov_deg: Some(-1.0),
            ..CarmenOptions::default()
        };
        assert!(matches!(
            o.validate(),
            Err(LogError::InvalidOption {
                name: "flaser_fov_deg",
                ..
            })
        ));
    }
}
