//! What differs between the two streams, for the generic ports ([`Publisher`](super::Publisher),
//! [`Subscriber`](super::Subscriber)): a scan is a [`ScanHeader`] (iceoryx2's user header)
//! followed by a slice of `beams` ranges; a pose is one fixed-size [`PoseMessage`] (the payload,
//! no user header).
//!
//! iceoryx2's typed API has separate methods for slice and fixed-size payloads (opening or
//! creating the service, loaning a sample, receiving one, reading its payload), so those few
//! calls are written once per stream here ([`Wire`](wire::Wire)); the ports' logic is generic.

use super::*;
use iceoryx2::port::LoanError;
use iceoryx2::service::builder::publish_subscribe::Builder;

/// The plumbing of a [`Message`] type: private to the crate (a sealed supertrait), so that the
/// streams and their wire format stay qicp's.
pub(crate) mod wire {
    use super::*;

    /// The publish-subscribe service of stream `M`.
    pub type Factory<M> =
        publish_subscribe::PortFactory<Ipc, <M as Wire>::Payload, <M as Wire>::Header>;
    /// The publisher port of stream `M`.
    pub type Port<M> = IoxPublisher<Ipc, <M as Wire>::Payload, <M as Wire>::Header>;
    /// The subscriber port of stream `M`.
    pub type SubscriberPort<M> = IoxSubscriber<Ipc, <M as Wire>::Payload, <M as Wire>::Header>;
    /// A sample of stream `M` received in place.
    pub type Received<M> = Sample<Ipc, <M as Wire>::Payload, <M as Wire>::Header>;
    /// A loaned sample of stream `M`, written and ready to send.
    pub type Outgoing<M> = SampleMut<Ipc, <M as Wire>::Payload, <M as Wire>::Header>;

    /// What the receive loop checks on every message.
    #[derive(Debug, Clone, Copy)]
    pub struct Stamp {
        /// [`LAYOUT_VERSION`](crate::messages::LAYOUT_VERSION) of the sender.
        pub version: u32,
        /// Data or end-of-stream.
        pub kind: u32,
        /// The sequence number.
        pub seq: u64,
    }

    /// How a service is reached.
    #[derive(Debug, Clone, Copy)]
    pub enum Finish {
        /// It must exist.
        Open,
        /// It must not exist yet.
        Create,
        /// Either.
        OpenOrCreate,
    }

    /// Why reaching a service failed.
    pub enum Attempt {
        /// [`Finish::Open`] failed.
        Open(PublishSubscribeOpenError),
        /// [`Finish::Create`] failed.
        Create(PublishSubscribeCreateError),
        /// [`Finish::OpenOrCreate`] failed.
        OpenOrCreate(PublishSubscribeOpenOrCreateError),
    }

    impl std::fmt::Debug for Attempt {
        /// iceoryx2's own error, as the error messages have always shown it.
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            match self {
                Attempt::Open(e) => e.fmt(f),
                Attempt::Create(e) => e.fmt(f),
                Attempt::OpenOrCreate(e) => e.fmt(f),
            }
        }
    }

    /// The calls iceoryx2 types differently for a slice and a fixed-size payload, and a
    /// stream's fixed settings.
    pub trait Wire: Sized + 'static {
        /// iceoryx2's payload type.
        type Payload: std::fmt::Debug + IceoryxSend + ?Sized + 'static;
        /// iceoryx2's user header type.
        type Header: std::fmt::Debug + ZeroCopySend + 'static;
        /// The back-pressure mode of a stream that has only one (`None`: chosen per service).
        const FIXED_BACKPRESSURE: Option<BackPressure>;
        /// History a subscriber may ask for at most.
        const HISTORY_MAX: usize;
        /// Largest subscriber buffer.
        const BUFFER_MAX: usize;

        /// The service name under `topics`.
        fn service(topics: &Topics) -> String;

        /// Opens and/or creates the service `builder` describes.
        fn finish(
            builder: Builder<Self::Payload, Self::Header, Ipc>,
            how: Finish,
        ) -> Result<Factory<Self>, Attempt>;

        /// A publisher port on `service`; `blocked` counts sends that found a subscriber full.
        fn publisher(
            service: &Factory<Self>,
            options: &PublisherOptions,
            blocked: &Arc<AtomicU64>,
        ) -> Result<Port<Self>, PublisherCreateError>;

        /// The end-of-stream marker of publisher `identity` after `sent` data messages.
        fn end_of_stream(
            port: &Port<Self>,
            identity: u64,
            sent: u64,
        ) -> Result<Outgoing<Self>, LoanError>;

        /// Takes the next sample from the subscriber's buffer.
        fn receive(
            port: &SubscriberPort<Self>,
        ) -> Result<Option<Received<Self>>, iceoryx2::port::ReceiveError>;

        /// The numbers of a received sample.
        fn stamp(sample: &Received<Self>) -> Stamp;
    }
}

use wire::{Attempt, Factory, Finish, Outgoing, Port, Received, Stamp, SubscriberPort, Wire};

/// A stream's message type, as the generic ports see it: [`ScanStream`] or [`PoseStream`].
/// Sealed: the streams and their wire format are qicp's.
pub trait Message: Wire + std::fmt::Debug {
    /// What a subscriber lends its callback for one data message, read in place from shared
    /// memory: a [`ScanView`] for scans, a `&PoseMessage` for poses.
    type View<'a>;

    /// The content of a received sample, in place.
    fn view(sample: &Received<Self>) -> Self::View<'_>;
}

/// The scan stream `<prefix>/scan`: payload `[f64]` (the ranges), user header [`ScanHeader`];
/// back-pressure chosen per service ([`PublisherOptions::backpressure`]).
#[derive(Debug)]
pub enum ScanStream {}

/// The pose stream `<prefix>/pose`: payload [`PoseMessage`], no user header; always
/// drop-oldest (the matcher never waits for a slow pose consumer, which counts its gaps
/// instead).
#[derive(Debug)]
pub enum PoseStream {}

impl Wire for ScanStream {
    type Payload = [f64];
    type Header = ScanHeader;
    const FIXED_BACKPRESSURE: Option<BackPressure> = None;
    const HISTORY_MAX: usize = SCAN_HISTORY_MAX;
    const BUFFER_MAX: usize = SCAN_BUFFER_MAX;

    fn service(topics: &Topics) -> String {
        topics.scan()
    }

    fn finish(
        builder: Builder<[f64], ScanHeader, Ipc>,
        how: Finish,
    ) -> Result<Factory<Self>, Attempt> {
        match how {
            Finish::Open => builder.open().map_err(Attempt::Open),
            Finish::Create => builder.create().map_err(Attempt::Create),
            Finish::OpenOrCreate => builder.open_or_create().map_err(Attempt::OpenOrCreate),
        }
    }

    fn publisher(
        service: &Factory<Self>,
        options: &PublisherOptions,
        blocked: &Arc<AtomicU64>,
    ) -> Result<Port<Self>, PublisherCreateError> {
        let counter = Arc::clone(blocked);
        let block_timeout = options.block_timeout;
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
    }

    fn end_of_stream(
        port: &Port<Self>,
        identity: u64,
        sent: u64,
    ) -> Result<Outgoing<Self>, LoanError> {
        let mut sample = port.loan_slice_uninit(0)?;
        *sample.user_header_mut() = ScanHeader {
            publisher: identity,
            ..ScanHeader::end_of_stream(sent)
        };
        Ok(sample.write_from_slice(&[]))
    }

    fn receive(
        port: &SubscriberPort<Self>,
    ) -> Result<Option<Received<Self>>, iceoryx2::port::ReceiveError> {
        port.receive()
    }

    fn stamp(sample: &Received<Self>) -> Stamp {
        let header = sample.user_header();
        Stamp {
            version: header.layout_version,
            kind: header.kind,
            seq: header.seq,
        }
    }
}

impl Message for ScanStream {
    type View<'a> = ScanView<'a>;

    fn view(sample: &Received<Self>) -> ScanView<'_> {
        ScanView {
            header: sample.user_header(),
            ranges: sample.payload(),
        }
    }
}

impl Wire for PoseStream {
    type Payload = PoseMessage;
    type Header = ();
    const FIXED_BACKPRESSURE: Option<BackPressure> = Some(BackPressure::DropOldest);
    const HISTORY_MAX: usize = POSE_HISTORY_MAX;
    const BUFFER_MAX: usize = POSE_BUFFER_MAX;

    fn service(topics: &Topics) -> String {
        topics.pose()
    }

    fn finish(
        builder: Builder<PoseMessage, (), Ipc>,
        how: Finish,
    ) -> Result<Factory<Self>, Attempt> {
        match how {
            Finish::Open => builder.open().map_err(Attempt::Open),
            Finish::Create => builder.create().map_err(Attempt::Create),
            Finish::OpenOrCreate => builder.open_or_create().map_err(Attempt::OpenOrCreate),
        }
    }

    /// iceoryx2's default publisher: the service overwrites a full subscriber's oldest pose,
    /// so no send ever waits.
    fn publisher(
        service: &Factory<Self>,
        _options: &PublisherOptions,
        _blocked: &Arc<AtomicU64>,
    ) -> Result<Port<Self>, PublisherCreateError> {
        service.publisher_builder().create()
    }

    fn end_of_stream(
        port: &Port<Self>,
        identity: u64,
        sent: u64,
    ) -> Result<Outgoing<Self>, LoanError> {
        Ok(port.loan_uninit()?.write_payload(PoseMessage {
            publisher: identity,
            ..PoseMessage::end_of_stream(sent)
        }))
    }

    fn receive(
        port: &SubscriberPort<Self>,
    ) -> Result<Option<Received<Self>>, iceoryx2::port::ReceiveError> {
        port.receive()
    }

    fn stamp(sample: &Received<Self>) -> Stamp {
        let message = sample.payload();
        Stamp {
            version: message.layout_version,
            kind: message.kind,
            seq: message.seq,
        }
    }
}

impl Message for PoseStream {
    type View<'a> = &'a PoseMessage;

    fn view(sample: &Received<Self>) -> &PoseMessage {
        sample.payload()
    }
}

/// The service of stream `M` on `node`, with the limits every qicp stream has (one publisher).
fn service_builder<M: Message>(
    node: &Node<Ipc>,
    name: &ServiceName,
) -> Builder<M::Payload, M::Header, Ipc> {
    node.service_builder(name)
        .publish_subscribe::<M::Payload>()
        .user_header::<M::Header>()
        .history_size(M::HISTORY_MAX)
        .subscriber_max_buffer_size(M::BUFFER_MAX)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_publishers(MAX_PUBLISHERS)
}

/// Opens (or creates) the service `name` of stream `M` in back-pressure `mode`; an existing
/// service in the other mode fails with [`ConnectError::BackPressureMismatch`].
pub(super) fn open_in_mode<M: Message>(
    node: &Node<Ipc>,
    name: &str,
    mode: BackPressure,
) -> Result<Factory<M>, ConnectError> {
    let builder = service_builder::<M>(node, &service_name(name)?);
    M::finish(
        builder.enable_safe_overflow(mode.safe_overflow()),
        Finish::OpenOrCreate,
    )
    .map_err(|e| open_error(name, mode, e))
}

/// Opens the service `name` of stream `M` if it exists, whatever its overflow setting (unless
/// `required`), and creates it with `required` (default `block`) if not; retries the race
/// where another process creates it in between.
pub(super) fn open_adopting<M: Message>(
    node: &Node<Ipc>,
    name: &str,
    required: Option<BackPressure>,
) -> Result<Factory<M>, ConnectError> {
    let sname = service_name(name)?;
    let fail = |e: String| ConnectError::Service {
        service: name.to_string(),
        detail: e,
    };
    for _ in 0..100 {
        match M::finish(service_builder::<M>(node, &sname), Finish::Open) {
            Ok(service) => {
                let existing =
                    BackPressure::of_overflow(service.static_config().has_safe_overflow());
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
            Err(e) => return Err(fail(detail(e))),
        }
        let mode = required.unwrap_or_default();
        let builder = service_builder::<M>(node, &sname).enable_safe_overflow(mode.safe_overflow());
        match M::finish(builder, Finish::Create) {
            Ok(service) => return Ok(service),
            Err(Attempt::Create(
                PublishSubscribeCreateError::AlreadyExists
                | PublishSubscribeCreateError::IsBeingCreatedByAnotherInstance,
            )) => std::thread::sleep(Duration::from_millis(10)),
            Err(e) => return Err(fail(detail(e))),
        }
    }
    Err(fail(detail(
        PublishSubscribeOpenOrCreateError::SystemInFlux,
    )))
}
