//! ROS 2 bags (rosbag2 in MCAP storage, the default since ROS 2 Iron), read and written
//! without ROS: `sensor_msgs/msg/LaserScan`, `nav_msgs/msg/Odometry` and `/tf` in CDR.
//!
//! [`BagReader`] streams laser records out of a bag ([`BagOptions`] names the scan topic and
//! where odometry comes from); [`BagWriter`] writes records and estimated poses into one.

pub mod cdr;
pub mod msgs;
mod read;
mod write;

pub use read::{BagInfo, BagOptions, BagReader, OdometrySource, is_mcap};
pub use write::{BagLayout, BagWriter};
