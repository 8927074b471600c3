//! Laser records from a ROS 2 bag in MCAP storage, streamed: scans from a `LaserScan` topic,
//! the robot's odometry from an `Odometry` topic or from `/tf`, interpolated to each scan's
//! time.

use super::msgs::{self, LaserScan, Odometry, is_type};
use crate::LogError;
use mcap::records::Record as McapRecord;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};
use qicp_core::{BeamGeometry, Pose2, Record, Scan, normalize_angle};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::io::Read;
use std::path::Path;

/// Where the robot's odometry comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OdometrySource {
    /// A `nav_msgs/msg/Odometry` topic (its `child_frame_id` is the robot's frame).
    Topic(String),
    /// The transform `odom_frame` → `base_frame` on `/tf`.
    Tf {
        /// The odometry frame, e.g. `odom`.
        odom_frame: String,
        /// The robot's frame, e.g. `base_link`.
        base_frame: String,
    },
    /// None: every scan is read with the same odometry pose, so that a matcher predicts it at
    /// its last checked velocity (`[matcher.motion] stall_velocity`). The poses are the
    /// laser's own (no robot frame to take an offset to).
    None,
}

impl OdometrySource {
    /// From /tf when an odometry frame is given (to `base_frame`), else from `odom_topic`: the
    /// choice `--odom-topic` / `--odom-frame --base-frame` makes on the command line.
    #[must_use]
    pub fn from_names(odom_topic: &str, odom_frame: Option<&str>, base_frame: &str) -> Self {
        match odom_frame {
            Some(odom_frame) => Self::Tf {
                odom_frame: odom_frame.to_string(),
                base_frame: base_frame.to_string(),
            },
            None => Self::Topic(odom_topic.to_string()),
        }
    }
}

/// How to read a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct BagOptions {
    /// The `sensor_msgs/msg/LaserScan` topic, e.g. `/scan`.
    pub scan_topic: String,
    /// Where odometry comes from.
    pub odometry: OdometrySource,
    /// Beams a scan may have at most; a longer one is an error.
    pub max_beams: usize,
    /// Scans that may wait for the odometry after them at most; more is an error (the
    /// odometry has stopped or lags far behind), so that memory stays bounded.
    pub max_waiting: usize,
}

impl BagOptions {
    /// Scans from `scan_topic`, odometry from `odometry`, the other limits at their defaults.
    #[must_use]
    pub fn new(scan_topic: impl Into<String>, odometry: OdometrySource) -> Self {
        Self {
            scan_topic: scan_topic.into(),
            odometry,
            max_beams: crate::carmen::DEFAULT_MAX_BEAMS,
            max_waiting: crate::carmen::DEFAULT_REORDER_RECORDS,
        }
    }
}

/// What a read met: counts and the topics of the bag.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BagInfo {
    /// Records delivered.
    pub records: usize,
    /// Scans read from the scan topic.
    pub scans: usize,
    /// Odometry samples read.
    pub odometry: usize,
    /// Scans dropped because no odometry surrounds them in time (before the first sample or
    /// after the last).
    pub without_odometry: usize,
    /// Odometry samples dropped because they are older than the one before.
    pub odometry_out_of_order: usize,
    /// Every topic seen, with its message type.
    pub topics: BTreeMap<String, String>,
    /// Pose of the laser on the robot, from `/tf_static` (identity when absent).
    pub laser_offset: Option<Pose2>,
    /// Time of the first and of the last record delivered (s).
    pub span: Option<(f64, f64)>,
}

impl BagInfo {
    /// The topics as `name (type)`, for errors.
    #[must_use]
    pub fn topic_list(&self) -> String {
        if self.topics.is_empty() {
            return "none".into();
        }
        let list: Vec<String> = self
            .topics
            .iter()
            .map(|(t, ty)| format!("{t} ({ty})"))
            .collect();
        list.join(", ")
    }

    /// Warnings a command prints on stderr.
    pub fn warn(&self, path: &Path) {
        if self.without_odometry > 0 {
            qicp_core::note!(
                "warning: dropped {} scans of {} that no odometry surrounds in time",
                self.without_odometry,
                path.display()
            );
        }
        if self.odometry_out_of_order > 0 {
            qicp_core::note!(
                "warning: dropped {} odometry samples of {} older than the one before",
                self.odometry_out_of_order,
                path.display()
            );
        }
    }
}

/// A channel of the bag: its topic and message type.
#[derive(Debug, Clone)]
struct Channel {
    topic: String,
    schema: String,
}

/// The decoding state, apart from the MCAP reader (whose records borrow it).
#[derive(Debug)]
struct State {
    path: String,
    opts: BagOptions,
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Channel>,
    /// Scans waiting for the odometry sample after them.
    waiting: VecDeque<(Scan, String)>,
    /// The last two odometry samples.
    before: Option<(f64, Pose2)>,
    last: Option<(f64, Pose2)>,
    /// The robot's frame (learnt from the odometry), and the static transforms seen.
    base_frame: Option<String>,
    static_tf: HashMap<(String, String), Pose2>,
    ready: VecDeque<Record>,
    info: BagInfo,
}

/// The laser records of a rosbag2 MCAP file, in the order of the bag, one at a time.
///
/// Each scan gets the odometry interpolated at its header stamp between the samples before
/// and after it (exactly a sample's pose when the stamps are equal); scans before the first
/// sample or after the last are dropped and counted. The laser's pose on the robot comes from
/// `/tf_static` (robot frame → the scan's `frame_id`); without it the laser sits at the
/// robot's origin. Memory holds the scans waiting for their odometry, not the bag. After an
/// error the iterator ends.
pub struct BagReader<R> {
    source: R,
    reader: LinearReader,
    state: State,
    done: bool,
}

impl<R> std::fmt::Debug for BagReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagReader")
            .field("state", &self.state)
            .finish_non_exhaustive()
    }
}

impl BagReader<std::io::BufReader<std::fs::File>> {
    /// Opens a bag file.
    pub fn open(path: &Path, opts: &BagOptions) -> Result<Self, LogError> {
        let file = std::fs::File::open(path).map_err(|e| LogError::io(path, e))?;
        Ok(Self::new(
            std::io::BufReader::new(file),
            &path.display().to_string(),
            opts,
        ))
    }
}

/// Whether a file is MCAP (by its magic bytes). Only a regular file is looked into: reading
/// the magic of a pipe (`/dev/stdin`, `<(bzcat log)`) would take its first bytes from the log
/// that follows, so a pipe is never a bag and is read as a CARMEN log, whole.
pub fn is_mcap(path: &Path) -> bool {
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return false;
    }
    let mut magic = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .is_ok_and(|()| magic == *mcap::MAGIC)
}

impl<R: Read> BagReader<R> {
    /// Streams a bag from any reader; `name` is used in errors.
    pub fn new(source: R, name: &str, opts: &BagOptions) -> Self {
        Self {
            source,
            reader: LinearReader::new(),
            state: State {
                path: name.to_string(),
                opts: opts.clone(),
                schemas: HashMap::new(),
                channels: HashMap::new(),
                waiting: VecDeque::new(),
                before: None,
                last: None,
                base_frame: match &opts.odometry {
                    OdometrySource::Tf { base_frame, .. } => Some(strip(base_frame).to_string()),
                    OdometrySource::Topic(_) | OdometrySource::None => None,
                },
                static_tf: HashMap::new(),
                ready: VecDeque::new(),
                info: BagInfo::default(),
            },
            done: false,
        }
    }

    /// Counts and topics so far.
    #[must_use]
    pub fn info(&self) -> &BagInfo {
        &self.state.info
    }

    fn fail(&mut self, why: String) -> Option<Result<Record, LogError>> {
        self.done = true;
        Some(Err(self.state.error(why)))
    }

    /// The checks at the end of the bag: the topics asked for exist and gave records.
    fn finish(&mut self) -> Option<Result<Record, LogError>> {
        self.done = true;
        let s = &mut self.state;
        s.info.without_odometry += s.waiting.len();
        s.waiting.clear();
        let scan_type = s.info.topics.get(&s.opts.scan_topic).cloned();
        let why = match scan_type {
            None => format!(
                "no topic {}; the bag has: {}",
                s.opts.scan_topic,
                s.info.topic_list()
            ),
            Some(ty) if !is_type(&ty, msgs::LASER_SCAN) => format!(
                "topic {} carries {ty}, not {}",
                s.opts.scan_topic,
                msgs::LASER_SCAN
            ),
            Some(_) if s.info.records > 0 => return None,
            Some(_) if s.info.scans == 0 => format!("no scans on {}", s.opts.scan_topic),
            Some(_) => s.no_odometry(),
        };
        Some(Err(s.error(why)))
    }
}

impl<R: Read> Iterator for BagReader<R> {
    type Item = Result<Record, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(record) = self.state.ready.pop_front() {
                self.state.info.records += 1;
                let t = record.timestamp();
                let span = self.state.info.span.get_or_insert((t, t));
                span.1 = t;
                return Some(Ok(record));
            }
            if self.done {
                return None;
            }
            let event = match self.reader.next_event() {
                None => return self.finish(),
                Some(Err(e)) => {
                    let why = format!("not a readable MCAP file: {e}");
                    return self.fail(why);
                }
                Some(Ok(event)) => event,
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    match self.source.read(self.reader.insert(need)) {
                        Ok(n) => self.reader.notify_read(n),
                        Err(e) => {
                            let why = format!("reading: {e}");
                            return self.fail(why);
                        }
                    }
                }
                LinearReadEvent::Record { opcode, data } => {
                    let result = match mcap::parse_record(opcode, data) {
                        Ok(record) => self.state.on_record(record),
                        Err(e) => Err(format!("a malformed MCAP record: {e}")),
                    };
                    if let Err(why) = result {
                        return self.fail(why);
                    }
                }
            }
        }
    }
}

/// A frame name without its leading `/` (ROS 1 style names still appear in bags).
fn strip(frame: &str) -> &str {
    frame.strip_prefix('/').unwrap_or(frame)
}

/// The pose at `t` between two samples: linear in position, along the shorter arc in heading.
fn interpolate((t0, p0): (f64, Pose2), (t1, p1): (f64, Pose2), t: f64) -> Pose2 {
    if t == t1 {
        return p1;
    }
    if t == t0 || t1 <= t0 {
        return p0;
    }
    let f = (t - t0) / (t1 - t0);
    Pose2::new(
        p0.x + (p1.x - p0.x) * f,
        p0.y + (p1.y - p0.y) * f,
        normalize_angle(p0.theta + normalize_angle(p1.theta - p0.theta) * f),
    )
}

impl State {
    /// Why the scans have no odometry.
    fn no_odometry(&self) -> String {
        let i = &self.info;
        match &self.opts.odometry {
            OdometrySource::Topic(topic) if i.odometry == 0 => format!(
                "{} scans but no odometry topic {topic}; the bag has: {}",
                i.scans,
                i.topic_list()
            ),
            OdometrySource::Tf {
                odom_frame,
                base_frame,
            } if i.odometry == 0 => format!(
                "{} scans but no transform {odom_frame} -> {base_frame} on /tf; the bag has: {}",
                i.scans,
                i.topic_list()
            ),
            _ => format!(
                "{} scans, {} odometry samples, but no scan lies between two samples: scans \
                 without odometry",
                i.scans, i.odometry
            ),
        }
    }

    fn error(&self, why: String) -> LogError {
        LogError::Bag {
            path: self.path.clone(),
            why,
        }
    }

    fn on_record(&mut self, record: McapRecord<'_>) -> Result<(), String> {
        match record {
            McapRecord::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
            }
            McapRecord::Channel(c) => {
                let schema = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                self.info.topics.insert(c.topic.clone(), schema.clone());
                if c.message_encoding != "cdr" && self.wanted(&c.topic) {
                    return Err(format!(
                        "topic {} is encoded as {:?}; qicp reads ROS 2 bags (cdr)",
                        c.topic, c.message_encoding
                    ));
                }
                self.channels.insert(
                    c.id,
                    Channel {
                        topic: c.topic,
                        schema,
                    },
                );
            }
            McapRecord::Message { header, data } => {
                let Some(channel) = self.channels.get(&header.channel_id).cloned() else {
                    return Err(format!(
                        "a message on channel {} before its Channel record",
                        header.channel_id
                    ));
                };
                self.on_message(&channel, &data)?;
            }
            _ => {}
        }
        Ok(())
    }

    fn wanted(&self, topic: &str) -> bool {
        topic == self.opts.scan_topic
            || topic == "/tf"
            || topic == "/tf_static"
            || matches!(&self.opts.odometry, OdometrySource::Topic(t) if t == topic)
    }

    fn expect(&self, channel: &Channel, ty: &str) -> Result<(), String> {
        if is_type(&channel.schema, ty) {
            Ok(())
        } else {
            Err(format!(
                "topic {} carries {}, not {ty}",
                channel.topic,
                if channel.schema.is_empty() {
                    "messages without a schema"
                } else {
                    &channel.schema
                }
            ))
        }
    }

    fn on_message(&mut self, channel: &Channel, data: &[u8]) -> Result<(), String> {
        let topic = channel.topic.as_str();
        if topic == self.opts.scan_topic {
            self.expect(channel, msgs::LASER_SCAN)?;
            let scan = LaserScan::decode(data)
                .map_err(|e| format!("scan {} on {topic}: {e}", self.info.scans + 1))?;
            self.info.scans += 1;
            return self.on_scan(scan);
        }
        match &self.opts.odometry {
            OdometrySource::Topic(t) if t == topic => {
                self.expect(channel, msgs::ODOMETRY)?;
                let odom =
                    Odometry::decode(data).map_err(|e| format!("odometry on {topic}: {e}"))?;
                if self.base_frame.is_none() {
                    self.base_frame = Some(strip(&odom.child_frame_id).to_string());
                }
                self.on_odometry(odom.stamp, odom.pose)?;
            }
            _ if topic == "/tf" || topic == "/tf_static" => {
                self.expect(channel, msgs::TF_MESSAGE)?;
                let transforms =
                    msgs::decode_tf(data).map_err(|e| format!("transform on {topic}: {e}"))?;
                for tf in transforms {
                    let (parent, child) = (strip(&tf.parent), strip(&tf.child));
                    if let OdometrySource::Tf {
                        odom_frame,
                        base_frame,
                    } = &self.opts.odometry
                        && topic == "/tf"
                        && parent == strip(odom_frame)
                        && child == strip(base_frame)
                    {
                        self.on_odometry(tf.stamp, tf.pose)?;
                    } else if topic == "/tf_static" {
                        self.static_tf
                            .insert((parent.to_string(), child.to_string()), tf.pose);
                    }
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn on_scan(&mut self, msg: LaserScan) -> Result<(), String> {
        let n = self.info.scans;
        if msg.ranges.len() > self.opts.max_beams {
            return Err(format!(
                "scan {n} has {} beams, more than --max-beams {}",
                msg.ranges.len(),
                self.opts.max_beams
            ));
        }
        let geometry = BeamGeometry {
            angle_min: f64::from(msg.angle_min),
            angle_increment: f64::from(msg.angle_increment),
            max_range: f64::from(msg.range_max),
            min_range: f64::from(msg.range_min),
        };
        let ranges = msg.ranges.iter().map(|&r| f64::from(r)).collect();
        let scan = Scan::new(msg.stamp, geometry, ranges).map_err(|e| format!("scan {n}: {e}"))?;
        if matches!(self.opts.odometry, OdometrySource::None) {
            self.emit(scan, &msg.frame_id, Pose2::IDENTITY);
            return Ok(());
        }
        match self.last {
            Some((t, pose)) if t == msg.stamp => self.emit(scan, &msg.frame_id, pose),
            Some((t, _)) if t > msg.stamp => {
                // Odometry is already past this scan: interpolate with the sample before.
                match self.before {
                    Some(b) if b.0 <= msg.stamp => {
                        let pose = interpolate(b, (t, self.last_pose()), msg.stamp);
                        self.emit(scan, &msg.frame_id, pose);
                    }
                    _ => self.info.without_odometry += 1,
                }
            }
            _ => {
                if self.waiting.len() >= self.opts.max_waiting && self.info.odometry == 0 {
                    return Err(self.no_odometry());
                }
                if self.waiting.len() >= self.opts.max_waiting {
                    return Err(format!(
                        "{} scans on {} wait for odometry after them: the odometry has \
                         stopped or lags far behind (scans without odometry)",
                        self.waiting.len(),
                        self.opts.scan_topic
                    ));
                }
                self.waiting.push_back((scan, msg.frame_id));
            }
        }
        Ok(())
    }

    fn last_pose(&self) -> Pose2 {
        self.last.map_or(Pose2::IDENTITY, |l| l.1)
    }

    fn on_odometry(&mut self, t: f64, pose: Pose2) -> Result<(), String> {
        if !(t.is_finite() && pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
            return Err(format!("odometry sample at {t} s is not finite"));
        }
        if self.last.is_some_and(|(l, _)| t < l) {
            self.info.odometry_out_of_order += 1;
            return Ok(());
        }
        self.info.odometry += 1;
        self.before = self.last;
        self.last = Some((t, pose));
        while let Some((scan, _)) = self.waiting.front() {
            let ts = scan.timestamp;
            if ts > t {
                break;
            }
            let Some((scan, frame)) = self.waiting.pop_front() else {
                break;
            };
            match self.before {
                Some(b) if b.0 <= ts => {
                    let p = interpolate(b, (t, pose), ts);
                    self.emit(scan, &frame, p);
                }
                _ if ts == t => self.emit(scan, &frame, pose),
                _ => self.info.without_odometry += 1,
            }
        }
        Ok(())
    }

    fn emit(&mut self, scan: Scan, frame: &str, odometry: Pose2) {
        let frame = strip(frame);
        let laser_offset = match &self.base_frame {
            Some(base) if base != frame => self
                .static_tf
                .get(&(base.clone(), frame.to_string()))
                .copied(),
            _ => Some(Pose2::IDENTITY),
        };
        if self.info.laser_offset.is_none() {
            self.info.laser_offset = laser_offset;
        }
        self.ready.push_back(Record {
            scan,
            odometry,
            truth: None,
            laser_offset: laser_offset.unwrap_or(Pose2::IDENTITY),
        });
    }
}
