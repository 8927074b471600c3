//! Writing laser records and poses as a ROS 2 bag in MCAP storage (CDR messages with their
//! `ros2msg` schemas), for Foxglove, RViz and `ros2 bag play`.

use super::msgs::{self, LaserScan, Odometry, Transform, nanos};
use crate::LogError;
use mcap::records::MessageHeader;
use qicp_core::{Pose2, Record};
use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::path::Path;

/// Topic and frame names of a written bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagLayout {
    /// The `LaserScan` topic. Default `/scan`.
    pub scan_topic: String,
    /// The odometry `Odometry` topic. Default `/odom`.
    pub odom_topic: String,
    /// The laser's frame. Default `laser`.
    pub laser_frame: String,
    /// The odometry frame. Default `odom`.
    pub odom_frame: String,
    /// The robot's frame. Default `base_link`.
    pub base_frame: String,
    /// The frame of estimated poses. Default `map`.
    pub map_frame: String,
    /// The topic of estimated poses (`Odometry` in `map_frame`). Default `/qicp/odom`.
    pub estimate_topic: String,
}

impl Default for BagLayout {
    fn default() -> Self {
        Self {
            scan_topic: "/scan".into(),
            odom_topic: "/odom".into(),
            laser_frame: "laser".into(),
            odom_frame: "odom".into(),
            base_frame: "base_link".into(),
            map_frame: "map".into(),
            estimate_topic: "/qicp/odom".into(),
        }
    }
}

/// Writes records (scans with their odometry) and estimated poses as a rosbag2 MCAP file.
///
/// Per record: the scan on the scan topic, its odometry on the odometry topic and as the
/// `/tf` transform odom → base_link, and the laser's pose on the robot once on `/tf_static`.
/// Per estimate: an `Odometry` in the map frame on the estimate topic and the `/tf` transform
/// map → odom that puts the robot at the estimate, as a SLAM node publishes it.
pub struct BagWriter<W: Write + Seek> {
    path: String,
    writer: mcap::Writer<W>,
    layout: BagLayout,
    channels: BTreeMap<&'static str, u16>,
    static_written: bool,
    sequence: u32,
}

impl<W: Write + Seek> std::fmt::Debug for BagWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter")
            .field("path", &self.path)
            .field("layout", &self.layout)
            .finish_non_exhaustive()
    }
}

impl BagWriter<std::io::BufWriter<std::fs::File>> {
    /// Creates (or truncates) a bag file.
    pub fn create(path: &Path, layout: BagLayout) -> Result<Self, LogError> {
        let file = std::fs::File::create(path).map_err(|e| LogError::io(path, e))?;
        Self::new(
            std::io::BufWriter::new(file),
            &path.display().to_string(),
            layout,
        )
    }
}

/// Seconds a ROS 2 stamp (`builtin_interfaces/Time`, int32 seconds) holds at most.
const MAX_STAMP_S: f64 = 2_147_483_648.0;

impl<W: Write + Seek> BagWriter<W> {
    /// A bag written to `w`; `name` is used in errors.
    pub fn new(w: W, name: &str, layout: BagLayout) -> Result<Self, LogError> {
        let err = |e: mcap::McapError| LogError::Bag {
            path: name.to_string(),
            why: format!("writing: {e}"),
        };
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .create(w)
            .map_err(err)?;
        Ok(Self {
            path: name.to_string(),
            writer,
            layout,
            channels: BTreeMap::new(),
            static_written: false,
            sequence: 0,
        })
    }

    fn error(&self, e: &mcap::McapError) -> LogError {
        LogError::Bag {
            path: self.path.clone(),
            why: format!("writing: {e}"),
        }
    }

    /// The channel of `key`, added with its schema when first used.
    fn channel(&mut self, key: &'static str) -> Result<u16, LogError> {
        if let Some(&id) = self.channels.get(key) {
            return Ok(id);
        }
        let l = &self.layout;
        let (topic, ty) = match key {
            "scan" => (l.scan_topic.as_str(), msgs::LASER_SCAN),
            "odom" => (l.odom_topic.as_str(), msgs::ODOMETRY),
            "estimate" => (l.estimate_topic.as_str(), msgs::ODOMETRY),
            "tf_static" => ("/tf_static", msgs::TF_MESSAGE),
            _ => ("/tf", msgs::TF_MESSAGE),
        };
        let topic = topic.to_string();
        let schema = self
            .writer
            .add_schema(ty, "ros2msg", msgs::schema_text(ty).as_bytes())
            .map_err(|e| self.error(&e))?;
        let mut metadata = BTreeMap::new();
        if key == "tf_static" {
            // What rosbag2 records for a latched topic, so that players deliver it late.
            metadata.insert(
                "offered_qos_profiles".to_string(),
                "- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n".to_string(),
            );
        }
        let id = self
            .writer
            .add_channel(schema, &topic, "cdr", &metadata)
            .map_err(|e| self.error(&e))?;
        self.channels.insert(key, id);
        Ok(id)
    }

    fn put(&mut self, key: &'static str, t: f64, data: &[u8]) -> Result<(), LogError> {
        // A ROS 2 stamp's seconds are an int32 and an MCAP log time unsigned nanoseconds: a
        // time outside both would be clamped into a wrong stamp.
        if !(0.0..MAX_STAMP_S).contains(&t) {
            return Err(LogError::Bag {
                path: self.path.clone(),
                why: format!(
                    "a record at t = {t:e} s: a ROS 2 stamp holds times in [0, {MAX_STAMP_S}) s (until \
                     2038-01-19)"
                ),
            });
        }
        let channel_id = self.channel(key)?;
        self.sequence = self.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: nanos(t),
            publish_time: nanos(t),
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.error(&e))
    }

    fn tf(&self, t: f64, parent: &str, child: &str, pose: Pose2) -> Vec<u8> {
        msgs::encode_tf(&[Transform {
            stamp: t,
            parent: parent.to_string(),
            child: child.to_string(),
            pose,
        }])
    }

    /// Writes a record: its scan (ranges as float32), its odometry, and the laser's pose on
    /// the robot (once).
    pub fn record(&mut self, record: &Record) -> Result<(), LogError> {
        let t = record.timestamp();
        let l = self.layout.clone();
        if !self.static_written {
            let data = self.tf(t, &l.base_frame, &l.laser_frame, record.laser_offset);
            self.put("tf_static", t, &data)?;
            self.static_written = true;
        }
        let g = &record.scan.geometry;
        let beams = record.scan.beams();
        let scan = LaserScan {
            stamp: t,
            frame_id: l.laser_frame.clone(),
            angle_min: g.angle_min as f32,
            angle_max: g.angle(beams.saturating_sub(1)) as f32,
            angle_increment: g.angle_increment as f32,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: g.min_range as f32,
            range_max: g.max_range as f32,
            ranges: record.scan.ranges().iter().map(|&r| r as f32).collect(),
            intensities: Vec::new(),
        };
        self.put("scan", t, &scan.encode())?;
        let odom = Odometry {
            stamp: t,
            frame_id: l.odom_frame.clone(),
            child_frame_id: l.base_frame.clone(),
            pose: record.odometry,
        };
        self.put("odom", t, &odom.encode())?;
        let data = self.tf(t, &l.odom_frame, &l.base_frame, record.odometry);
        self.put("tf", t, &data)
    }

    /// Writes the estimated robot pose at `t`, given the odometry at the same time.
    pub fn estimate(&mut self, t: f64, pose: Pose2, odometry: Pose2) -> Result<(), LogError> {
        let l = self.layout.clone();
        let odom = Odometry {
            stamp: t,
            frame_id: l.map_frame.clone(),
            child_frame_id: l.base_frame.clone(),
            pose,
        };
        self.put("estimate", t, &odom.encode())?;
        let correction = pose.compose(&odometry.inverse());
        let data = self.tf(t, &l.map_frame, &l.odom_frame, correction);
        self.put("tf", t, &data)
    }

    /// Writes the summary and flushes; the bag is complete only after this. Gives back the
    /// writer it wrote to.
    pub fn finish(mut self) -> Result<W, LogError> {
        self.writer.finish().map_err(|e| self.error(&e))?;
        Ok(self.writer.into_inner())
    }
}
