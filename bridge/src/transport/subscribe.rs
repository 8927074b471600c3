//! The subscribing port, one for both streams ([`Subscriber<M>`]), and its wait loop.

use super::streams::wire::{Factory, SubscriberPort};
use super::streams::{open_adopting, open_in_mode};
use super::*;

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
    service: Factory<M>,
    signals: Signals,
    node: SharedNode,
    name: String,
    options: SubscriberOptions,
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
        })
    }

    fn port(&self) -> &SubscriberPort<M> {
        self.port
            .as_ref()
            .unwrap_or_else(|| unreachable!("the subscriber is taken only on drop"))
    }

    /// The back-pressure mode of the service (adopted or required).
    #[must_use]
    pub fn backpressure(&self) -> BackPressure {
        BackPressure::of_overflow(self.service.static_config().has_safe_overflow())
    }

    fn publishers(&self) -> usize {
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
    /// publisher's liveness; every wait is bounded.
    pub fn run(
        &self,
        mut on_event: impl FnMut(StreamEvent<M::View<'_>>) -> ControlFlow<()>,
    ) -> Result<StreamReport, ReceiveError> {
        let service = self.name.as_str();
        let wait = &self.options.wait;
        let signals = &self.signals;
        let port = self.port();
        let wait_error = |detail: String| ReceiveError::Wait {
            service: service.to_string(),
            detail,
        };
        let receive_error = |detail: String| ReceiveError::Receive {
            service: service.to_string(),
            detail,
        };
        let connected =
            |id| publisher_connected(|f| self.service.dynamic_config().list_publishers(f), id);
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
        let mut publisher_announced = true;
        loop {
            // Attach to new publishers, then tell them (count read first: we attach to at least
            // those counted).
            let count = self.publishers();
            if publisher_announced || count > known_publishers {
                port.update_connections()
                    .map_err(|e| receive_error(detail(e)))?;
                if count > 0 {
                    let _ = signals.notify(event_id::SUBSCRIBER_READY);
                }
            }
            known_publishers = count;

            // Drain the buffer.
            while let Some(sample) = M::receive(port).map_err(|e| receive_error(detail(e)))? {
                last_activity = Instant::now();
                let m = M::stamp(&sample);
                let origin = sample.origin().value();
                if m.version != LAYOUT_VERSION {
                    return Err(ReceiveError::LayoutVersion {
                        service: service.to_string(),
                        found: m.version,
                        expected: LAYOUT_VERSION,
                    });
                }
                // One owner: another publisher's message (data or end marker) is never mixed in
                // while the owner is connected.
                match tracker.admit(origin, connected) {
                    Admission::Admitted => {}
                    Admission::Succeeds => {
                        if on_event(StreamEvent::PublisherLost).is_break() {
                            return Ok(tracker.finish(StreamEnd::Stopped));
                        }
                    }
                    Admission::Intruder { first } => {
                        if first && on_event(StreamEvent::Intruder).is_break() {
                            return Ok(tracker.finish(StreamEnd::Stopped));
                        }
                        continue;
                    }
                }
                if m.kind == KIND_END_OF_STREAM {
                    tracker.end_of_stream(origin, m.seq);
                    return Ok(tracker.finish(StreamEnd::EndOfStream));
                }
                let event = match tracker.observe(origin, m.seq) {
                    Observation::OutOfOrder => continue,
                    Observation::InOrder => None,
                    Observation::Gap { missing } => Some(StreamEvent::Gap { missing }),
                    Observation::NewPublisher { skipped } => {
                        Some(StreamEvent::PublisherJoined { skipped })
                    }
                };
                if let Some(event) = event
                    && on_event(event).is_break()
                {
                    return Ok(tracker.finish(StreamEnd::Stopped));
                }
                if on_event(StreamEvent::Data(M::view(&sample))).is_break() {
                    return Ok(tracker.finish(StreamEnd::Stopped));
                }
            }

            // Liveness: a killed publisher stays registered until someone removes its dead
            // node; a quiet subscriber does so once per tick.
            let now = Instant::now();
            if now - last_activity >= wait.tick && now - last_cleanup >= wait.tick {
                self.node.try_cleanup_dead_nodes();
                last_cleanup = now;
            }
            if self.publishers() > 0 {
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
                        if on_event(StreamEvent::PublisherLost).is_break() {
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
            publisher_announced = signals.drain().map_err(wait_error)?.publisher_connected;
        }
    }
}

impl<M: Message> Drop for Subscriber<M> {
    fn drop(&mut self) {
        self.port.take();
        let _ = self.signals.notify(event_id::SUBSCRIBER_LEFT);
    }
}
