//! The few ROS 2 messages qicp reads and writes, decoded from and encoded to CDR by hand:
//! `sensor_msgs/msg/LaserScan`, `nav_msgs/msg/Odometry` and `tf2_msgs/msg/TFMessage`. Poses
//! are planar: x, y and the yaw of the quaternion; z, roll, pitch and twists are not used.

use super::cdr::{CdrError, CdrReader, CdrWriter};
use qicp_core::{Pose2, normalize_angle};

/// `sensor_msgs/msg/LaserScan`.
pub const LASER_SCAN: &str = "sensor_msgs/msg/LaserScan";
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// `tf2_msgs/msg/TFMessage` (on `/tf` and `/tf_static`).
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";

/// Whether a schema name is `full` (`pkg/msg/Type`), also in ROS 1's `pkg/Type` spelling.
#[must_use]
pub fn is_type(schema: &str, full: &str) -> bool {
    schema == full || schema == full.replacen("/msg/", "/", 1)
}

/// A `builtin_interfaces/Time` as seconds.
fn read_stamp(r: &mut CdrReader<'_>) -> Result<f64, CdrError> {
    let sec = r.i32("header.stamp.sec")?;
    let nanosec = r.u32("header.stamp.nanosec")?;
    Ok(f64::from(sec) + f64::from(nanosec) * 1e-9)
}

/// Seconds as a `builtin_interfaces/Time` (nanoseconds rounded; clamped to its range).
fn write_stamp(w: &mut CdrWriter, t: f64) {
    let (sec, nanosec) = stamp_parts(t);
    w.i32(sec);
    w.u32(nanosec);
}

/// Seconds and nanoseconds of a time (s), rounded to the nanosecond.
#[must_use]
pub fn stamp_parts(t: f64) -> (i32, u32) {
    let sec = t.floor();
    let mut nanosec = ((t - sec) * 1e9).round();
    let mut sec = sec;
    if nanosec >= 1e9 {
        sec += 1.0;
        nanosec -= 1e9;
    }
    (sec as i32, nanosec as u32)
}

/// Nanoseconds since the epoch, as MCAP's log times count (0 for negative or non-finite times).
#[must_use]
pub fn nanos(t: f64) -> u64 {
    let (sec, nanosec) = stamp_parts(t.max(0.0));
    u64::try_from(sec).unwrap_or(0) * 1_000_000_000 + u64::from(nanosec)
}

fn read_header(r: &mut CdrReader<'_>) -> Result<(f64, String), CdrError> {
    let stamp = read_stamp(r)?;
    let frame = r.string("header.frame_id")?;
    Ok((stamp, frame))
}

fn write_header(w: &mut CdrWriter, t: f64, frame: &str) {
    write_stamp(w, t);
    w.string(frame);
}

/// The heading of a quaternion (x, y, z, w): its rotation about z.
fn yaw(x: f64, y: f64, z: f64, w: f64) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// A planar pose from a position and an orientation.
fn read_pose(r: &mut CdrReader<'_>, what: &str) -> Result<Pose2, CdrError> {
    let x = r.f64(what)?;
    let y = r.f64(what)?;
    let _z = r.f64(what)?;
    let (qx, qy, qz, qw) = (r.f64(what)?, r.f64(what)?, r.f64(what)?, r.f64(what)?);
    Ok(Pose2::new(x, y, normalize_angle(yaw(qx, qy, qz, qw))))
}

fn write_pose(w: &mut CdrWriter, p: &Pose2) {
    let (qz, qw) = (p.theta / 2.0).sin_cos();
    for v in [p.x, p.y, 0.0, 0.0, 0.0, qz, qw] {
        w.f64(v);
    }
}

/// `sensor_msgs/msg/LaserScan`.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Time of the first beam (s).
    pub stamp: f64,
    /// The laser's frame.
    pub frame_id: String,
    /// Bearing of the first beam (rad).
    pub angle_min: f32,
    /// Bearing of the last beam (rad).
    pub angle_max: f32,
    /// Step between beams (rad).
    pub angle_increment: f32,
    /// Time between beams (s).
    pub time_increment: f32,
    /// Time between scans (s).
    pub scan_time: f32,
    /// Readings below this are invalid (m).
    pub range_min: f32,
    /// Readings above this are invalid (m).
    pub range_max: f32,
    /// Ranges (m).
    pub ranges: Vec<f32>,
    /// Intensities (device units), possibly empty.
    pub intensities: Vec<f32>,
}

impl LaserScan {
    /// Decodes a CDR message.
    pub fn decode(message: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(message)?;
        let (stamp, frame_id) = read_header(&mut r)?;
        Ok(Self {
            stamp,
            frame_id,
            angle_min: r.f32("angle_min")?,
            angle_max: r.f32("angle_max")?,
            angle_increment: r.f32("angle_increment")?,
            time_increment: r.f32("time_increment")?,
            scan_time: r.f32("scan_time")?,
            range_min: r.f32("range_min")?,
            range_max: r.f32("range_max")?,
            ranges: r.f32_seq("ranges")?,
            intensities: r.f32_seq("intensities")?,
        })
    }

    /// Encodes as a CDR message.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut w = CdrWriter::default();
        write_header(&mut w, self.stamp, &self.frame_id);
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(v);
        }
        w.f32_seq(&self.ranges);
        w.f32_seq(&self.intensities);
        w.finish()
    }
}

/// `nav_msgs/msg/Odometry`, planar.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Time (s).
    pub stamp: f64,
    /// The frame the pose is given in (`odom`, or `map` for an estimate).
    pub frame_id: String,
    /// The robot's frame (`base_link`).
    pub child_frame_id: String,
    /// The robot's pose in `frame_id`.
    pub pose: Pose2,
}

impl Odometry {
    /// Decodes a CDR message (the pose; covariance and twist are skipped).
    pub fn decode(message: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(message)?;
        let (stamp, frame_id) = read_header(&mut r)?;
        let child_frame_id = r.string("child_frame_id")?;
        let pose = read_pose(&mut r, "pose")?;
        Ok(Self {
            stamp,
            frame_id,
            child_frame_id,
            pose,
        })
    }

    /// Encodes as a CDR message, with zero covariances and twist.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut w = CdrWriter::default();
        write_header(&mut w, self.stamp, &self.frame_id);
        w.string(&self.child_frame_id);
        write_pose(&mut w, &self.pose);
        // pose covariance, twist (linear, angular), twist covariance.
        for _ in 0..(36 + 6 + 36) {
            w.f64(0.0);
        }
        w.finish()
    }
}

/// One `geometry_msgs/msg/TransformStamped`, planar.
#[derive(Debug, Clone, PartialEq)]
pub struct Transform {
    /// Time (s).
    pub stamp: f64,
    /// The parent frame.
    pub parent: String,
    /// The child frame.
    pub child: String,
    /// The child's pose in the parent.
    pub pose: Pose2,
}

/// Decodes a `tf2_msgs/msg/TFMessage`.
pub fn decode_tf(message: &[u8]) -> Result<Vec<Transform>, CdrError> {
    let mut r = CdrReader::new(message)?;
    // A transform takes at least 8 (stamp) + 4 + 4 (two empty strings) + 56 bytes.
    let n = r.seq_len("transforms", 72)?;
    (0..n)
        .map(|_| {
            let (stamp, parent) = read_header(&mut r)?;
            let child = r.string("child_frame_id")?;
            let pose = read_pose(&mut r, "transform")?;
            Ok(Transform {
                stamp,
                parent,
                child,
                pose,
            })
        })
        .collect()
}

/// Encodes a `tf2_msgs/msg/TFMessage`.
#[must_use]
pub fn encode_tf(transforms: &[Transform]) -> Vec<u8> {
    let mut w = CdrWriter::default();
    w.u32(u32::try_from(transforms.len()).unwrap_or(u32::MAX));
    for t in transforms {
        write_header(&mut w, t.stamp, &t.parent);
        w.string(&t.child);
        write_pose(&mut w, &t.pose);
    }
    w.finish()
}

const SEPARATOR: &str =
    "================================================================================\n";

const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const POSE: &str = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n";
const POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION: &str =
    "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
const VECTOR3: &str = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";

fn definition(main: &str, deps: &[&str]) -> String {
    let mut text = main.to_string();
    for d in deps {
        text += SEPARATOR;
        text += d;
    }
    text
}

/// The `ros2msg` schema text of a message type this module writes (the message's definition
/// followed by those of the types it uses), so that Foxglove and `ros2 bag` decode it.
#[must_use]
pub fn schema_text(name: &str) -> String {
    match name {
        LASER_SCAN => definition(
            "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\n\
             float32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\n\
             float32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n",
            &[HEADER, TIME],
        ),
        ODOMETRY => definition(
            "std_msgs/Header header\nstring child_frame_id\n\
             geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
            &[
                HEADER,
                TIME,
                "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n",
                POSE,
                POINT,
                QUATERNION,
                "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n",
                "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n",
                VECTOR3,
            ],
        ),
        _ => definition(
            "geometry_msgs/TransformStamped[] transforms\n",
            &[
                "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\n\
                 string child_frame_id\nTransform transform\n",
                HEADER,
                TIME,
                "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n",
                VECTOR3,
                QUATERNION,
            ],
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip() {
        let scan = LaserScan {
            stamp: 976_052_857.376,
            frame_id: "laser".into(),
            angle_min: -1.5,
            angle_max: 1.5,
            angle_increment: 0.01,
            time_increment: 0.0,
            scan_time: 0.2,
            range_min: 0.1,
            range_max: 30.0,
            ranges: vec![1.0, f32::INFINITY, 2.5],
            intensities: vec![],
        };
        let back = LaserScan::decode(&scan.encode()).unwrap();
        assert!((back.stamp - scan.stamp).abs() < 1e-6);
        assert_eq!(back.ranges, scan.ranges);
        assert_eq!(back.frame_id, "laser");

        let odom = Odometry {
            stamp: 12.5,
            frame_id: "odom".into(),
            child_frame_id: "base_link".into(),
            pose: Pose2::new(1.0, -2.0, 3.0),
        };
        let back = Odometry::decode(&odom.encode()).unwrap();
        assert_eq!(back.child_frame_id, "base_link");
        assert!((back.pose.theta - 3.0).abs() < 1e-12 && back.pose.x == 1.0);

        let tf = vec![Transform {
            stamp: 1.0,
            parent: "base_link".into(),
            child: "laser".into(),
            pose: Pose2::new(0.2, 0.0, -0.5),
        }];
        let back = decode_tf(&encode_tf(&tf)).unwrap();
        assert_eq!(back.len(), 1);
        assert!((back[0].pose.theta + 0.5).abs() < 1e-12);
    }

    #[test]
    fn stamps_carry_nanoseconds() {
        assert_eq!(stamp_parts(1.5), (1, 500_000_000));
        assert_eq!(stamp_parts(2.999_999_999_9), (3, 0));
        assert_eq!(nanos(-1.0), 0);
        assert!(is_type("sensor_msgs/LaserScan", LASER_SCAN));
    }
}
