//! The publishing ports: scans (ranges written straight into shared memory) and poses.

use super::*;

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
