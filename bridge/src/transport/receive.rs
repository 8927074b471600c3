//! A subscriber's receive loop, one step at a time ([`Session`], `Subscriber::step`): the one
//! place that takes samples, checks their numbers and owners, watches the publisher's liveness
//! and waits. [`Subscriber::run`] and [`Records`](super::Records) both drive it.

use super::subscribe::Subscriber;
use super::*;
use iceoryx2::waitset::{WaitSet, WaitSetGuard};

/// Where a receive loop stands between two steps: the sequence bookkeeping and the clocks of
/// the connect, reconnect and idle timeouts.
#[derive(Debug)]
pub(super) struct Session {
    tracker: SequenceTracker,
    started: Instant,
    present: bool,
    lost_since: Option<Instant>,
    last_activity: Instant,
    last_cleanup: Instant,
    known_publishers: usize,
    publisher_announced: bool,
    /// Connections are refreshed before the next sample is taken: at the start and after
    /// every drain of the events.
    refresh: bool,
    /// Events may be pending since the last drain: a wait returned. They are drained once
    /// the buffer is empty, after the samples the wake-up announced were handed over, so
    /// that a sample's latency does not include the drain's system calls.
    undrained: bool,
}

impl Session {
    /// A loop about to start: the connect timeout counts from now.
    pub(super) fn new() -> Self {
        let now = Instant::now();
        Self {
            tracker: SequenceTracker::new(),
            started: now,
            present: false,
            lost_since: None,
            last_activity: now,
            last_cleanup: now,
            known_publishers: 0,
            publisher_announced: true,
            refresh: true,
            undrained: false,
        }
    }

    /// The report so far (`end` is `None` while the stream runs).
    pub(super) fn report(&self) -> &StreamReport {
        self.tracker.report()
    }

    /// Ends the stream.
    pub(super) fn finish(self, end: StreamEnd) -> StreamReport {
        self.tracker.finish(end)
    }
}

/// The WaitSet a subscriber waits in, and its event listener attached to it. Both borrow
/// the subscriber, so an iterator can hold them across calls.
pub(super) type Attached<'s> = (&'s WaitSet<Ipc>, WaitSetGuard<'s, 's, Ipc>);

impl<M: Message> Subscriber<M> {
    /// Attaches the event listener to this subscriber's WaitSet (created on first use).
    pub(super) fn attach(&self) -> Result<Attached<'_>, ReceiveError> {
        let wait_error = |e: String| ReceiveError::Wait {
            service: self.name.clone(),
            detail: e,
        };
        let waitset = match self.waitset.get() {
            Some(waitset) => waitset,
            None => {
                let waitset = WaitSetBuilder::new()
                    .create::<Ipc>()
                    .map_err(|e| wait_error(detail(e)))?;
                self.waitset.get_or_init(|| waitset)
            }
        };
        let guard = waitset
            .attach_notification(&self.signals.listener)
            .map_err(|e| wait_error(detail(e)))?;
        Ok((waitset, guard))
    }

    /// One step of the receive loop: refreshes the connections if due, then either handles
    /// the next sample in the buffer (its events and data go to `on_event`) or, the buffer
    /// empty, drains the events of the last wake-up (and looks again in the next step), or
    /// checks the publisher's liveness and waits in `waitset` for an event or the next tick.
    /// `Break(end)`: the stream ended (finish `session` with `end`).
    ///
    /// At most one data message reaches `on_event` per step.
    pub(super) fn step(
        &self,
        session: &mut Session,
        waitset: &WaitSet<Ipc>,
        on_event: &mut impl FnMut(StreamEvent<M::View<'_>>) -> ControlFlow<()>,
    ) -> Result<ControlFlow<StreamEnd>, ReceiveError> {
        let service = self.name.as_str();
        let wait = &self.options.wait;
        let signals = &self.signals;
        let port = self.port();
        let s = session;
        let wait_error = |detail: String| ReceiveError::Wait {
            service: service.to_string(),
            detail,
        };
        let receive_error = |detail: String| ReceiveError::Receive {
            service: service.to_string(),
            detail,
        };
        let stop = ControlFlow::Break(StreamEnd::Stopped);
        let go_on = ControlFlow::Continue(());

        if s.refresh {
            s.refresh = false;
            // Attach to new publishers, then tell them (count read first: we attach to at
            // least those counted).
            let count = self.publishers();
            if s.publisher_announced || count > s.known_publishers {
                port.update_connections()
                    .map_err(|e| receive_error(detail(e)))?;
                if count > 0 {
                    let _ = signals.notify(event_id::SUBSCRIBER_READY);
                }
            }
            s.known_publishers = count;
        }

        // The next sample in the buffer.
        if let Some(sample) = M::receive(port).map_err(|e| receive_error(detail(e)))? {
            s.last_activity = Instant::now();
            let m = M::stamp(&sample);
            let origin = sample.origin().value();
            if m.version != LAYOUT_VERSION {
                return Err(ReceiveError::LayoutVersion {
                    service: service.to_string(),
                    found: m.version,
                    expected: LAYOUT_VERSION,
                });
            }
            let connected =
                |id| publisher_connected(|f| self.service.dynamic_config().list_publishers(f), id);
            // One owner: another publisher's message (data or end marker) is never mixed in
            // while the owner is connected.
            match s.tracker.admit(origin, connected) {
                Admission::Admitted => {}
                Admission::Succeeds => {
                    if on_event(StreamEvent::PublisherLost).is_break() {
                        return Ok(stop);
                    }
                }
                Admission::Intruder { first } => {
                    if first && on_event(StreamEvent::Intruder).is_break() {
                        return Ok(stop);
                    }
                    return Ok(go_on);
                }
            }
            if m.kind == KIND_END_OF_STREAM {
                s.tracker.end_of_stream(origin, m.seq);
                return Ok(ControlFlow::Break(StreamEnd::EndOfStream));
            }
            let event = match s.tracker.observe(origin, m.seq) {
                Observation::OutOfOrder => return Ok(go_on),
                Observation::InOrder => None,
                Observation::Gap { missing } => Some(StreamEvent::Gap { missing }),
                Observation::NewPublisher { skipped } => {
                    Some(StreamEvent::PublisherJoined { skipped })
                }
            };
            if let Some(event) = event
                && on_event(event).is_break()
            {
                return Ok(stop);
            }
            if on_event(StreamEvent::Data(M::view(&sample))).is_break() {
                return Ok(stop);
            }
            return Ok(go_on);
        }

        // The buffer is empty: the events of the last wake-up are drained, the connections
        // refreshed (a new publisher announces itself by an event), and the buffer looked at
        // again. No wake-up is lost: a sample is in the buffer before its event is sent, so
        // every sample whose event the drain consumed is found by the look after it.
        if s.undrained {
            s.undrained = false;
            s.publisher_announced = signals.drain().map_err(wait_error)?.publisher_connected;
            s.refresh = true;
            return Ok(go_on);
        }

        // Liveness: a killed publisher stays registered until someone removes its dead node;
        // a quiet subscriber does so once per tick.
        let now = Instant::now();
        if now - s.last_activity >= wait.tick && now - s.last_cleanup >= wait.tick {
            self.node.try_cleanup_dead_nodes();
            s.last_cleanup = now;
        }
        if self.publishers() > 0 {
            s.present = true;
            s.lost_since = None;
            if now - s.last_activity > wait.idle_timeout {
                return Ok(ControlFlow::Break(StreamEnd::Idle));
            }
        } else {
            if s.present {
                s.present = false;
                s.lost_since = Some(now);
                if s.tracker.has_open_stream() {
                    s.tracker.publisher_lost();
                    if on_event(StreamEvent::PublisherLost).is_break() {
                        return Ok(stop);
                    }
                }
            }
            match s.lost_since {
                Some(since) if now - since > wait.reconnect_timeout => {
                    return Ok(ControlFlow::Break(StreamEnd::PublisherLost));
                }
                None if now - s.started > wait.connect_timeout => {
                    let end = if s.tracker.report().publishers_seen > 0 {
                        StreamEnd::PublisherLost
                    } else {
                        StreamEnd::NoPublisher
                    };
                    return Ok(ControlFlow::Break(end));
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
            return Ok(ControlFlow::Break(StreamEnd::Interrupted));
        }
        s.undrained = true;
        Ok(go_on)
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
