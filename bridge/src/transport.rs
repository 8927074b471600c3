//! The iceoryx2 side: services, typed publishers and subscribers, waiting.
//!
//! Each stream is two iceoryx2 services of the same name: a publish-subscribe service carrying
//! the messages and an event service that wakes the other side (a sample was sent, a subscriber
//! connected or left). Subscribers block in a [`WaitSet`] on their event listener; between
//! events they wake only on a `tick` to notice a publisher that died without saying so.
//!
//! One owner per service: every service qicp creates allows one publisher, and qicp joins no
//! service that allows more, so a subscriber never sees two streams mixed. A publisher whose
//! service is taken is refused ([`ConnectError::Owned`]).
//!
//! The iceoryx2 configuration is explicit ([`Topics::with_config_file`], default: iceoryx2's
//! built-in defaults): iceoryx2's own lookup of `config/iceoryx2.toml` in the working
//! directory (then the user's and the system's) is never used.

use crate::error::{ConnectError, PublishError, ReceiveError, detail, port_error};
use crate::messages::{
    KIND_END_OF_STREAM, LAYOUT_VERSION, PoseMessage, ScanHeader, publisher_identity,
};
use crate::sequence::{Admission, Observation, SequenceTracker, StreamEnd, StreamReport};
use iceoryx2::config::Config;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeCreateError, PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::dynamic_config::publish_subscribe::PublisherDetails;
use iceoryx2::service::port_factory::{event as event_factory, publish_subscribe};
use iceoryx2::waitset::WaitSetRunResult;
use qicp_core::Record;
use std::ops::ControlFlow;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

pub mod payload;
mod publish;
mod subscribe;

pub use publish::{PosePublisher, ScanPublisher};
pub use subscribe::{PoseSubscriber, ScanSubscriber};

/// The default service prefix: services `qicp/scan` and `qicp/pose`.
pub const DEFAULT_PREFIX: &str = "qicp";

/// History a scan subscriber may ask for at most (samples the publisher keeps).
pub const SCAN_HISTORY_MAX: usize = 64;
/// Largest scan subscriber buffer.
pub const SCAN_BUFFER_MAX: usize = 256;
/// History a pose subscriber may ask for at most.
pub const POSE_HISTORY_MAX: usize = 64;
/// Largest pose subscriber buffer.
pub const POSE_BUFFER_MAX: usize = 256;
/// Subscribers per stream.
pub const MAX_SUBSCRIBERS: usize = 8;
/// Publishers per stream: one owner. A second publisher's creation fails
/// ([`ConnectError::Owned`]); a killed owner's slot is freed by removing its dead node, which
/// a new publisher does before giving up.
pub const MAX_PUBLISHERS: usize = 1;

/// How often a waiting publisher removes dead nodes (a killed subscriber stops counting).
const CLEANUP_EVERY: Duration = Duration::from_millis(100);

/// Event ids on a stream's event service.
pub mod event_id {
    /// A publisher sent a sample (data or end-of-stream).
    pub const SAMPLE: usize = 1;
    /// A subscriber connected: publishers refresh their connections (deliver history).
    pub const SUBSCRIBER_CONNECTED: usize = 2;
    /// A subscriber left.
    pub const SUBSCRIBER_LEFT: usize = 3;
    /// A publisher connected.
    pub const PUBLISHER_CONNECTED: usize = 4;
    /// A publisher left.
    pub const PUBLISHER_LEFT: usize = 5;
    /// A subscriber has attached to every publisher it can see and can take samples: sent
    /// after a publisher appeared. iceoryx2 drops (rather than block on) a sample for a
    /// subscriber that has not attached yet once its buffer is full, so a `block` publisher
    /// waits for this before its first send.
    pub const SUBSCRIBER_READY: usize = 6;
}

/// The service names of one qicp bridge (`<prefix>/scan`, `<prefix>/pose`) and the iceoryx2
/// configuration they live in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    prefix: String,
    /// iceoryx2's settings (where its files live, their prefix, …): the built-in defaults
    /// unless a file was given. Processes meet only if they agree on them.
    config: std::sync::Arc<Config>,
    config_file: Option<std::path::PathBuf>,
}

impl Default for Topics {
    fn default() -> Self {
        Self::new(DEFAULT_PREFIX)
    }
}

impl Topics {
    /// Topics under `prefix` (e.g. `qicp`, or a unique prefix per test).
    #[must_use]
    ///
    /// The iceoryx2 configuration is iceoryx2's built-in default (`Config::default()`), whatever
    /// lies in the working directory.
    pub fn new(prefix: &str) -> Self {
        Self {
            prefix: prefix.trim_end_matches('/').to_string(),
            config: std::sync::Arc::new(Config::default()),
            config_file: None,
        }
    }

    /// These topics in the iceoryx2 configuration of `path` (iceoryx2's TOML format; keys it
    /// leaves out keep their defaults). Every process of one bridge needs the same settings.
    pub fn with_config_file(self, path: &std::path::Path) -> Result<Self, ConnectError> {
        let error = |detail: String| ConnectError::Config {
            path: path.to_path_buf(),
            detail,
        };
        let text = std::fs::read_to_string(path).map_err(|e| error(e.to_string()))?;
        let config: Config = toml::from_str(&text).map_err(|e| error(e.to_string()))?;
        Ok(Self {
            config: std::sync::Arc::new(config),
            config_file: Some(path.to_path_buf()),
            ..self
        })
    }

    /// The iceoryx2 configuration file given, if any (`None`: the built-in defaults).
    #[must_use]
    pub fn config_file(&self) -> Option<&std::path::Path> {
        self.config_file.as_deref()
    }

    /// The scan stream, `<prefix>/scan`.
    #[must_use]
    pub fn scan(&self) -> String {
        format!("{}/scan", self.prefix)
    }

    /// The pose stream, `<prefix>/pose`.
    #[must_use]
    pub fn pose(&self) -> String {
        format!("{}/pose", self.prefix)
    }
}

/// What a publisher does when a subscriber's buffer is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BackPressure {
    /// The publisher waits until the subscriber has room: lossless (replay, simulation).
    #[default]
    Block,
    /// The newest sample overwrites the subscriber's oldest; the subscriber counts the gap
    /// (live sensors, where a stale scan is worth less than a fresh one).
    DropOldest,
}

impl BackPressure {
    /// `block` or `drop-oldest`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            BackPressure::Block => "block",
            BackPressure::DropOldest => "drop-oldest",
        }
    }

    fn safe_overflow(self) -> bool {
        self == BackPressure::DropOldest
    }

    fn of_overflow(safe_overflow: bool) -> Self {
        if safe_overflow {
            BackPressure::DropOldest
        } else {
            BackPressure::Block
        }
    }
}

impl std::fmt::Display for BackPressure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for BackPressure {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "block" => Ok(BackPressure::Block),
            "drop-oldest" => Ok(BackPressure::DropOldest),
            other => Err(format!(
                "unknown back-pressure {other:?}: use block or drop-oldest"
            )),
        }
    }
}

/// Options of a scan publisher.
#[derive(Debug, Clone)]
pub struct PublisherOptions {
    /// Back-pressure mode (must match the service's if it already exists).
    pub backpressure: BackPressure,
    /// Beams per scan the shared-memory segment is first sized for; longer scans grow it
    /// (unless `fixed_size`).
    pub beams: usize,
    /// No scan will have more than `beams` ranges (a simulator's laser, a log whose longest
    /// scan is known): the segment is allocated once and never grows, and a longer scan fails
    /// to publish. Saves about 4 ms of start-up: iceoryx2 keeps per-chunk counters for each
    /// of the 255 segments a growing publisher may allocate (2,130 chunks × 255 × 8 bytes).
    pub fixed_size: bool,
    /// In `block` mode, how long one send may wait for a full subscriber before it fails.
    pub block_timeout: Duration,
}

impl Default for PublisherOptions {
    fn default() -> Self {
        Self {
            backpressure: BackPressure::Block,
            beams: 361,
            fixed_size: false,
            block_timeout: Duration::from_secs(30),
        }
    }
}

/// How long a subscriber waits for what.
#[derive(Debug, Clone, Copy)]
pub struct WaitOptions {
    /// For the first publisher to appear.
    pub connect_timeout: Duration,
    /// For a new publisher after one was lost.
    pub reconnect_timeout: Duration,
    /// For the next message while a publisher is connected.
    pub idle_timeout: Duration,
    /// How often a quiet subscriber checks that its publisher is alive.
    pub tick: Duration,
}

impl Default for WaitOptions {
    fn default() -> Self {
        Self {
            connect_timeout: Duration::from_secs(60),
            reconnect_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(120),
            tick: Duration::from_millis(100),
        }
    }
}

/// Options of a subscriber.
#[derive(Debug, Clone, Default)]
pub struct SubscriberOptions {
    /// Messages sent before this subscriber connected that it asks for (at most the
    /// service's history size).
    pub history: usize,
    /// Its buffer (0: the service's largest); raised to `history` if smaller.
    pub buffer: usize,
    /// The back-pressure mode to require; `None` adopts the mode of an existing service
    /// (and creates a `block` one if none exists yet).
    pub backpressure: Option<BackPressure>,
    /// Timeouts.
    pub wait: WaitOptions,
}

/// What a subscriber's callback is told.
#[derive(Debug)]
pub enum StreamEvent<M> {
    /// A data message.
    Data(M),
    /// A publisher's first message; `skipped` of its messages were sent before it.
    PublisherJoined {
        /// Messages of the new publisher sent before the first one received.
        skipped: u64,
    },
    /// The publisher vanished without an end-of-stream marker.
    PublisherLost,
    /// `missing` messages were lost just before the next one.
    Gap {
        /// Messages lost.
        missing: u64,
    },
    /// Another publisher sent on the service while the owner was connected (told once per
    /// intruder): its messages are dropped and counted ([`StreamReport::intruders`]).
    Intruder,
}

/// A received scan, read in place from shared memory.
#[derive(Debug, Clone, Copy)]
pub struct ScanView<'a> {
    /// The header.
    pub header: &'a ScanHeader,
    /// The ranges, still in the publisher's shared-memory segment.
    pub ranges: &'a [f64],
}

type Ipc = ipc::Service;

fn service_name(name: &str) -> Result<ServiceName, ConnectError> {
    ServiceName::new(name).map_err(|e| ConnectError::BadServiceName {
        name: name.to_string(),
        detail: detail(e),
    })
}

type SharedNode = std::rc::Rc<Node<Ipc>>;

/// A thread's node, if alive, and the configuration it was made from.
type CachedNode = (std::rc::Weak<Node<Ipc>>, Option<std::sync::Arc<Config>>);

thread_local! {
    /// The node of this thread's ports, alive while any of them is.
    static NODE: std::cell::RefCell<CachedNode> =
        const { std::cell::RefCell::new((std::rc::Weak::new(), None)) };
}

/// The iceoryx2 node of this thread for `topics`' configuration: every port created on a
/// thread with one configuration shares one node, so a process such as
/// `qicp match --subscribe` (scan subscriber, pose publisher) registers once, and has one node
/// to clean up when it exits. (iceoryx2's `ipc` ports stay on the thread that made them, so a
/// node per thread is a node per port set.)
fn shared_node(topics: &Topics) -> Result<SharedNode, ConnectError> {
    NODE.with(|cell| {
        {
            let cached = cell.borrow();
            if let (Some(node), Some(config)) = (cached.0.upgrade(), cached.1.as_ref())
                && **config == *topics.config
            {
                return Ok(node);
            }
        }
        // iceoryx2 warns on stderr that it runs without a config file; qicp needs none.
        // `IOX2_LOG_LEVEL` still overrides this.
        static QUIET: std::sync::Once = std::sync::Once::new();
        QUIET.call_once(|| set_log_level_from_env_or(LogLevel::Error));
        // Dead nodes are removed where they matter: iceoryx2 does it when a service is
        // opened (`cleanup_dead_nodes_on_open`), and qicp's waits do it on their ticks. The
        // node-wide scans when a node is created and dropped (~1 ms each: every node's
        // details are read and parsed) add nothing to that.
        // The configuration is the topics' own, never `Config::global_config()`: that one is
        // whatever `config/iceoryx2.toml` lies in the working directory.
        let mut config = (*topics.config).clone();
        config.global.node.cleanup_dead_nodes_on_creation = false;
        config.global.node.cleanup_dead_nodes_on_destruction = false;
        let node = std::rc::Rc::new(
            NodeBuilder::new()
                .config(&config)
                .create::<Ipc>()
                .map_err(|e| ConnectError::Node { detail: detail(e) })?,
        );
        *cell.borrow_mut() = (
            std::rc::Rc::downgrade(&node),
            Some(std::sync::Arc::clone(&topics.config)),
        );
        Ok(node)
    })
}

/// Refuses a service that allows more than one publisher: its subscribers could see two
/// streams mixed.
fn single_owner(service: &str, max_publishers: usize) -> Result<(), ConnectError> {
    if max_publishers == MAX_PUBLISHERS {
        Ok(())
    } else {
        Err(ConnectError::NotSingleOwner {
            service: service.to_string(),
            max_publishers,
        })
    }
}

/// The back-pressure handler of a block-mode publisher: retry until `block_timeout` has
/// passed, then give the sample up and fail the send.
fn give_up_after(block_timeout: Duration, info: &BackpressureInfo) -> BackpressureAction {
    if info.elapsed_time > block_timeout {
        BackpressureAction::DiscardDataAndFail
    } else {
        BackpressureAction::Retry
    }
}

/// Creates the one publisher of `service`. A killed owner keeps its slot until its dead node
/// is removed, so a new publisher removes dead nodes before it gives up; a live owner makes
/// it fail with [`ConnectError::Owned`].
fn create_owner<P>(
    node: &Node<Ipc>,
    service: &str,
    create: impl Fn() -> Result<P, PublisherCreateError>,
) -> Result<P, ConnectError> {
    let fail = |e: PublisherCreateError| match e {
        PublisherCreateError::ExceedsMaxSupportedPublishers => ConnectError::Owned {
            service: service.to_string(),
        },
        e => port_error("publisher", service, e),
    };
    match create() {
        Err(PublisherCreateError::ExceedsMaxSupportedPublishers) => {
            node.try_cleanup_dead_nodes();
            create().map_err(fail)
        }
        other => other.map_err(fail),
    }
}

/// The event half of a stream: wakes the other side.
#[derive(Debug)]
struct Signals {
    notifier: Notifier<Ipc>,
    listener: Listener<Ipc>,
    _service: event_factory::PortFactory<Ipc>,
}

impl Signals {
    fn open(node: &Node<Ipc>, name: &str) -> Result<Self, ConnectError> {
        let service = node
            .service_builder(&service_name(name)?)
            .event()
            .open_or_create()
            .map_err(|e| ConnectError::Service {
                service: name.to_string(),
                detail: detail(e),
            })?;
        let port = |port: &'static str, e: String| ConnectError::Port {
            port,
            service: name.to_string(),
            detail: e,
        };
        let notifier = service
            .notifier_builder()
            .create()
            .map_err(|e| port("notifier", detail(e)))?;
        let listener = service
            .listener_builder()
            .create()
            .map_err(|e| port("listener", detail(e)))?;
        Ok(Self {
            notifier,
            listener,
            _service: service,
        })
    }

    fn notify(&self, id: usize) -> Result<usize, String> {
        self.notifier
            .notify_with_custom_event_id(EventId::new(id))
            .map_err(detail)
    }

    /// Waits up to `timeout` for any event, then consumes all pending ones.
    fn wait(&self, timeout: Duration) -> Result<Seen, String> {
        let mut seen = Seen::default();
        self.listener
            .timed_wait(|e| seen.add(e), timeout)
            .map_err(detail)?;
        self.listener.try_wait(|e| seen.add(e)).map_err(detail)?;
        Ok(seen)
    }

    /// Consumes all pending events.
    fn drain(&self) -> Result<Seen, String> {
        let mut seen = Seen::default();
        self.listener.try_wait(|e| seen.add(e)).map_err(detail)?;
        Ok(seen)
    }
}

/// The events of interest among those consumed.
#[derive(Debug, Default, Clone, Copy)]
struct Seen {
    ready: u64,
    publisher_connected: bool,
}

impl Seen {
    fn add(&mut self, e: EventActivation) {
        match e.id.as_value() {
            event_id::SUBSCRIBER_READY => self.ready += e.count.max(1),
            event_id::PUBLISHER_CONNECTED => self.publisher_connected = true,
            _ => {}
        }
    }
}

/// What the publishers of both streams share: the node, the event signals and the
/// subscriber bookkeeping.
#[derive(Debug)]
struct PublisherCore {
    service: String,
    signals: Signals,
    node: SharedNode,
    sent: u64,
    /// `SUBSCRIBER_READY` events seen since this publisher appeared.
    ready: std::cell::Cell<u64>,
    /// [`publisher_identity`] of the port, written into every message.
    identity: u64,
}

impl PublisherCore {
    /// A publisher's shared state, before anything has been sent.
    fn new(service: String, signals: Signals, node: SharedNode, unique_id: u128) -> Self {
        Self {
            service,
            signals,
            node,
            sent: 0,
            ready: std::cell::Cell::new(0),
            identity: publisher_identity(unique_id),
        }
    }

    fn interrupted(&self) -> bool {
        self.node.wait(Duration::ZERO).is_err()
    }

    /// Waits until `count(subscribers)` holds or `timeout` passes; true if it holds.
    /// Dead subscribers are cleaned up on the way, so a killed one does not count.
    fn wait_until(
        &self,
        timeout: Duration,
        subscribers: &dyn Fn() -> usize,
        holds: &dyn Fn(usize, u64) -> bool,
    ) -> Result<bool, ReceiveError> {
        // A timeout beyond what an `Instant` can hold waits without a deadline.
        let deadline = Instant::now().checked_add(timeout);
        let wait_error = |detail| ReceiveError::Wait {
            service: self.service.clone(),
            detail,
        };
        // Listing the nodes costs ~1 ms; events come in bursts at start-up, so clean up at
        // most once per `CLEANUP_EVERY`, starting with the first look.
        let mut last_cleanup: Option<Instant> = None;
        loop {
            if last_cleanup.is_none_or(|t| t.elapsed() >= CLEANUP_EVERY) {
                self.node.try_cleanup_dead_nodes();
                last_cleanup = Some(Instant::now());
            }
            let seen = self.signals.drain().map_err(wait_error)?;
            self.ready.set(self.ready.get() + seen.ready);
            if holds(subscribers(), self.ready.get()) {
                return Ok(true);
            }
            let now = Instant::now();
            if deadline.is_some_and(|d| now >= d) || self.interrupted() {
                return Ok(false);
            }
            let step = deadline.map_or(Duration::MAX, |d| d - now);
            let step = step.min(Duration::from_millis(200));
            let seen = self.signals.wait(step).map_err(wait_error)?;
            self.ready.set(self.ready.get() + seen.ready);
        }
    }

    fn notify_sample(&self) -> Result<(), PublishError> {
        self.signals
            .notify(event_id::SAMPLE)
            .map(|_| ())
            .map_err(|detail| PublishError::Notify {
                service: self.service.clone(),
                detail,
            })
    }
}

fn scan_service_builder(
    node: &Node<Ipc>,
    name: &ServiceName,
) -> iceoryx2::service::builder::publish_subscribe::Builder<[f64], ScanHeader, Ipc> {
    node.service_builder(name)
        .publish_subscribe::<[f64]>()
        .user_header::<ScanHeader>()
        .history_size(SCAN_HISTORY_MAX)
        .subscriber_max_buffer_size(SCAN_BUFFER_MAX)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_publishers(MAX_PUBLISHERS)
}

fn pose_service_builder(
    node: &Node<Ipc>,
    name: &ServiceName,
) -> iceoryx2::service::builder::publish_subscribe::Builder<PoseMessage, (), Ipc> {
    node.service_builder(name)
        .publish_subscribe::<PoseMessage>()
        .enable_safe_overflow(true)
        .history_size(POSE_HISTORY_MAX)
        .subscriber_max_buffer_size(POSE_BUFFER_MAX)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_publishers(MAX_PUBLISHERS)
}

fn open_error(service: &str, requested: BackPressure, e: impl std::fmt::Debug) -> ConnectError {
    let text = detail(&e);
    if text.contains("IncompatibleOverflowBehavior") {
        ConnectError::BackPressureMismatch {
            service: service.to_string(),
            existing: BackPressure::of_overflow(!requested.safe_overflow()).name(),
            requested: requested.name(),
        }
    } else {
        ConnectError::Service {
            service: service.to_string(),
            detail: text,
        }
    }
}
