//! # qicp-bridge
//!
//! Moves laser scans and pose estimates between processes through iceoryx2 shared memory:
//! a simulator, a log replayer or a robot's laser driver publishes scans, the matcher process
//! subscribes, matches and publishes poses, and any other process (Rust, C, C++, Python)
//! subscribes to either stream.
//!
//! - [`messages`]: the `#[repr(C)]` wire types ([`ScanHeader`] + a slice of ranges,
//!   [`PoseMessage`], the end-of-stream marker) and their conversions to [`qicp_core`] types;
//! - [`ScanPublisher`], [`ScanSubscriber`], [`PosePublisher`], [`PoseSubscriber`]: typed ports
//!   on the services `<prefix>/scan` and `<prefix>/pose` (see [`Topics`]), all one generic
//!   [`Publisher`] and [`Subscriber`] over the stream's [`Message`] type ([`ScanStream`],
//!   [`PoseStream`]);
//! - [`ScanSubscriber::records`]: the scans as an iterator of owned records ([`Records`]),
//!   which is a `qicp_io::RecordSource` (by that trait's blanket impl over iterators of
//!   `Result<Record, E>`), so a matcher reads the bridge as it reads a log or the simulator;
//! - [`drive`]: the publishing driver ([`publish_records`]): a drive published at a pace
//!   ([`Rate`]), its start-up overlapped with the source's, reported in a [`PublishReport`];
//! - [`sequence`]: the sequence-number bookkeeping that makes every loss visible;
//! - [`payload`]: opaque byte payloads of any size, written and read in place (what
//!   `qicp bench bridge --sizes` measures against a Unix-domain socket);
//! - one owner per service: a second publisher on a stream is refused
//!   ([`ConnectError::Owned`]), and every message names its publisher;
//! - the iceoryx2 configuration is explicit ([`Topics::with_config_file`]; default iceoryx2's
//!   built-in one), never a file found in the working directory.
//!
//! Zero copy: a publisher loans a sample in shared memory and writes the ranges into it;
//! the subscriber reads the same memory ([`ScanView::ranges`]). The one copy on the receiving
//! side is [`ScanHeader::to_record`], because [`qicp_core::Scan`] owns its ranges.
#![warn(missing_docs)]

pub mod drive;
pub mod error;
pub mod messages;
pub mod sequence;
mod transport;

pub use drive::{DriveOptions, PublishReport, Rate, publish_records};
pub use error::{ConnectError, DriveError, PublishError, ReceiveError};
pub use messages::{LAYOUT_VERSION, PoseC, PoseMessage, ScanHeader, publisher_identity};
pub use sequence::{Admission, SequenceTracker, StreamEnd, StreamReport};
pub use transport::payload;
pub use transport::{
    BackPressure, DEFAULT_PREFIX, MAX_PUBLISHERS, MAX_SUBSCRIBERS, Message, POSE_BUFFER_MAX,
    POSE_HISTORY_MAX, PosePublisher, PoseStream, PoseSubscriber, Publisher, PublisherOptions,
    Records, SCAN_BUFFER_MAX, SCAN_HISTORY_MAX, ScanPublisher, ScanStream, ScanSubscriber,
    ScanView, StreamEvent, Subscriber, SubscriberOptions, Topics, WaitOptions, event_id,
};
