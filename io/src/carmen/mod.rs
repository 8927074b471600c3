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
//! Every laser line becomes one [`Record`], in file order ([`RecordOrder::File`], the default:
//! CARMEN's logger writes each message as it arrives and its playback replays the file line by
//! line, so the file holds a laser's scans in the order it took them, even where their
//! timestamps jitter: Intel's run back by up to 0.6 s at 631 lines, while the odometry in those
//! lines moves on steadily) or, with [`RecordOrder::Time`], in `ipc_timestamp` order within a
//! reorder window. [`CarmenReader`] streams them in bounded memory; [`read_carmen`] reads
//! them all. Its odometry is the robot pose of the line (the
//! `odom_*` fields of `FLASER`, the `robot_*` fields of `ROBOTLASER1`); `TRUEPOS` lines give
//! the ground truth of the laser record nearest in time.
//!
//! `FLASER` lines carry no beam angles. They are laid out like CARMEN's own reader
//! (`carmen_laser_guess_angle_increment`) and GMapping do: the first beam at −fov/2 and, for
//! the 180- and 360-beam SICK layouts that drop the last beam of the sweep, a step of fov/n
//! (1° and 0.5° over 180°); any other beam count spreads evenly over the fov (step
//! fov/(n−1)). See [`flaser_geometry`].
//!
//! `PARAM`s `laser_front_laser_fov` (degrees, in (0, 360]), `robot_front_laser_max` (m,
//! positive), `robot_frontlaser_offset`, `robot_frontlaser_side_offset` (m) and
//! `robot_frontlaser_angular_offset` (rad) shape the `FLASER` scans; they come before the
//! first `FLASER` line (the last value of a name wins), and [`CarmenOptions`] set explicitly
//! override them. Unknown record types (`RLASER`, `SYNC`, `RAWLASER1`, …) are skipped and
//! counted in [`LogInfo::unknown_types`]; [`LogInfo::report`] lists them.
//!
//! Limits: a laser line announces at most [`CarmenOptions::max_beams`] readings; poses lie
//! within ±[`MAX_COORDINATE`](qicp_core::index::MAX_COORDINATE) m; a `ROBOTLASER1` angular resolution
//! is not 0 and its beams span at most a full turn.

mod fields;
mod stream;
mod write;

pub use stream::CarmenReader;
pub use write::write_carmen;

use super::{LogError, parse_f64};
use qicp_core::{BeamGeometry, Pose2, Record};
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

/// Field of view assumed for `FLASER` lines when neither the options nor a `PARAM` give one.
pub const DEFAULT_FLASER_FOV_DEG: f64 = 180.0;
/// Maximum range assumed for `FLASER` lines when neither the options nor a `PARAM` give one:
/// SICK LMS no-returns read about 81.9 m.
pub const DEFAULT_FLASER_MAX_RANGE: f64 = 81.0;
/// How far (s) a `TRUEPOS` may lie from a laser record and still be its ground truth.
pub const DEFAULT_TRUEPOS_MAX_DT: f64 = 0.1;
/// Readings a laser line may announce at most: well above any real 2D laser (a 0.1° scanner
/// over 360° gives 3,600).
pub const DEFAULT_MAX_BEAMS: usize = 10_000;
/// How far (s) laser lines may come out of time order and still be put back in order.
pub const DEFAULT_REORDER_WINDOW: f64 = 5.0;
/// How many laser records the reorder buffer holds at most.
pub const DEFAULT_REORDER_RECORDS: usize = 1_000;

/// In which order a CARMEN log's laser records are delivered ([`CarmenOptions::order`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RecordOrder {
    /// As the lines stand in the file: the order the logger received them, which for one
    /// laser is the order it took them. Timestamps running back against it are counted
    /// ([`LogInfo::out_of_order`]), not acted on. Default: on the Intel log, whose stamps
    /// jitter, scan-to-scan IDC scores 0.18 m on the relations this way and 0.44 m sorted by
    /// time, which puts scans taken in a steady drive forwards and back by up to 0.15 m.
    #[default]
    File,
    /// By `ipc_timestamp` (ties in file order), within [`CarmenOptions::reorder_window`]:
    /// for a file whose lines are not in the order they were taken (several logs cut
    /// together); a line later than the window allows is dropped ([`LogInfo::late`]).
    Time,
}

impl RecordOrder {
    /// The order's name where a user gives it: `"file"` or `"time"`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            RecordOrder::File => "file",
            RecordOrder::Time => "time",
        }
    }
}

impl std::str::FromStr for RecordOrder {
    type Err = String;

    /// `"file"` or `"time"`; anything else is refused with the two names.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [RecordOrder::File, RecordOrder::Time]
            .into_iter()
            .find(|o| o.name() == s)
            .ok_or_else(|| format!("order {s:?}: use \"file\" or \"time\""))
    }
}

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
    /// Readings a laser line may announce at most; a longer line is malformed. Default
    /// [`DEFAULT_MAX_BEAMS`].
    pub max_beams: usize,
    /// The order of the records. Default [`RecordOrder::File`].
    pub order: RecordOrder,
    /// How far (s) laser lines may come out of time order and still be sorted
    /// ([`RecordOrder::Time`]), and how long a record waits for a `TRUEPOS` line that the
    /// file gives after it; at least `truepos_max_dt`. Default [`DEFAULT_REORDER_WINDOW`].
    pub reorder_window: f64,
    /// How many records the reorder buffer holds at most, so that memory stays bounded even
    /// when timestamps stand still. Default [`DEFAULT_REORDER_RECORDS`].
    pub reorder_records: usize,
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
            max_beams: DEFAULT_MAX_BEAMS,
            order: RecordOrder::File,
            reorder_window: DEFAULT_REORDER_WINDOW,
            reorder_records: DEFAULT_REORDER_RECORDS,
        }
    }
}

/// Why `fov` (deg) cannot be a laser's field of view ([`CarmenOptions::flaser_fov_deg`]), or
/// `None` when it can.
#[must_use]
pub fn fov_deg_problem(fov: f64) -> Option<&'static str> {
    (!(fov.is_finite() && fov > 0.0 && fov <= 360.0)).then_some("must lie in (0, 360]")
}

/// Why `m` cannot be a laser's maximum range ([`CarmenOptions::max_range`]), or `None`.
#[must_use]
pub fn max_range_problem(m: f64) -> Option<&'static str> {
    (!(m.is_finite() && m > 0.0)).then_some("must be finite and positive")
}

/// Why `m` cannot be a laser's minimum range ([`CarmenOptions::min_range`]), or `None`.
#[must_use]
pub fn min_range_problem(m: f64) -> Option<&'static str> {
    (!(m.is_finite() && m >= 0.0)).then_some("must be finite and non-negative")
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
        if let Some(why) = self.flaser_fov_deg.and_then(fov_deg_problem) {
            return bad("flaser_fov_deg", why);
        }
        if let Some(why) = self.max_range.and_then(max_range_problem) {
            return bad("max_range", why);
        }
        if let Some(why) = min_range_problem(self.min_range) {
            return bad("min_range", why);
        }
        if let Some(o) = self.laser_offset
            && !o.is_finite()
        {
            return bad("laser_offset", "must be finite");
        }
        if !(self.truepos_max_dt.is_finite() && self.truepos_max_dt >= 0.0) {
            return bad("truepos_max_dt", "must be finite and non-negative");
        }
        if self.max_beams == 0 {
            return bad("max_beams", "must be at least 1");
        }
        if !(self.reorder_window.is_finite() && self.reorder_window >= self.truepos_max_dt) {
            return bad(
                "reorder_window",
                "must be finite and at least truepos_max_dt",
            );
        }
        if self.reorder_records == 0 {
            return bad("reorder_records", "must be at least 1");
        }
        Ok(())
    }
}

/// What a read met besides the laser records: counts, skips, `PARAM`s.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogInfo {
    /// Laser records delivered.
    pub records: usize,
    /// Malformed lines skipped (lenient mode only).
    pub skipped_lines: usize,
    /// Why the first few skipped lines were skipped (`file:line: why`).
    pub skipped_examples: Vec<String>,
    /// `PARAM` lines, name → value (the last one wins).
    pub params: BTreeMap<String, String>,
    /// Lines of each record type read (known types only).
    pub counts: BTreeMap<String, usize>,
    /// Lines of record types this reader does not know, skipped, per type.
    pub unknown_types: BTreeMap<String, usize>,
    /// Laser lines whose timestamp is earlier than the previous laser line's (put back in
    /// time order with [`RecordOrder::Time`]).
    pub out_of_order: usize,
    /// The order the records were delivered in.
    pub order: RecordOrder,
    /// Laser lines dropped because they came later than [`CarmenOptions::reorder_window`]
    /// allows: records after them had already been delivered.
    pub late: usize,
    /// Earliest and latest time of the records delivered (s).
    pub span: Option<(f64, f64)>,
    /// Beams of the first record delivered.
    pub first_beams: usize,
    /// The ranges the delivered scans keep, counted per centimetre.
    pub ranges: RangeCounts,
    /// A no-return code found at the head of the log and read as no-returns
    /// ([`no_return_probe`]: a log opened by path that does not say its maximum range, with
    /// none given).
    pub no_return_code: Option<NoReturnCode>,
}

/// Readings beyond this range (m) are not counted by [`RangeCounts`].
const RANGE_COUNT_LIMIT: f64 = 200.0;
/// A range that at least this many readings share, and at least [`CODE_RATIO`] times as
/// many as the average centimetre of the metre below it, is a no-return code.
const CODE_MIN_READINGS: u64 = 100;
/// See [`CODE_MIN_READINGS`].
const CODE_RATIO: f64 = 20.0;

/// How many of a log's kept readings fall in each centimetre of range, up to 200 m: where a
/// laser writes its no-returns as a value below the maximum range the log declares (the
/// Freiburg clinic's `ROBOTLASER1` lines declare 81.9 m and write 81.83 m, a SICK LMS error
/// code, in 5,849 readings), that value stands far above the metre below it, and every scan
/// would keep phantom points there. [`RangeCounts::no_return_code`] finds it;
/// [`LogInfo::warn`] names it and the `--max-range` that drops it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RangeCounts {
    /// Readings per centimetre, `bins[k]` for ranges that round to k cm; empty until the
    /// first scan.
    bins: Vec<u64>,
}

impl RangeCounts {
    /// Counts the ranges of the points `scan` keeps.
    pub fn add(&mut self, scan: &qicp_core::Scan) {
        if self.bins.is_empty() {
            self.bins = vec![0; (RANGE_COUNT_LIMIT * 100.0) as usize + 1];
        }
        for k in 0..scan.points().len() {
            let cm = (scan.point_range(k) * 100.0).round();
            if (0.0..=RANGE_COUNT_LIMIT * 100.0).contains(&cm) {
                self.bins[cm as usize] += 1;
            }
        }
    }

    /// The largest range kept, where it looks like a no-return code: the range (m), its
    /// readings, and the average readings per centimetre in the metre below it.
    #[must_use]
    pub fn no_return_code(&self) -> Option<(f64, u64, f64)> {
        let top = self.bins.iter().rposition(|&n| n > 0)?;
        let count = self.bins[top];
        let below = &self.bins[top.saturating_sub(100)..top];
        let per_cm = below.iter().sum::<u64>() as f64 / below.len().max(1) as f64;
        (count >= CODE_MIN_READINGS && count as f64 >= CODE_RATIO * per_cm.max(1.0)).then_some((
            top as f64 / 100.0,
            count,
            per_cm,
        ))
    }
}

/// Laser records [`no_return_probe`] reads from the head of a log.
pub const NO_RETURN_PROBE_RECORDS: usize = 1_000;
/// Distinct beams that must read a no-return code in the probe: a code stands wherever a beam
/// finds nothing, across the field of view, where a real far return that the robot, standing
/// still, reads again and again stands in a beam or two.
pub const CODE_MIN_BEAMS: usize = 10;

/// A no-return code found at the head of a log ([`no_return_probe`]) and read as no-returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoReturnCode {
    /// The code (m).
    pub range: f64,
    /// Readings of the probe that read it.
    pub count: u64,
    /// Average readings per centimetre of the probe in the metre below it.
    pub per_cm: f64,
    /// Records the probe read.
    pub records: usize,
}

impl NoReturnCode {
    /// The maximum range the records are read with: half a centimetre below the code.
    #[must_use]
    pub fn max_range(&self) -> f64 {
        just_below(self.range)
    }
}

/// The maximum range that reads `code` as a no-return and keeps everything shorter: half a
/// centimetre below it, as logs write their ranges to the centimetre.
fn just_below(code: f64) -> f64 {
    code - 0.005
}

/// Where neither the options (`opts.max_range`) nor the log give a maximum range, the
/// 81 m of [`DEFAULT_FLASER_MAX_RANGE`] is a guess: reads the first
/// [`NO_RETURN_PROBE_RECORDS`] laser records of `path` and looks for a no-return code below it,
/// by the rule of [`RangeCounts::no_return_code`], read by at least [`CODE_MIN_BEAMS`] distinct
/// beams. A 50 m laser's `FLASER` lines with no `PARAM robot_front_laser_max` would otherwise
/// put a phantom point in every beam that found nothing, on a circle that moves with the
/// robot and pulls each match towards standing still: on Intel with its no-returns written
/// as 50 m, q-wsm scored 3.36 m and q-idc 1.93 m against 0.020 and 0.017 m. A log that gives
/// its maximum range (a `PARAM robot_front_laser_max`, or `ROBOTLASER1` lines, which carry
/// their own) is read as it says, and a code below it is named by the warning after the read
/// ([`LogInfo::warn`]): the Freiburg clinic's lines declare 81.9 m and write 81.83 m for a
/// no-return in about one reading of 200, and read as no-returns they turned q-wsm's heading
/// outdoors up to 45° off q-idc's, against 12.5° read as points (the README, Data). `None`
/// where a maximum range is given, or the probe finds no code, or the head of the log cannot
/// be read (the read proper then says why), or `path` is not a regular file: a log on a pipe
/// can be read only once, and the probe would take its head from the read (such a log is read
/// as it says, and the warning after the read names a code).
pub fn no_return_probe(path: &Path, opts: &CarmenOptions) -> Option<NoReturnCode> {
    let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    if opts.max_range.is_some() || !regular {
        return None;
    }
    let probe = CarmenOptions {
        lenient: true,
        ..opts.clone()
    };
    let mut reader = CarmenReader::open_as_given(path, &probe).ok()?;
    let records: Vec<Record> = reader
        .by_ref()
        .take(NO_RETURN_PROBE_RECORDS)
        .map_while(Result::ok)
        .collect();
    let declared = reader.info.params.contains_key("robot_front_laser_max")
        || reader.info.counts.contains_key("ROBOTLASER1");
    if declared {
        return None;
    }
    let (range, count, per_cm) = reader.info.ranges.no_return_code()?;
    let code_cm = (range * 100.0).round();
    let mut beams = std::collections::BTreeSet::new();
    for r in &records {
        for (k, &beam) in r.scan.beam_of_point().iter().enumerate() {
            if (r.scan.point_range(k) * 100.0).round() == code_cm {
                beams.insert(beam);
            }
        }
    }
    (beams.len() >= CODE_MIN_BEAMS).then_some(NoReturnCode {
        range,
        count,
        per_cm,
        records: records.len(),
    })
}

/// The options a log at `path` is read with: `opts`, with the maximum range set just below a
/// no-return code [`no_return_probe`] finds, and that code.
fn with_no_return_code(path: &Path, opts: &CarmenOptions) -> (CarmenOptions, Option<NoReturnCode>) {
    let code = no_return_probe(path, opts);
    let opts = CarmenOptions {
        max_range: code.map(|c| c.max_range()).or(opts.max_range),
        ..opts.clone()
    };
    (opts, code)
}

impl LogInfo {
    /// A human-readable summary: what was read, what was skipped and why.
    #[must_use]
    pub fn report(&self) -> String {
        let mut s = format!("{} laser records", self.records);
        if let Some((first, last)) = self.span {
            s += &format!(" ({} beams, {:.1} s)", self.first_beams, last - first);
        }
        for (k, v) in &self.counts {
            s += &format!(", {v} {k}");
        }
        if self.out_of_order > 0 {
            let how = match self.order {
                RecordOrder::File => "kept in file order",
                RecordOrder::Time => "sorted",
            };
            s += &format!(
                "; {} laser lines out of time order ({how})",
                self.out_of_order
            );
        }
        if self.late > 0 {
            s += &format!(
                "; dropped {} laser lines more than the reorder window out of time order",
                self.late
            );
        }
        if !self.unknown_types.is_empty() {
            s += &format!("; skipped unknown record types: {}", self.unknown_list());
        }
        if self.skipped_lines > 0 {
            s += &format!("; skipped {} malformed lines", self.skipped_lines);
            for e in &self.skipped_examples {
                s += &format!("\n  {e}");
            }
        }
        s
    }

    /// The unknown record types with their counts, e.g. `2 SYNC, 1 RLASER`.
    fn unknown_list(&self) -> String {
        let list: Vec<String> = self
            .unknown_types
            .iter()
            .map(|(k, v)| format!("{v} {k}"))
            .collect();
        list.join(", ")
    }

    /// Warnings a command prints on stderr: skipped and dropped lines, and notes on lines
    /// out of time order kept in file order and on records of types qicp does not read.
    pub fn warn(&self, path: &Path) {
        if self.skipped_lines > 0 {
            qicp_core::note!(
                "warning: skipped {} malformed lines of {} (--lenient)",
                self.skipped_lines,
                path.display()
            );
        }
        if self.out_of_order > 0 && self.order == RecordOrder::File {
            qicp_core::note!(
                "note: {} laser lines of {} are stamped earlier than the line before them; they \
                 are matched in file order, the order the laser took them (--order time sorts \
                 them)",
                self.out_of_order,
                path.display()
            );
        }
        if self.late > 0 {
            qicp_core::note!(
                "warning: dropped {} laser lines of {} that came more than {} s out of time order",
                self.late,
                path.display(),
                DEFAULT_REORDER_WINDOW
            );
        }
        if let Some(code) = self.no_return_code {
            qicp_core::note!(
                "note: {} readings of the first {} records of {} read {:.2} m, the largest \
                 range, against {:.1} per centimetre in the metre below: a no-return code, \
                 read as no-returns (the maximum range set to {:.3} m; --max-range gives \
                 another)",
                code.count,
                code.records,
                path.display(),
                code.range,
                code.per_cm,
                code.max_range()
            );
        }
        if let Some((range, count, per_cm)) = self.ranges.no_return_code() {
            qicp_core::note!(
                "warning: {count} readings of {} read {range:.2} m, the largest range kept, \
                 against {per_cm:.1} per centimetre in the metre below: a no-return code, \
                 read as points? --max-range {:.3} drops them",
                path.display(),
                just_below(range)
            );
        }
        if !self.unknown_types.is_empty() {
            // Other CARMEN records (SYNC, NMEAGGA, RAWLASER1…) carry nothing qicp reads; a
            // misspelt or damaged tag lands here too, so none is dropped unseen.
            qicp_core::note!(
                "note: ignored records of {} of types qicp does not read: {}",
                path.display(),
                self.unknown_list()
            );
        }
    }
}

/// A log read into memory.
#[derive(Debug, Clone, Default)]
pub struct CarmenLog {
    /// Laser records in the order of [`CarmenOptions::order`] (file order by default).
    pub records: Vec<Record>,
    /// `ODOM` records `(ipc_timestamp, pose)` in time order.
    pub odometry: Vec<(f64, Pose2)>,
    /// `TRUEPOS` records `(ipc_timestamp, true pose)` in time order.
    pub truepos: Vec<(f64, Pose2)>,
    /// Counts, skips and `PARAM`s.
    pub info: LogInfo,
}

impl CarmenLog {
    /// Laser records with ground truth attached.
    #[must_use]
    pub fn records_with_truth(&self) -> usize {
        self.records.iter().filter(|r| r.truth.is_some()).count()
    }

    /// The odometry of the laser records: `(timestamp, robot pose)`, in record order.
    #[must_use]
    pub fn laser_odometry(&self) -> Vec<(f64, Pose2)> {
        self.records
            .iter()
            .map(|r| (r.timestamp(), r.odometry))
            .collect()
    }

    /// The ground truth of the laser records that have one, in record order.
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
        self.info.report()
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

/// How many skipped lines [`LogInfo::skipped_examples`] keeps.
const SKIPPED_EXAMPLES: usize = 10;

/// The `PARAM`s that shape `FLASER` scans.
const FLASER_PARAMS: [&str; 5] = [
    "laser_front_laser_fov",
    "robot_front_laser_max",
    "robot_frontlaser_offset",
    "robot_frontlaser_side_offset",
    "robot_frontlaser_angular_offset",
];

/// Reads a CARMEN log for a command: strict, or with `lenient` skipping malformed lines and
/// warning on stderr how many it skipped. A log without a laser record is an error.
pub fn load_for_command(path: &Path, lenient: bool) -> Result<CarmenLog, LogError> {
    let log = read_carmen(
        path,
        &CarmenOptions {
            lenient,
            ..CarmenOptions::default()
        },
    )?;
    log.info.warn(path);
    if log.records.is_empty() {
        return Err(LogError::empty(path, &log.info));
    }
    Ok(log)
}

/// Reads a whole CARMEN log into memory, plain or bzip2-compressed. To match a long log in
/// bounded memory, iterate a [`CarmenReader`] instead.
pub fn read_carmen(path: &Path, opts: &CarmenOptions) -> Result<CarmenLog, LogError> {
    let (opts, code) = with_no_return_code(path, opts);
    let mut reader = super::open_text(path)?;
    let mut log = read_carmen_from(&mut reader, &path.display().to_string(), &opts)?;
    log.info.no_return_code = code;
    Ok(log)
}

/// Reads a whole CARMEN log from any reader (already decompressed); `name` is used in errors.
pub fn read_carmen_from<R: BufRead + ?Sized>(
    reader: &mut R,
    name: &str,
    opts: &CarmenOptions,
) -> Result<CarmenLog, LogError> {
    let mut stream = CarmenReader::new(reader, name, opts)?;
    stream.keep_side_records = true;
    let mut records = Vec::new();
    for record in &mut stream {
        records.push(record?);
    }
    let mut odometry = std::mem::take(&mut stream.odometry);
    let mut truepos = std::mem::take(&mut stream.all_truepos);
    odometry.sort_by(|a, b| a.0.total_cmp(&b.0));
    truepos.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(CarmenLog {
        records,
        odometry,
        truepos,
        info: stream.info,
    })
}

/// The `FLASER` layout in force: options, else `PARAM`s, else defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
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
                _ => Err(bad_param(name, key, v, "not a finite number")),
            },
        }
    };
    let fov_deg = match opts.flaser_fov_deg {
        Some(f) => f,
        None => {
            let fov = param("laser_front_laser_fov")?.unwrap_or(DEFAULT_FLASER_FOV_DEG);
            if !(fov > 0.0 && fov <= 360.0) {
                let v = &params["laser_front_laser_fov"];
                return Err(bad_param(
                    name,
                    "laser_front_laser_fov",
                    v,
                    "must lie in (0, 360] degrees",
                ));
            }
            fov
        }
    };
    let max_range = match opts.max_range {
        Some(m) => m,
        None => {
            let m = param("robot_front_laser_max")?.unwrap_or(DEFAULT_FLASER_MAX_RANGE);
            if m <= 0.0 {
                let v = &params["robot_front_laser_max"];
                return Err(bad_param(
                    name,
                    "robot_front_laser_max",
                    v,
                    "must be positive",
                ));
            }
            m
        }
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

/// A `PARAM` whose value cannot describe the laser.
fn bad_param(name: &str, key: &str, value: &str, why: &str) -> LogError {
    LogError::Malformed {
        path: name.to_string(),
        line: 0,
        why: format!("PARAM {key} {value}: {why}"),
    }
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
