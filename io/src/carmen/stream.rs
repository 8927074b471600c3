//! [`CarmenReader`]: a CARMEN log streamed record by record, in file order or (sorted by time)
//! through a bounded reorder window.

use super::RecordOrder;
use super::fields::{
    Layout, Parsed, RawLaser, parse_flaser, parse_odom, parse_param, parse_robotlaser1,
    parse_truepos,
};
use super::{
    CarmenOptions, FLASER_PARAMS, FlaserSettings, LogInfo, SKIPPED_EXAMPLES, flaser_geometry,
    flaser_settings, nearest,
};
use crate::{LogError, next_line};
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::io::BufRead;
use std::path::Path;

/// A laser record waiting in the buffer, ordered by `key` (its time, or 0 in file order) and
/// then by line.
struct Pending {
    key: f64,
    timestamp: f64,
    line: usize,
    record: Record,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other).is_eq()
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key
            .total_cmp(&other.key)
            .then(self.line.cmp(&other.line))
    }
}

/// Streams the laser records of a CARMEN log in the order of [`CarmenOptions::order`] (file
/// order by default), one at a time, in memory bounded by the reorder window (not by the log's
/// length).
///
/// Records wait in a buffer of [`CarmenOptions::reorder_window`] seconds or
/// [`CarmenOptions::reorder_records`] records, whichever fills first, for the `TRUEPOS` lines
/// that attach to the laser record nearest in time within [`CarmenOptions::truepos_max_dt`].
/// With [`RecordOrder::Time`] laser lines out of time order (Intel's jitter by up to 0.6 s)
/// are put back in order within that buffer, by time with ties in file order, and a line
/// later than that is dropped and counted in [`LogInfo::late`]; in file order none is.
/// `PARAM`s that shape `FLASER` scans must come before the first `FLASER` line or repeat
/// their values; a later change is an error, as the scans before it would have been read with
/// another layout.
///
/// After an error the iterator ends.
pub struct CarmenReader<R> {
    reader: R,
    name: String,
    opts: CarmenOptions,
    /// Counts, skips and `PARAM`s so far.
    pub info: LogInfo,
    buf: Vec<u8>,
    line_no: usize,
    pending: BinaryHeap<Reverse<Pending>>,
    /// `TRUEPOS` lines not yet too old for the next record, in time order.
    truepos: Vec<(f64, Pose2)>,
    /// Latest timestamp of a laser or `TRUEPOS` line read.
    newest: f64,
    /// Timestamp of the last record delivered.
    delivered: f64,
    last_laser_time: f64,
    /// The `FLASER` layout, fixed by the first `FLASER` line.
    flaser: Option<FlaserSettings>,
    done: bool,
    /// Whether to keep every `ODOM` and `TRUEPOS` line ([`read_carmen`] does).
    pub(super) keep_side_records: bool,
    pub(super) odometry: Vec<(f64, Pose2)>,
    pub(super) all_truepos: Vec<(f64, Pose2)>,
}

impl<R> std::fmt::Debug for CarmenReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CarmenReader")
            .field("name", &self.name)
            .field("line", &self.line_no)
            .field("pending", &self.pending.len())
            .field("truepos", &self.truepos.len())
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl CarmenReader<Box<dyn BufRead + Send>> {
    /// Opens a CARMEN log, plain or bzip2-compressed.
    ///
    /// Where neither `opts` nor the log gives a maximum range (`FLASER` lines with no `PARAM
    /// robot_front_laser_max`), the head of a regular file is read first for a no-return code
    /// below the guessed 81 m ([`super::no_return_probe`]); one found is read as no-returns,
    /// and [`LogInfo::no_return_code`] says so.
    pub fn open(path: &Path, opts: &CarmenOptions) -> Result<Self, LogError> {
        let (opts, code) = super::with_no_return_code(path, opts);
        let reader = crate::open_text(path)?;
        let mut stream = Self::new(reader, &path.display().to_string(), &opts)?;
        stream.info.no_return_code = code;
        Ok(stream)
    }

    /// Opens a CARMEN log as [`CarmenReader::open`] does, without the probe: as `opts` and
    /// the log say.
    pub(super) fn open_as_given(path: &Path, opts: &CarmenOptions) -> Result<Self, LogError> {
        let reader = crate::open_text(path)?;
        Self::new(reader, &path.display().to_string(), opts)
    }
}

impl<R: BufRead> CarmenReader<R> {
    /// Streams a log from any reader (already decompressed); `name` is used in errors.
    pub fn new(reader: R, name: &str, opts: &CarmenOptions) -> Result<Self, LogError> {
        opts.validate()?;
        Ok(Self {
            reader,
            name: name.to_string(),
            opts: opts.clone(),
            info: LogInfo {
                order: opts.order,
                ..LogInfo::default()
            },
            buf: Vec::with_capacity(4096),
            line_no: 0,
            pending: BinaryHeap::new(),
            truepos: Vec::new(),
            newest: f64::NEG_INFINITY,
            delivered: f64::NEG_INFINITY,
            last_laser_time: f64::NEG_INFINITY,
            flaser: None,
            done: false,
            keep_side_records: false,
            odometry: Vec::new(),
            all_truepos: Vec::new(),
        })
    }

    /// Counts a malformed line, or fails with it when strict.
    fn skip(&mut self, err: LogError) -> Result<(), LogError> {
        if !self.opts.lenient {
            return Err(err);
        }
        self.info.skipped_lines += 1;
        if self.info.skipped_examples.len() < SKIPPED_EXAMPLES {
            self.info.skipped_examples.push(err.to_string());
        }
        Ok(())
    }

    /// Reads lines until one laser record is buffered or the input ends; `false` at the end.
    fn read_some(&mut self) -> Result<bool, LogError> {
        loop {
            let more = next_line(&mut self.reader, &mut self.buf).map_err(|e| LogError::Io {
                path: self.name.clone(),
                cause: e,
            })?;
            if !more {
                return Ok(false);
            }
            self.line_no += 1;
            if self.buf.contains(&b'\r') {
                // A CR-only file reads as one huge line; say so rather than find no records.
                let err = LogError::malformed(
                    &self.name,
                    self.line_no,
                    "carriage return inside a line (CR-only line endings?); convert them to LF",
                );
                self.skip(err)?;
                continue;
            }
            let Ok(line) = std::str::from_utf8(&self.buf) else {
                let err = LogError::malformed(&self.name, self.line_no, "not UTF-8 text");
                self.skip(err)?;
                continue;
            };
            let line = if self.line_no == 1 {
                crate::without_bom(line)
            } else {
                line
            };
            let mut tokens = line.split_ascii_whitespace();
            let Some(kind) = tokens.next() else { continue };
            if kind.starts_with('#') {
                continue;
            }
            let kind = kind.to_string();
            let fields: Vec<&str> = tokens.collect();
            let max_beams = self.opts.max_beams;
            let parsed = match kind.as_str() {
                "FLASER" => parse_flaser(&fields, self.line_no, max_beams).map(Parsed::Laser),
                "ROBOTLASER1" => {
                    parse_robotlaser1(&fields, self.line_no, max_beams).map(Parsed::Laser)
                }
                "ODOM" => parse_odom(&fields).map(Parsed::Odom),
                "TRUEPOS" => parse_truepos(&fields).map(Parsed::TruePos),
                "PARAM" => parse_param(&fields).map(Parsed::Param),
                other => {
                    *self
                        .info
                        .unknown_types
                        .entry(other.to_string())
                        .or_insert(0) += 1;
                    continue;
                }
            };
            let parsed = match parsed {
                Ok(p) => p,
                Err(why) => {
                    let err =
                        LogError::malformed(&self.name, self.line_no, format!("{kind}: {why}"));
                    self.skip(err)?;
                    continue;
                }
            };
            *self.info.counts.entry(kind).or_insert(0) += 1;
            match parsed {
                Parsed::Laser(raw) => {
                    if self.push_laser(raw)? {
                        return Ok(true);
                    }
                }
                Parsed::Odom(o) => {
                    if self.keep_side_records {
                        self.odometry.push(o);
                    }
                }
                Parsed::TruePos(t) => {
                    self.newest = self.newest.max(t.0);
                    let at = self.truepos.partition_point(|(s, _)| *s <= t.0);
                    self.truepos.insert(at, t);
                    // Bounded even without laser lines: a record older than the window
                    // behind the newest line comes too late for its truth to matter here.
                    let horizon = self.newest - self.opts.reorder_window - self.opts.truepos_max_dt;
                    let old = self.truepos.partition_point(|(s, _)| *s < horizon);
                    self.truepos.drain(..old);
                    if self.keep_side_records {
                        self.all_truepos.push(t);
                    }
                }
                Parsed::Param((k, v)) => self.set_param(k, v)?,
            }
        }
    }

    /// A `PARAM` line: kept, and checked against the `FLASER` layout already in use.
    fn set_param(&mut self, key: String, value: String) -> Result<(), LogError> {
        let shapes = FLASER_PARAMS.contains(&key.as_str());
        self.info.params.insert(key.clone(), value.clone());
        let Some(in_use) = self.flaser else {
            return Ok(());
        };
        if !shapes {
            return Ok(());
        }
        let now = flaser_settings(&self.info.params, &self.opts, &self.name)?;
        if now != in_use {
            return Err(LogError::malformed(
                &self.name,
                self.line_no,
                format!(
                    "PARAM {key} {value} changes the FLASER layout after FLASER lines were read \
                     with another; CARMEN logs give their PARAMs before the first laser line"
                ),
            ));
        }
        Ok(())
    }

    /// Turns a parsed laser line into a record and buffers it; `false` if it was skipped.
    fn push_laser(&mut self, l: RawLaser) -> Result<bool, LogError> {
        if l.timestamp < self.last_laser_time {
            self.info.out_of_order += 1;
        }
        self.last_laser_time = l.timestamp;
        let by_time = self.opts.order == RecordOrder::Time;
        if by_time && l.timestamp < self.delivered {
            self.info.late += 1;
            return Ok(false);
        }
        let (geometry, laser_offset) = match l.layout {
            Layout::Flaser => {
                let flaser = match self.flaser {
                    Some(f) => f,
                    None => {
                        let f = flaser_settings(&self.info.params, &self.opts, &self.name)?;
                        self.flaser = Some(f);
                        f
                    }
                };
                (
                    flaser_geometry(
                        l.ranges.len(),
                        flaser.fov,
                        flaser.max_range,
                        self.opts.min_range,
                    ),
                    flaser.offset,
                )
            }
            Layout::Robot {
                angle_min,
                angle_increment,
                max_range,
                laser_offset,
            } => (
                BeamGeometry {
                    angle_min,
                    angle_increment,
                    max_range: self.opts.max_range.unwrap_or(max_range),
                    min_range: self.opts.min_range,
                },
                laser_offset,
            ),
        };
        match Scan::new(l.timestamp, geometry, l.ranges) {
            Ok(scan) => {
                self.newest = self.newest.max(l.timestamp);
                self.pending.push(Reverse(Pending {
                    key: if by_time { l.timestamp } else { 0.0 },
                    timestamp: l.timestamp,
                    line: l.line,
                    record: Record {
                        scan,
                        odometry: l.odometry,
                        truth: None,
                        laser_offset,
                    },
                }));
                Ok(true)
            }
            Err(e) => {
                self.skip(LogError::malformed(&self.name, l.line, e.to_string()))?;
                Ok(false)
            }
        }
    }

    /// Whether the first buffered record can go: in time order nothing earlier can come any
    /// more, and no `TRUEPOS` line near it.
    fn ready(&self) -> bool {
        self.pending.peek().is_some_and(|Reverse(p)| {
            self.done
                || self.newest - p.timestamp > self.opts.reorder_window
                || self.pending.len() > self.opts.reorder_records
        })
    }

    /// Delivers the first buffered record with its ground truth.
    fn deliver(&mut self) -> Option<Record> {
        let Reverse(p) = self.pending.pop()?;
        let mut record = p.record;
        let t = p.timestamp;
        let max_dt = self.opts.truepos_max_dt;
        record.truth = nearest(&self.truepos, t, max_dt).map(|(_, pose)| pose);
        if self.opts.order == RecordOrder::Time {
            // Later records are no earlier than t: what lies beyond max_dt before it is done
            // with. (In file order the window's horizon, as each TRUEPOS line arrives, bounds
            // what is kept.)
            let old = self.truepos.partition_point(|(s, _)| *s < t - max_dt);
            self.truepos.drain(..old);
        }
        self.delivered = t;
        self.info.records += 1;
        self.info.ranges.add(&record.scan);
        self.info.span = Some(match self.info.span {
            None => {
                self.info.first_beams = record.scan.beams();
                (t, t)
            }
            Some((first, last)) => (first.min(t), last.max(t)),
        });
        Some(record)
    }
}

impl<R: BufRead> Iterator for CarmenReader<R> {
    type Item = Result<Record, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.ready() {
            if self.done {
                return None;
            }
            match self.read_some() {
                Ok(true) => {}
                Ok(false) => self.done = true,
                Err(e) => {
                    self.done = true;
                    self.pending.clear();
                    return Some(Err(e));
                }
            }
        }
        self.deliver().map(Ok)
    }
}
