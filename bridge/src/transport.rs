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

/// Publishes scans on `<prefix>/scan`; the ranges are written straight into loaned shared
/// memory (the only write; subscribers read them in place).
#[derive(Debug)]
pub struct ScanPublisher {
    publisher: Option<Publisher<Ipc, [f64], ScanHeader>>,
    service: publish_subscribe::PortFactory<Ipc, [f64], ScanHeader>,
    core: PublisherCore,
    backpressure: BackPressure,
    blocked: Arc<AtomicU64>,
    /// A subscriber was connected at some send: in `block` mode, none being left is an error.
    had_subscriber: bool,
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

impl ScanPublisher {
    /// Opens (or creates) `<prefix>/scan` and a publisher on it.
    /// Fails with [`ConnectError::Owned`] if another publisher owns the service.
    pub fn create(topics: &Topics, options: &PublisherOptions) -> Result<Self, ConnectError> {
        let name = topics.scan();
        let node = shared_node(topics)?;
        let service = scan_service_builder(&node, &service_name(&name)?)
            .enable_safe_overflow(options.backpressure.safe_overflow())
            .open_or_create()
            .map_err(|e| open_error(&name, options.backpressure, e))?;
        single_owner(&name, service.static_config().max_publishers())?;
        // Listen before registering: a subscriber's READY answers our registration.
        let signals = Signals::open(&node, &name)?;
        let blocked = Arc::new(AtomicU64::new(0));
        let block_timeout = options.block_timeout;
        let publisher = create_owner(&node, &name, || {
            let counter = Arc::clone(&blocked);
            service
                .publisher_builder()
                .initial_max_slice_len(options.beams.max(1))
                .allocation_strategy(if options.fixed_size {
                    AllocationStrategy::Static
                } else {
                    AllocationStrategy::PowerOfTwo
                })
                .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
                .set_backpressure_handler(move |info: &BackpressureInfo| {
                    if info.retries == 0 {
                        counter.fetch_add(1, Ordering::Relaxed);
                    }
                    give_up_after(block_timeout, info)
                })
                .create()
        })?;
        let _ = signals.notify(event_id::PUBLISHER_CONNECTED);
        let unique_id = publisher.id().value();
        Ok(Self {
            publisher: Some(publisher),
            service,
            core: PublisherCore::new(name, signals, node, unique_id),
            backpressure: options.backpressure,
            blocked,
            had_subscriber: false,
        })
    }

    fn port(&self) -> &Publisher<Ipc, [f64], ScanHeader> {
        self.publisher
            .as_ref()
            .unwrap_or_else(|| unreachable!("the publisher is taken only on drop"))
    }

    /// Publishes `record` as the next scan; returns its sequence number.
    ///
    /// In `block` mode, fails with [`PublishError::SubscribersLeft`] once every subscriber
    /// that was there has left: lossless mode never sends into nothing.
    ///
    /// The ranges are copied once, from the record into the loaned sample: that is the
    /// publisher's write. A source that produces ranges itself should use
    /// [`ScanPublisher::publish_with`] and write them into the sample directly.
    pub fn publish(&mut self, record: &Record) -> Result<u64, PublishError> {
        let header = ScanHeader::of(record, self.core.sent);
        let ranges = record.scan.ranges();
        self.send(header, ranges.len(), |sample| {
            sample.write_from_slice(ranges)
        })
    }

    /// Publishes a scan whose `beams` ranges `range(i)` computes straight into the loaned
    /// shared memory (e.g. a laser driver decoding its packet in place). `header`'s `seq`,
    /// `publisher`, `beams`, `kind` and `layout_version` are set here.
    pub fn publish_with(
        &mut self,
        header: ScanHeader,
        beams: usize,
        range: impl FnMut(usize) -> f64,
    ) -> Result<u64, PublishError> {
        self.send(header, beams, |sample| sample.write_from_fn(range))
    }

    fn send(
        &mut self,
        mut header: ScanHeader,
        beams: usize,
        write: impl FnOnce(UninitScan) -> ScanSample,
    ) -> Result<u64, PublishError> {
        let seq = self.core.sent;
        if self.subscribers() > 0 {
            self.had_subscriber = true;
        } else if self.had_subscriber && self.backpressure == BackPressure::Block {
            return Err(PublishError::SubscribersLeft {
                service: self.core.service.clone(),
                sent: seq,
            });
        }
        header.layout_version = LAYOUT_VERSION;
        header.kind = crate::messages::KIND_DATA;
        header.seq = seq;
        header.publisher = self.core.identity;
        header.beams = u32::try_from(beams).map_err(|_| PublishError::TooManyBeams { beams })?;
        let mut sample = self.loan(beams)?;
        *sample.user_header_mut() = header;
        self.deliver(write(sample))?;
        self.core.sent += 1;
        Ok(seq)
    }

    fn loan(&self, beams: usize) -> Result<UninitScan, PublishError> {
        self.port()
            .loan_slice_uninit(beams)
            .map_err(|e| PublishError::Loan {
                service: self.core.service.clone(),
                detail: detail(e),
            })
    }

    fn deliver(&self, sample: ScanSample) -> Result<(), PublishError> {
        sample.send().map_err(|e| PublishError::Send {
            service: self.core.service.clone(),
            detail: detail(e),
        })?;
        self.core.notify_sample()
    }

    /// Sends the end-of-stream marker (no ranges; its `seq` is the number of scans sent).
    pub fn end_of_stream(&mut self) -> Result<(), PublishError> {
        let mut sample = self.loan(0)?;
        *sample.user_header_mut() = ScanHeader {
            publisher: self.core.identity,
            ..ScanHeader::end_of_stream(self.core.sent)
        };
        self.deliver(sample.write_from_slice(&[]))
    }

    /// Scans published so far.
    #[must_use]
    pub fn sent(&self) -> u64 {
        self.core.sent
    }

    /// The service name, `<prefix>/scan`.
    #[must_use]
    pub fn service(&self) -> &str {
        &self.core.service
    }

    /// Sends that found a subscriber's buffer full and had to wait (`block` mode).
    #[must_use]
    pub fn blocked_sends(&self) -> u64 {
        self.blocked.load(Ordering::Relaxed)
    }

    /// The back-pressure mode.
    #[must_use]
    pub fn backpressure(&self) -> BackPressure {
        self.backpressure
    }

    /// Subscribers connected now.
    #[must_use]
    pub fn subscribers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// This publisher's identity, written into every message ([`ScanHeader::publisher`]).
    #[must_use]
    pub fn identity(&self) -> u64 {
        self.core.identity
    }

    /// Waits (on events, with `timeout`) until at least `n` subscribers are connected and
    /// have said they are ready to take samples. Returns false on timeout or SIGINT/SIGTERM.
    pub fn wait_for_subscribers(&self, n: usize, timeout: Duration) -> Result<bool, ReceiveError> {
        let port = self.port();
        self.core
            .wait_until(timeout, &|| self.subscribers(), &|k, ready| {
                // Connect to them now so that they get their history without waiting for a send.
                let _ = port.update_connections();
                k >= n && ready >= n as u64
            })
    }

    /// After the end-of-stream marker: waits (with `timeout`) until every subscriber has
    /// left, so none loses what is still in its buffer when this process exits.
    pub fn linger(&self, timeout: Duration) -> Result<bool, ReceiveError> {
        // Nobody there: nothing to wait for, and a dead-node cleanup could only lower the count.
        if self.subscribers() == 0 {
            return Ok(true);
        }
        self.core
            .wait_until(timeout, &|| self.subscribers(), &|k, _| k == 0)
    }

    /// Whether SIGINT or SIGTERM arrived (iceoryx2 catches them to exit cleanly).
    #[must_use]
    pub fn interrupted(&self) -> bool {
        self.core.interrupted()
    }
}

type UninitScan =
    iceoryx2::sample_mut_uninit::SampleMutUninit<Ipc, [std::mem::MaybeUninit<f64>], ScanHeader>;
type ScanSample = iceoryx2::sample_mut::SampleMut<Ipc, [f64], ScanHeader>;

impl Drop for ScanPublisher {
    fn drop(&mut self) {
        // Leave first, then say so: a subscriber woken by the event must see us gone.
        self.publisher.take();
        let _ = self.core.signals.notify(event_id::PUBLISHER_LEFT);
    }
}

/// Publishes the matcher's poses on `<prefix>/pose` (always drop-oldest: the matcher never
/// waits for a slow pose consumer, which counts its gaps instead).
#[derive(Debug)]
pub struct PosePublisher {
    publisher: Option<Publisher<Ipc, PoseMessage, ()>>,
    service: publish_subscribe::PortFactory<Ipc, PoseMessage, ()>,
    core: PublisherCore,
}

impl PosePublisher {
    /// Opens (or creates) `<prefix>/pose` and a publisher on it. Fails with
    /// [`ConnectError::Owned`] if another process (another matcher) already publishes poses
    /// there.
    pub fn create(topics: &Topics) -> Result<Self, ConnectError> {
        let name = topics.pose();
        let node = shared_node(topics)?;
        let service = pose_service_builder(&node, &service_name(&name)?)
            .open_or_create()
            .map_err(|e| open_error(&name, BackPressure::DropOldest, e))?;
        single_owner(&name, service.static_config().max_publishers())?;
        let signals = Signals::open(&node, &name)?;
        let publisher = create_owner(&node, &name, || service.publisher_builder().create())?;
        let _ = signals.notify(event_id::PUBLISHER_CONNECTED);
        let unique_id = publisher.id().value();
        Ok(Self {
            publisher: Some(publisher),
            service,
            core: PublisherCore::new(name, signals, node, unique_id),
        })
    }

    /// Publishes one pose; `message.seq` and `message.publisher` are set here. Returns the
    /// sequence number.
    pub fn publish(&mut self, mut message: PoseMessage) -> Result<u64, PublishError> {
        let seq = self.core.sent;
        message.seq = seq;
        message.publisher = self.core.identity;
        self.write(message)?;
        self.core.sent += 1;
        Ok(seq)
    }

    /// Sends the end-of-stream marker.
    pub fn end_of_stream(&mut self) -> Result<(), PublishError> {
        self.write(PoseMessage {
            publisher: self.core.identity,
            ..PoseMessage::end_of_stream(self.core.sent)
        })
    }

    fn write(&self, message: PoseMessage) -> Result<(), PublishError> {
        let service = &self.core.service;
        let port = self
            .publisher
            .as_ref()
            .unwrap_or_else(|| unreachable!("the publisher is taken only on drop"));
        let sample = port.loan_uninit().map_err(|e| PublishError::Loan {
            service: service.clone(),
            detail: detail(e),
        })?;
        sample
            .write_payload(message)
            .send()
            .map_err(|e| PublishError::Send {
                service: service.clone(),
                detail: detail(e),
            })?;
        self.core.notify_sample()
    }

    /// Poses published so far.
    #[must_use]
    pub fn sent(&self) -> u64 {
        self.core.sent
    }

    /// Subscribers connected now.
    #[must_use]
    pub fn subscribers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Waits until every pose subscriber has left (or `timeout`).
    pub fn linger(&self, timeout: Duration) -> Result<bool, ReceiveError> {
        // Nobody there: nothing to wait for, and a dead-node cleanup could only lower the count.
        if self.subscribers() == 0 {
            return Ok(true);
        }
        self.core
            .wait_until(timeout, &|| self.subscribers(), &|k, _| k == 0)
    }
}

impl Drop for PosePublisher {
    fn drop(&mut self) {
        self.publisher.take();
        let _ = self.core.signals.notify(event_id::PUBLISHER_LEFT);
    }
}

/// Whether the publisher with iceoryx2's unique id `id` is still registered on the service (a
/// killed one stays until its dead node is removed).
fn publisher_connected(
    list: impl FnOnce(&mut dyn FnMut(&PublisherDetails) -> CallbackProgression),
    id: u128,
) -> bool {
    let mut found = false;
    list(&mut |details| {
        found = details.publisher_id.value() == id;
        if found {
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    found
}

/// What the receive loop needs to know of one sample.
struct Meta {
    version: u32,
    kind: u32,
    seq: u64,
    origin: u128,
}

/// The receive loop shared by both subscribers: wait on the WaitSet, drain the buffer,
/// check the numbers, watch the publisher's liveness; every wait bounded.
#[allow(clippy::too_many_arguments)]
fn run_loop<S>(
    node: &Node<Ipc>,
    signals: &Signals,
    service: &str,
    wait: &WaitOptions,
    receive: &dyn Fn() -> Result<Option<S>, String>,
    attach: &dyn Fn() -> Result<(), String>,
    publishers: &dyn Fn() -> usize,
    connected: &dyn Fn(u128) -> bool,
    meta: &dyn Fn(&S) -> Meta,
    deliver: &mut dyn FnMut(StreamEvent<&S>) -> ControlFlow<()>,
) -> Result<StreamReport, ReceiveError> {
    let wait_error = |detail: String| ReceiveError::Wait {
        service: service.to_string(),
        detail,
    };
    let waitset = WaitSetBuilder::new()
        .create::<Ipc>()
        .map_err(|e| wait_error(detail(e)))?;
    let _guard = waitset
        .attach_notification(&signals.listener)
        .map_err(|e| wait_error(detail(e)))?;

    let mut tracker = SequenceTracker::new();
    let started = Instant::now();
    let mut present = false;
    let mut lost_since: Option<Instant> = None;
    let mut last_activity = Instant::now();
    let mut last_cleanup = Instant::now();
    let mut known_publishers = 0;
    let mut publisher_connected = true;
    loop {
        // Attach to new publishers, then tell them (count read first: we attach to at least
        // those counted).
        let count = publishers();
        if publisher_connected || count > known_publishers {
            attach().map_err(|detail| ReceiveError::Receive {
                service: service.to_string(),
                detail,
            })?;
            if count > 0 {
                let _ = signals.notify(event_id::SUBSCRIBER_READY);
            }
        }
        known_publishers = count;

        // Drain the buffer.
        while let Some(sample) = receive().map_err(|detail| ReceiveError::Receive {
            service: service.to_string(),
            detail,
        })? {
            last_activity = Instant::now();
            let m = meta(&sample);
            if m.version != LAYOUT_VERSION {
                return Err(ReceiveError::LayoutVersion {
                    service: service.to_string(),
                    found: m.version,
                    expected: LAYOUT_VERSION,
                });
            }
            // One owner: another publisher's message (data or end marker) is never mixed in
            // while the owner is connected.
            match tracker.admit(m.origin, connected) {
                Admission::Admitted => {}
                Admission::Succeeds => {
                    if deliver(StreamEvent::PublisherLost).is_break() {
                        return Ok(tracker.finish(StreamEnd::Stopped));
                    }
                }
                Admission::Intruder { first } => {
                    if first && deliver(StreamEvent::Intruder).is_break() {
                        return Ok(tracker.finish(StreamEnd::Stopped));
                    }
                    continue;
                }
            }
            if m.kind == KIND_END_OF_STREAM {
                tracker.end_of_stream(m.origin, m.seq);
                return Ok(tracker.finish(StreamEnd::EndOfStream));
            }
            let event = match tracker.observe(m.origin, m.seq) {
                Observation::OutOfOrder => continue,
                Observation::InOrder => None,
                Observation::Gap { missing } => Some(StreamEvent::Gap { missing }),
                Observation::NewPublisher { skipped } => {
                    Some(StreamEvent::PublisherJoined { skipped })
                }
            };
            if let Some(event) = event
                && deliver(event).is_break()
            {
                return Ok(tracker.finish(StreamEnd::Stopped));
            }
            if deliver(StreamEvent::Data(&sample)).is_break() {
                return Ok(tracker.finish(StreamEnd::Stopped));
            }
        }

        // Liveness: a killed publisher stays registered until someone removes its dead
        // node; a quiet subscriber does so once per tick.
        let now = Instant::now();
        if now - last_activity >= wait.tick && now - last_cleanup >= wait.tick {
            node.try_cleanup_dead_nodes();
            last_cleanup = now;
        }
        if publishers() > 0 {
            present = true;
            lost_since = None;
            if now - last_activity > wait.idle_timeout {
                return Ok(tracker.finish(StreamEnd::Idle));
            }
        } else {
            if present {
                present = false;
                lost_since = Some(now);
                if tracker.has_open_stream() {
                    tracker.publisher_lost();
                    if deliver(StreamEvent::PublisherLost).is_break() {
                        return Ok(tracker.finish(StreamEnd::Stopped));
                    }
                }
            }
            match lost_since {
                Some(since) if now - since > wait.reconnect_timeout => {
                    return Ok(tracker.finish(StreamEnd::PublisherLost));
                }
                None if now - started > wait.connect_timeout => {
                    let end = if tracker.report().publishers_seen > 0 {
                        StreamEnd::PublisherLost
                    } else {
                        StreamEnd::NoPublisher
                    };
                    return Ok(tracker.finish(end));
                }
                _ => {}
            }
        }

        // Sleep until an event (a sample, a peer coming or going) or the next tick.
        let result = waitset
            .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, wait.tick)
            .map_err(|e| wait_error(detail(e)))?;
        if matches!(
            result,
            WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt
        ) {
            return Ok(tracker.finish(StreamEnd::Interrupted));
        }
        publisher_connected = signals.drain().map_err(wait_error)?.publisher_connected;
    }
}

fn subscriber_limits(
    options: &SubscriberOptions,
    history_max: usize,
    buffer_max: usize,
) -> Result<(usize, usize), ConnectError> {
    if options.history > history_max {
        return Err(ConnectError::Limit {
            what: "history",
            requested: options.history,
            limit: history_max,
        });
    }
    let buffer = if options.buffer == 0 {
        buffer_max
    } else {
        options.buffer.max(options.history)
    };
    if buffer > buffer_max {
        return Err(ConnectError::Limit {
            what: "buffer",
            requested: buffer,
            limit: buffer_max,
        });
    }
    Ok((options.history, buffer))
}

/// Receives scans from `<prefix>/scan`.
#[derive(Debug)]
pub struct ScanSubscriber {
    subscriber: Option<Subscriber<Ipc, [f64], ScanHeader>>,
    polled_publishers: std::cell::Cell<usize>,
    service: publish_subscribe::PortFactory<Ipc, [f64], ScanHeader>,
    signals: Signals,
    node: SharedNode,
    name: String,
    options: SubscriberOptions,
}

impl ScanSubscriber {
    /// Opens `<prefix>/scan` (adopting an existing service's back-pressure mode unless
    /// `options.backpressure` requires one) and subscribes.
    pub fn create(topics: &Topics, options: &SubscriberOptions) -> Result<Self, ConnectError> {
        let name = topics.scan();
        let (history, buffer) = subscriber_limits(options, SCAN_HISTORY_MAX, SCAN_BUFFER_MAX)?;
        let node = shared_node(topics)?;
        let sname = service_name(&name)?;
        let service = open_adopting(&name, options.backpressure, |overflow| {
            let b = scan_service_builder(&node, &sname);
            match overflow {
                Some(o) => b.enable_safe_overflow(o).create().map_err(Attempt::Create),
                None => b.open().map_err(Attempt::Open),
            }
        })?;
        single_owner(&name, service.static_config().max_publishers())?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(buffer)
            .history_request(history)
            .create()
            .map_err(|e| port_error("subscriber", &name, e))?;
        let signals = Signals::open(&node, &name)?;
        let _ = signals.notify(event_id::SUBSCRIBER_CONNECTED);
        Ok(Self {
            subscriber: Some(subscriber),
            polled_publishers: std::cell::Cell::new(usize::MAX),
            service,
            signals,
            node,
            name,
            options: options.clone(),
        })
    }

    /// The back-pressure mode of the service (adopted or required).
    #[must_use]
    pub fn backpressure(&self) -> BackPressure {
        BackPressure::of_overflow(self.service.static_config().has_safe_overflow())
    }

    /// Receives until the end-of-stream marker, a lost publisher (none back within the
    /// reconnect timeout), a timeout, a signal, or `on_event` breaks. Scans are lent to
    /// `on_event` in place; nothing is copied.
    pub fn run(
        &self,
        mut on_event: impl FnMut(StreamEvent<ScanView<'_>>) -> ControlFlow<()>,
    ) -> Result<StreamReport, ReceiveError> {
        let port = self
            .subscriber
            .as_ref()
            .unwrap_or_else(|| unreachable!("the subscriber is taken only on drop"));
        run_loop(
            &self.node,
            &self.signals,
            &self.name,
            &self.options.wait,
            &|| port.receive().map_err(detail),
            &|| port.update_connections().map_err(detail),
            &|| self.service.dynamic_config().number_of_publishers(),
            &|id| publisher_connected(|f| self.service.dynamic_config().list_publishers(f), id),
            &|s: &Sample<Ipc, [f64], ScanHeader>| Meta {
                version: s.user_header().layout_version,
                kind: s.user_header().kind,
                seq: s.user_header().seq,
                origin: s.origin().value(),
            },
            &mut |event| {
                on_event(match event {
                    StreamEvent::Data(s) => StreamEvent::Data(ScanView {
                        header: s.user_header(),
                        ranges: s.payload(),
                    }),
                    StreamEvent::PublisherJoined { skipped } => {
                        StreamEvent::PublisherJoined { skipped }
                    }
                    StreamEvent::PublisherLost => StreamEvent::PublisherLost,
                    StreamEvent::Gap { missing } => StreamEvent::Gap { missing },
                    StreamEvent::Intruder => StreamEvent::Intruder,
                })
            },
        )
    }
}

impl ScanSubscriber {
    /// Takes every scan waiting in the buffer without blocking, for a caller that runs its
    /// own cycle (a control loop, a busy-polling benchmark). No sequence bookkeeping: use
    /// [`ScanSubscriber::run`] for that. Returns the number of scans handed to `on_scan`.
    pub fn poll(&self, mut on_scan: impl FnMut(ScanView<'_>)) -> Result<usize, ReceiveError> {
        let port = self
            .subscriber
            .as_ref()
            .unwrap_or_else(|| unreachable!("the subscriber is taken only on drop"));
        let error = |detail| ReceiveError::Receive {
            service: self.name.clone(),
            detail,
        };
        let count = self.service.dynamic_config().number_of_publishers();
        if count != self.polled_publishers.get() {
            port.update_connections().map_err(|e| error(detail(e)))?;
            if count > 0 {
                let _ = self.signals.notify(event_id::SUBSCRIBER_READY);
            }
            self.polled_publishers.set(count);
        }
        let mut n = 0;
        while let Some(sample) = port.receive().map_err(|e| error(detail(e)))? {
            if sample.user_header().kind == KIND_END_OF_STREAM {
                continue;
            }
            on_scan(ScanView {
                header: sample.user_header(),
                ranges: sample.payload(),
            });
            n += 1;
        }
        Ok(n)
    }
}

impl Drop for ScanSubscriber {
    fn drop(&mut self) {
        self.subscriber.take();
        let _ = self.signals.notify(event_id::SUBSCRIBER_LEFT);
    }
}

/// Receives poses from `<prefix>/pose`.
#[derive(Debug)]
pub struct PoseSubscriber {
    subscriber: Option<Subscriber<Ipc, PoseMessage, ()>>,
    service: publish_subscribe::PortFactory<Ipc, PoseMessage, ()>,
    signals: Signals,
    node: SharedNode,
    name: String,
    options: SubscriberOptions,
}

impl PoseSubscriber {
    /// Opens `<prefix>/pose` and subscribes (`options.backpressure` is ignored: the pose
    /// stream is always drop-oldest).
    pub fn create(topics: &Topics, options: &SubscriberOptions) -> Result<Self, ConnectError> {
        let name = topics.pose();
        let (history, buffer) = subscriber_limits(options, POSE_HISTORY_MAX, POSE_BUFFER_MAX)?;
        let node = shared_node(topics)?;
        let service = pose_service_builder(&node, &service_name(&name)?)
            .open_or_create()
            .map_err(|e| open_error(&name, BackPressure::DropOldest, e))?;
        single_owner(&name, service.static_config().max_publishers())?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(buffer)
            .history_request(history)
            .create()
            .map_err(|e| port_error("subscriber", &name, e))?;
        let signals = Signals::open(&node, &name)?;
        let _ = signals.notify(event_id::SUBSCRIBER_CONNECTED);
        Ok(Self {
            subscriber: Some(subscriber),
            service,
            signals,
            node,
            name,
            options: options.clone(),
        })
    }

    /// Receives poses until the end-of-stream marker, a lost publisher, a timeout, a signal,
    /// or `on_event` breaks.
    pub fn run(
        &self,
        mut on_event: impl FnMut(StreamEvent<&PoseMessage>) -> ControlFlow<()>,
    ) -> Result<StreamReport, ReceiveError> {
        let port = self
            .subscriber
            .as_ref()
            .unwrap_or_else(|| unreachable!("the subscriber is taken only on drop"));
        run_loop(
            &self.node,
            &self.signals,
            &self.name,
            &self.options.wait,
            &|| port.receive().map_err(detail),
            &|| port.update_connections().map_err(detail),
            &|| self.service.dynamic_config().number_of_publishers(),
            &|id| publisher_connected(|f| self.service.dynamic_config().list_publishers(f), id),
            &|s: &Sample<Ipc, PoseMessage, ()>| Meta {
                version: s.payload().layout_version,
                kind: s.payload().kind,
                seq: s.payload().seq,
                origin: s.origin().value(),
            },
            &mut |event| {
                on_event(match event {
                    StreamEvent::Data(s) => StreamEvent::Data(s.payload()),
                    StreamEvent::PublisherJoined { skipped } => {
                        StreamEvent::PublisherJoined { skipped }
                    }
                    StreamEvent::PublisherLost => StreamEvent::PublisherLost,
                    StreamEvent::Gap { missing } => StreamEvent::Gap { missing },
                    StreamEvent::Intruder => StreamEvent::Intruder,
                })
            },
        )
    }
}

impl Drop for PoseSubscriber {
    fn drop(&mut self) {
        self.subscriber.take();
        let _ = self.signals.notify(event_id::SUBSCRIBER_LEFT);
    }
}

/// One attempt at opening or creating a service.
enum Attempt {
    Open(PublishSubscribeOpenError),
    Create(PublishSubscribeCreateError),
}

/// Opens the service if it exists, whatever its overflow setting (unless `required`), and
/// creates it with `required` (default `block`) if not; retries the race where another
/// process creates it in between.
fn open_adopting<T>(
    name: &str,
    required: Option<BackPressure>,
    attempt: impl Fn(Option<bool>) -> Result<T, Attempt>,
) -> Result<T, ConnectError>
where
    T: HasOverflow,
{
    let fail = |e: String| ConnectError::Service {
        service: name.to_string(),
        detail: e,
    };
    for _ in 0..100 {
        match attempt(None) {
            Ok(service) => {
                let existing = BackPressure::of_overflow(service.safe_overflow());
                return match required {
                    Some(r) if r != existing => Err(ConnectError::BackPressureMismatch {
                        service: name.to_string(),
                        existing: existing.name(),
                        requested: r.name(),
                    }),
                    _ => Ok(service),
                };
            }
            Err(Attempt::Open(PublishSubscribeOpenError::DoesNotExist)) => {}
            Err(Attempt::Open(e)) => return Err(fail(detail(e))),
            Err(Attempt::Create(e)) => return Err(fail(detail(e))),
        }
        let mode = required.unwrap_or_default();
        match attempt(Some(mode.safe_overflow())) {
            Ok(service) => return Ok(service),
            Err(Attempt::Create(
                PublishSubscribeCreateError::AlreadyExists
                | PublishSubscribeCreateError::IsBeingCreatedByAnotherInstance,
            )) => std::thread::sleep(Duration::from_millis(10)),
            Err(Attempt::Create(e)) => return Err(fail(detail(e))),
            Err(Attempt::Open(e)) => return Err(fail(detail(e))),
        }
    }
    Err(fail(detail(
        PublishSubscribeOpenOrCreateError::SystemInFlux,
    )))
}

trait HasOverflow {
    fn safe_overflow(&self) -> bool;
}

impl<P: std::fmt::Debug + IceoryxSend + ?Sized, H: std::fmt::Debug + ZeroCopySend> HasOverflow
    for publish_subscribe::PortFactory<Ipc, P, H>
{
    fn safe_overflow(&self) -> bool {
        self.static_config().has_safe_overflow()
    }
}
