//! The event half of a stream ([`Signals`]: wakes the other side) and the state every
//! publisher builds on it ([`PublisherCore`]).

use super::*;

/// The event half of a stream: wakes the other side.
#[derive(Debug)]
pub(super) struct Signals {
    notifier: Notifier<Ipc>,
    pub(super) listener: Listener<Ipc>,
    _service: event_factory::PortFactory<Ipc>,
}

impl Signals {
    pub(super) fn open(node: &Node<Ipc>, name: &str) -> Result<Self, ConnectError> {
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

    pub(super) fn notify(&self, id: usize) -> Result<usize, String> {
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
    pub(super) fn drain(&self) -> Result<Seen, String> {
        let mut seen = Seen::default();
        self.listener.try_wait(|e| seen.add(e)).map_err(detail)?;
        Ok(seen)
    }
}

/// The events of interest among those consumed.
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Seen {
    ready: u64,
    pub(super) publisher_connected: bool,
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
pub(super) struct PublisherCore {
    pub(super) service: String,
    pub(super) signals: Signals,
    node: SharedNode,
    pub(super) sent: u64,
    /// `SUBSCRIBER_READY` events seen since this publisher appeared.
    ready: std::cell::Cell<u64>,
    /// [`publisher_identity`] of the port, written into every message.
    pub(super) identity: u64,
}

impl PublisherCore {
    /// A publisher's shared state, before anything has been sent.
    pub(super) fn new(
        service: String,
        signals: Signals,
        node: SharedNode,
        unique_id: u128,
    ) -> Self {
        Self {
            service,
            signals,
            node,
            sent: 0,
            ready: std::cell::Cell::new(0),
            identity: publisher_identity(unique_id),
        }
    }

    pub(super) fn interrupted(&self) -> bool {
        self.node.wait(Duration::ZERO).is_err()
    }

    /// Waits until `count(subscribers)` holds or `timeout` passes; true if it holds.
    /// Dead subscribers are cleaned up on the way, so a killed one does not count.
    pub(super) fn wait_until(
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

    pub(super) fn notify_sample(&self) -> Result<(), PublishError> {
        self.signals
            .notify(event_id::SAMPLE)
            .map(|_| ())
            .map_err(|detail| PublishError::Notify {
                service: self.service.clone(),
                detail,
            })
    }
}
