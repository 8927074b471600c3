//! The publishing port, one for both streams ([`Publisher<M>`]), and what only a scan or a pose
//! publisher does: the message it builds and how it is created.

use super::streams::open_in_mode;
use super::streams::wire::{Factory, Outgoing, Port};
use super::*;

/// Publishes the messages of stream `M` on its service, which it owns: one publisher per
/// service ([`ConnectError::Owned`] for a second one). Every message carries its sequence
/// number and this publisher's [`identity`](Publisher::identity); the stream ends with an
/// end-of-stream marker ([`Publisher::end_of_stream`]).
#[derive(Debug)]
pub struct Publisher<M: Message> {
    port: Option<Port<M>>,
    service: Factory<M>,
    core: PublisherCore,
    backpressure: BackPressure,
    blocked: Arc<AtomicU64>,
    /// A subscriber was connected at some send: in `block` mode, none being left is an error.
    had_subscriber: bool,
}

/// Publishes scans on `<prefix>/scan`; the ranges are written straight into loaned shared
/// memory (the only write; subscribers read them in place).
pub type ScanPublisher = Publisher<ScanStream>;

/// Publishes the matcher's poses on `<prefix>/pose` (always drop-oldest: the matcher never
/// waits for a slow pose consumer, which counts its gaps instead).
pub type PosePublisher = Publisher<PoseStream>;

impl<M: Message> Publisher<M> {
    /// Opens (or creates) the stream's service and the one publisher on it.
    fn connect(topics: &Topics, options: &PublisherOptions) -> Result<Self, ConnectError> {
        let name = M::service(topics);
        let backpressure = M::FIXED_BACKPRESSURE.unwrap_or(options.backpressure);
        let node = shared_node(topics)?;
        let service = open_in_mode::<M>(&node, &name, backpressure)?;
        single_owner(&name, service.static_config().max_publishers())?;
        // Listen before registering: a subscriber's READY answers our registration.
        let signals = Signals::open(&node, &name)?;
        let blocked = Arc::new(AtomicU64::new(0));
        let port = create_owner(&node, &name, || M::publisher(&service, options, &blocked))?;
        let _ = signals.notify(event_id::PUBLISHER_CONNECTED);
        let unique_id = port.id().value();
        Ok(Self {
            port: Some(port),
            service,
            core: PublisherCore::new(name, signals, node, unique_id),
            backpressure,
            blocked,
            had_subscriber: false,
        })
    }

    fn port(&self) -> &Port<M> {
        self.port
            .as_ref()
            .unwrap_or_else(|| unreachable!("the publisher is taken only on drop"))
    }

    /// Sends the next data message, which `write(self, seq)` loans and fills; returns its
    /// sequence number. In `block` mode, fails with
    /// [`PublishError::SubscribersLeft`] once every subscriber that was there has left.
    fn send(
        &mut self,
        write: impl FnOnce(&Self, u64) -> Result<Outgoing<M>, PublishError>,
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
        let sample = write(self, seq)?;
        self.deliver(sample)?;
        self.core.sent += 1;
        Ok(seq)
    }

    fn loan_error(&self, e: impl std::fmt::Debug) -> PublishError {
        PublishError::Loan {
            service: self.core.service.clone(),
            detail: detail(e),
        }
    }

    fn deliver(&self, sample: Outgoing<M>) -> Result<(), PublishError> {
        sample.send().map_err(|e| PublishError::Send {
            service: self.core.service.clone(),
            detail: detail(e),
        })?;
        self.core.notify_sample()
    }

    /// Sends the end-of-stream marker (no data; its `seq` is the number of messages sent).
    pub fn end_of_stream(&mut self) -> Result<(), PublishError> {
        let sample = M::end_of_stream(self.port(), self.core.identity, self.core.sent)
            .map_err(|e| self.loan_error(e))?;
        self.deliver(sample)
    }

    /// Data messages published so far.
    #[must_use]
    pub fn sent(&self) -> u64 {
        self.core.sent
    }

    /// The service name (`<prefix>/scan`, `<prefix>/pose`).
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

    /// This publisher's identity, written into every message ([`ScanHeader::publisher`],
    /// [`PoseMessage::publisher`]).
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

impl<M: Message> Drop for Publisher<M> {
    fn drop(&mut self) {
        // Leave first, then say so: a subscriber woken by the event must see us gone.
        self.port.take();
        let _ = self.core.signals.notify(event_id::PUBLISHER_LEFT);
    }
}

impl Publisher<ScanStream> {
    /// Opens (or creates) `<prefix>/scan` and a publisher on it.
    /// Fails with [`ConnectError::Owned`] if another publisher owns the service.
    pub fn create(topics: &Topics, options: &PublisherOptions) -> Result<Self, ConnectError> {
        Self::connect(topics, options)
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
        self.send_scan(header, ranges.len(), |sample| {
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
        self.send_scan(header, beams, |sample| sample.write_from_fn(range))
    }

    fn send_scan(
        &mut self,
        mut header: ScanHeader,
        beams: usize,
        write: impl FnOnce(UninitScan) -> Outgoing<ScanStream>,
    ) -> Result<u64, PublishError> {
        self.send(|this, seq| {
            header.layout_version = LAYOUT_VERSION;
            header.kind = crate::messages::KIND_DATA;
            header.seq = seq;
            header.publisher = this.core.identity;
            header.beams =
                u32::try_from(beams).map_err(|_| PublishError::TooManyBeams { beams })?;
            let mut sample = this
                .port()
                .loan_slice_uninit(beams)
                .map_err(|e| this.loan_error(e))?;
            *sample.user_header_mut() = header;
            Ok(write(sample))
        })
    }
}

type UninitScan =
    iceoryx2::sample_mut_uninit::SampleMutUninit<Ipc, [std::mem::MaybeUninit<f64>], ScanHeader>;

impl Publisher<PoseStream> {
    /// Opens (or creates) `<prefix>/pose` and a publisher on it. Fails with
    /// [`ConnectError::Owned`] if another process (another matcher) already publishes poses
    /// there.
    pub fn create(topics: &Topics) -> Result<Self, ConnectError> {
        Self::connect(topics, &PublisherOptions::default())
    }

    /// Publishes one pose; `message.seq` and `message.publisher` are set here. Returns the
    /// sequence number.
    pub fn publish(&mut self, mut message: PoseMessage) -> Result<u64, PublishError> {
        self.send(|this, seq| {
            message.seq = seq;
            message.publisher = this.core.identity;
            let sample = this.port().loan_uninit().map_err(|e| this.loan_error(e))?;
            Ok(sample.write_payload(message))
        })
    }
}
