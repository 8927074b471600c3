//! The subscribing port, one for both streams ([`Subscriber<M>`]), and its wait loop.

use super::receive::Session;
use super::streams::wire::{Factory, SubscriberPort};
use super::streams::{open_adopting, open_in_mode};
use super::*;
use iceoryx2::waitset::WaitSet;

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

/// Receives the messages of stream `M`, read in place from shared memory, and checks their
/// numbers ([`StreamReport`]): gaps, a publisher that joined, was lost or intruded become
/// [`StreamEvent`]s.
#[derive(Debug)]
pub struct Subscriber<M: Message> {
    port: Option<SubscriberPort<M>>,
    polled_publishers: std::cell::Cell<usize>,
    pub(super) service: Factory<M>,
    pub(super) signals: Signals,
    pub(super) node: SharedNode,
    pub(super) name: String,
    pub(super) options: SubscriberOptions,
    /// The WaitSet the receive loop sleeps in, made on first use and kept for the next.
    pub(super) waitset: std::cell::OnceCell<WaitSet<Ipc>>,
}

/// Receives scans from `<prefix>/scan`.
pub type ScanSubscriber = Subscriber<ScanStream>;

/// Receives poses from `<prefix>/pose`.
pub type PoseSubscriber = Subscriber<PoseStream>;

impl<M: Message> Subscriber<M> {
    /// Opens the stream's service and subscribes. On `<prefix>/scan`, an existing service's
    /// back-pressure mode is adopted unless `options.backpressure` requires one (none: it is
    /// created in `block` mode); `<prefix>/pose` is always drop-oldest and
    /// `options.backpressure` is ignored.
    pub fn create(topics: &Topics, options: &SubscriberOptions) -> Result<Self, ConnectError> {
        let name = M::service(topics);
        let (history, buffer) = subscriber_limits(options, M::HISTORY_MAX, M::BUFFER_MAX)?;
        let node = shared_node(topics)?;
        let service = match M::FIXED_BACKPRESSURE {
            Some(mode) => open_in_mode::<M>(&node, &name, mode)?,
            None => open_adopting::<M>(&node, &name, options.backpressure)?,
        };
        single_owner(&name, service.static_config().max_publishers())?;
        let port = service
            .subscriber_builder()
            .buffer_size(buffer)
            .history_request(history)
            .create()
            .map_err(|e| port_error("subscriber", &name, e))?;
        let signals = Signals::open(&node, &name)?;
        let _ = signals.notify(event_id::SUBSCRIBER_CONNECTED);
        Ok(Self {
            port: Some(port),
            polled_publishers: std::cell::Cell::new(usize::MAX),
            service,
            signals,
            node,
            name,
            options: options.clone(),
            waitset: std::cell::OnceCell::new(),
        })
    }

    pub(super) fn port(&self) -> &SubscriberPort<M> {
        self.port
            .as_ref()
            .unwrap_or_else(|| unreachable!("the subscriber is taken only on drop"))
    }

    /// The back-pressure mode of the service (adopted or required).
    #[must_use]
    pub fn backpressure(&self) -> BackPressure {
        BackPressure::of_overflow(self.service.static_config().has_safe_overflow())
    }

    pub(super) fn publishers(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }

    /// Takes every message waiting in the buffer without blocking, for a caller that runs its
    /// own cycle (a control loop, a busy-polling benchmark); end-of-stream markers are
    /// skipped. No sequence bookkeeping: use [`Subscriber::run`] for that. Returns the number
    /// of messages handed to `on_message`.
    pub fn poll(&self, mut on_message: impl FnMut(M::View<'_>)) -> Result<usize, ReceiveError> {
        let port = self.port();
        let error = |detail| ReceiveError::Receive {
            service: self.name.clone(),
            detail,
        };
        let count = self.publishers();
        if count != self.polled_publishers.get() {
            port.update_connections().map_err(|e| error(detail(e)))?;
            if count > 0 {
                let _ = self.signals.notify(event_id::SUBSCRIBER_READY);
            }
            self.polled_publishers.set(count);
        }
        let mut n = 0;
        while let Some(sample) = M::receive(port).map_err(|e| error(detail(e)))? {
            if M::stamp(&sample).kind == KIND_END_OF_STREAM {
                continue;
            }
            on_message(M::view(&sample));
            n += 1;
        }
        Ok(n)
    }

    /// Receives until the end-of-stream marker, a lost publisher (none back within the
    /// reconnect timeout), a timeout, a signal, or `on_event` breaks. Messages are lent to
    /// `on_event` in place; nothing is copied.
    ///
    /// The loop waits on the WaitSet, drains the buffer, checks the numbers and watches the
    /// publisher's liveness; every wait is bounded. It is the same loop, step by step, as
    /// [`ScanSubscriber::records`] pulls scans from.
    pub fn run(
        &self,
        mut on_event: impl FnMut(StreamEvent<M::View<'_>>) -> ControlFlow<()>,
    ) -> Result<StreamReport, ReceiveError> {
        let (waitset, _attached) = self.attach()?;
        let mut session = Session::new();
        loop {
            if let ControlFlow::Break(end) = self.step(&mut session, waitset, &mut on_event)? {
                return Ok(session.finish(end));
            }
        }
    }
}

impl<M: Message> Drop for Subscriber<M> {
    fn drop(&mut self) {
        self.port.take();
        let _ = self.signals.notify(event_id::SUBSCRIBER_LEFT);
    }
}
