//! The iceoryx2 side: services, publishers and subscribers, waiting.
//!
//! One generic port of each kind, [`Publisher<M>`] and [`Subscriber<M>`], serves both streams;
//! what differs between a scan and a pose ([`Message`]: a slice of ranges behind a header, or
//! one fixed-size message) is in `streams`. [`ScanPublisher`], [`PosePublisher`],
//! [`ScanSubscriber`] and [`PoseSubscriber`] are those ports on each stream.
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
use iceoryx2::port::publisher::{Publisher as IoxPublisher, PublisherCreateError};
use iceoryx2::port::subscriber::Subscriber as IoxSubscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
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

mod options;
pub mod payload;
mod publish;
mod receive;
mod records;
mod signals;
mod streams;
mod subscribe;

pub use options::{
    BackPressure, PublisherOptions, ScanView, StreamEvent, SubscriberOptions, WaitOptions,
};
pub use publish::{PosePublisher, Publisher, ScanPublisher};
pub use records::Records;
use signals::{PublisherCore, Signals};
pub use streams::{Message, PoseStream, ScanStream};
pub use subscribe::{PoseSubscriber, ScanSubscriber, Subscriber};

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
