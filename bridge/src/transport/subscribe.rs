//! The subscribing ports and their wait loop: scans (read in place) and poses.

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
