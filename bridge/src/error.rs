//! One error enum per operation: connecting (node, services, ports), publishing, receiving,
//! publishing a whole drive.
//!
//! iceoryx2's own errors are kept as their `Debug` text (`detail`): they are many small enums
//! per call, and the caller needs the operation and the service that failed, not the type.

use thiserror::Error;

/// Creating a publisher or subscriber: the node, the services and the ports.
#[derive(Debug, Error)]
pub enum ConnectError {
    /// The service prefix makes an invalid iceoryx2 service name.
    #[error("invalid service name {name:?}: {detail}")]
    BadServiceName {
        /// The name.
        name: String,
        /// Why iceoryx2 refused it.
        detail: String,
    },
    /// The iceoryx2 node could not be created.
    #[error("creating the iceoryx2 node: {detail}")]
    Node {
        /// iceoryx2's error.
        detail: String,
    },
    /// The service exists with the other back-pressure mode (overflow setting).
    #[error(
        "service {service:?} exists in {existing} mode but {requested} was asked for: give both \
         sides the same --backpressure, or let the subscriber adopt the publisher's"
    )]
    BackPressureMismatch {
        /// The service.
        service: String,
        /// The mode the service has.
        existing: &'static str,
        /// The mode requested.
        requested: &'static str,
    },
    /// Opening or creating a service failed.
    #[error("opening service {service:?}: {detail}")]
    Service {
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Creating a port (publisher, subscriber, notifier, listener) failed.
    #[error("creating the {port} port of {service:?}: {detail}")]
    Port {
        /// Which port.
        port: &'static str,
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Another publisher owns the service: a qicp service has one publisher, so that no
    /// subscriber ever mixes two streams.
    #[error(
        "another process already publishes on {service:?} (a qicp service has one publisher: \
         stop the other one, or use another service prefix)"
    )]
    Owned {
        /// The service.
        service: String,
    },
    /// The service exists but allows more than one publisher (created by another program or an
    /// older qicp), so its stream could be mixed.
    #[error(
        "service {service:?} was created for {max_publishers} publishers; qicp needs one owner \
         per service (stop the program that created it, or use another service prefix)"
    )]
    NotSingleOwner {
        /// The service.
        service: String,
        /// The publishers it allows.
        max_publishers: usize,
    },
    /// The iceoryx2 configuration file could not be read or parsed.
    #[error("iceoryx2 configuration {path:?}: {detail}")]
    Config {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong with it.
        detail: String,
    },
    /// A request outside the service's fixed limits.
    #[error("{what} {requested} exceeds the service limit {limit}")]
    Limit {
        /// What was requested.
        what: &'static str,
        /// The request.
        requested: usize,
        /// The limit.
        limit: usize,
    },
}

/// Publishing one message.
#[derive(Debug, Error)]
pub enum PublishError {
    /// No sample could be loaned (all in use, or the scan is longer than the segment allows).
    #[error("loaning a sample on {service:?}: {detail}")]
    Loan {
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// The sample could not be delivered; in `block` mode this includes a subscriber whose
    /// buffer stayed full for longer than the block timeout.
    #[error("sending on {service:?}: {detail}")]
    Send {
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Waking the subscribers failed.
    #[error("notifying the subscribers of {service:?}: {detail}")]
    Notify {
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// In `block` mode every subscriber left while the publisher still had data: what it
    /// would send now would reach nobody, which `block` (lossless) promises never to do.
    #[error(
        "every subscriber of {service:?} left after {sent} messages; in block (lossless) mode \
         the rest would reach nobody"
    )]
    SubscribersLeft {
        /// The service.
        service: String,
        /// Messages sent before.
        sent: u64,
    },
    /// The scan has more beams than a sample header can count.
    #[error("a scan of {beams} beams is too long for the wire format")]
    TooManyBeams {
        /// The beams.
        beams: usize,
    },
}

/// Waiting for or receiving messages.
#[derive(Debug, Error)]
pub enum ReceiveError {
    /// The WaitSet could not be created, attached or run.
    #[error("waiting on {service:?}: {detail}")]
    Wait {
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Taking a sample from the subscriber's buffer failed.
    #[error("receiving from {service:?}: {detail}")]
    Receive {
        /// The service.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// A message with another layout version: the two sides were built from different
    /// versions of qicp.
    #[error("message layout version {found} on {service:?}, expected {expected}")]
    LayoutVersion {
        /// The service.
        service: String,
        /// The version received.
        found: u32,
        /// This build's version.
        expected: u32,
    },
    /// A scan arrived but cannot become a record (a pose that is not finite or off the map,
    /// a bad beam geometry): yielded by [`Records`](crate::Records), which goes on with the
    /// next scan.
    #[error("scan {seq} of publisher {publisher:#x} on {service:?} rejected: {why}")]
    Rejected {
        /// The service.
        service: String,
        /// The scan's sequence number.
        seq: u64,
        /// The scan's publisher ([`ScanHeader::publisher`](crate::ScanHeader::publisher)).
        publisher: u64,
        /// Why it is not a record (part of the message, not a separate `source()`).
        why: qicp_core::ScanError,
    },
}

/// Publishing a drive ([`publish_records`](crate::drive::publish_records)): connecting, pacing,
/// publishing, and the record source's own failures.
#[derive(Debug, Error)]
pub enum DriveError {
    /// The iceoryx2 configuration, the node, the service or the publisher port.
    #[error(transparent)]
    Connect(#[from] ConnectError),
    /// Another publisher owns the scan service ([`ConnectError::Owned`]).
    #[error("{0}; its subscribers would see two streams mixed, so this one does not start")]
    Owned(ConnectError),
    /// Publishing a scan or the end-of-stream marker.
    #[error(transparent)]
    Publish(#[from] PublishError),
    /// Waiting for the subscribers to come or to leave.
    #[error(transparent)]
    Receive(#[from] ReceiveError),
    /// SIGINT/SIGTERM arrived while the publisher waited for its subscribers.
    #[error("interrupted while waiting for subscribers")]
    Interrupted,
    /// Too few subscribers came within the connect timeout.
    #[error("no subscriber on {service} within {timeout} s (--connect-timeout)")]
    NoSubscriber {
        /// The scan service.
        service: String,
        /// The connect timeout (s).
        timeout: f64,
    },
    /// At the rate asked for, a scan is due more than
    /// [`MAX_SECONDS`](crate::drive::MAX_SECONDS) after the first (or at no finite time).
    #[error(
        "scan {index} (t = {t} s) is due {due} s after the first (t = {first} s) at --rate \
         {rate}: a wait beyond {max} s; the log's time jumps (publish it with --rate max)",
        max = crate::drive::MAX_SECONDS
    )]
    TimeJump {
        /// The scan's index in the drive.
        index: u64,
        /// Its timestamp (s).
        t: f64,
        /// When it is due after the first scan at this rate (s).
        due: f64,
        /// The first scan's timestamp (s).
        first: f64,
        /// The rate.
        rate: crate::drive::Rate,
    },
    /// The thread that pulls records ahead of the publisher could not be started.
    #[error("starting the source thread")]
    SourceThread(#[source] std::io::Error),
    /// The thread that pulls records ahead of the publisher panicked.
    #[error("the record source panicked")]
    SourcePanicked,
    /// The record source failed (a malformed log line, a simulation error).
    #[error(transparent)]
    Source(Box<dyn std::error::Error + Send + Sync>),
}

pub(crate) fn detail(e: impl std::fmt::Debug) -> String {
    format!("{e:?}")
}

/// The error of a port (`"publisher"` or `"subscriber"`) that could not be created on `service`.
pub(crate) fn port_error(
    port: &'static str,
    service: &str,
    e: impl std::fmt::Debug,
) -> ConnectError {
    ConnectError::Port {
        port,
        service: service.to_string(),
        detail: detail(e),
    }
}
