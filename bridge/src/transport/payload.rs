//! Opaque byte payloads of any size (a camera frame, a point cloud): the zero-copy path that
//! `qicp bench bridge --sizes` measures against a Unix-domain socket.
//!
//! The publisher loans a sample of `bytes` bytes in shared memory and the source writes the
//! payload straight into it ([`PayloadPublisher::publish_with`]); the subscriber reads it in
//! place ([`PayloadSubscriber::receive`]). Nothing is copied between the two.
//!
//! Each stream is its own service `<prefix>/payload`, sized for its payload: one publisher,
//! one subscriber, no history and a small buffer, so its shared memory holds a handful of
//! samples (a scan service, 8 subscribers × 256 buffered + 64 history, would hold 2,130).
//! Waiting is the same as for scans: `SAMPLE` events on the event service of the same name,
//! and the `SUBSCRIBER_READY` handshake before a `block` send.

use super::{
    Ipc, PublisherCore, SharedNode, Signals, Topics, event_id, service_name, shared_node,
    single_owner,
};
use crate::error::{ConnectError, PublishError, ReceiveError, detail, port_error};
use iceoryx2::port::BackpressureInfo;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe;
use iceoryx2::waitset::WaitSetRunResult;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

/// The user header of a payload sample (16 bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("qicp::PayloadHeader")]
pub struct PayloadHeader {
    /// 0, 1, 2, … per publisher.
    pub seq: u64,
    /// When the payload was complete and handed to the transport (the caller's clock, s).
    pub sent: f64,
}

/// The service `<prefix>/payload`.
fn payload_service(topics: &Topics) -> String {
    format!("{}/payload", topics.prefix)
}

type PayloadPort = publish_subscribe::PortFactory<Ipc, [u8], PayloadHeader>;

fn open(node: &Node<Ipc>, name: &str, buffer: usize) -> Result<PayloadPort, ConnectError> {
    let service = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<[u8]>()
        .user_header::<PayloadHeader>()
        .enable_safe_overflow(false)
        .history_size(0)
        .subscriber_max_buffer_size(buffer.max(1))
        .max_subscribers(1)
        .max_publishers(super::MAX_PUBLISHERS)
        .open_or_create()
        .map_err(|e| ConnectError::Service {
            service: name.to_string(),
            detail: detail(e),
        })?;
    single_owner(name, service.static_config().max_publishers())?;
    Ok(service)
}

/// Publishes byte payloads of up to `max_bytes` on `<prefix>/payload`, lossless (`block`).
#[derive(Debug)]
pub struct PayloadPublisher {
    publisher: Option<Publisher<Ipc, [u8], PayloadHeader>>,
    service: PayloadPort,
    core: PublisherCore,
    notify: bool,
}

impl PayloadPublisher {
    /// Creates the service (its subscriber buffers `buffer` payloads) and the publisher, whose
    /// shared memory is sized once for `max_bytes`. `notify`: signal a `SAMPLE` event after
    /// each send, for a subscriber that waits on events ([`PayloadSubscriber::run`] with
    /// [`Waiting::Event`]); a subscriber that polls needs none. A send waits at most
    /// `block_timeout` for a full subscriber, then fails.
    pub fn create(
        topics: &Topics,
        max_bytes: usize,
        buffer: usize,
        notify: bool,
        block_timeout: Duration,
    ) -> Result<Self, ConnectError> {
        let name = payload_service(topics);
        let node = shared_node(topics)?;
        let service = open(&node, &name, buffer)?;
        let signals = Signals::open(&node, &name)?;
        let publisher = super::create_owner(&node, &name, || {
            service
                .publisher_builder()
                .initial_max_slice_len(max_bytes.max(1))
                .allocation_strategy(AllocationStrategy::Static)
                .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
                .set_backpressure_handler(move |info: &BackpressureInfo| {
                    super::give_up_after(block_timeout, info)
                })
                .create()
        })?;
        let _ = signals.notify(event_id::PUBLISHER_CONNECTED);
        let unique_id = publisher.id().value();
        Ok(Self {
            publisher: Some(publisher),
            service,
            core: PublisherCore::new(name, signals, node, unique_id),
            notify,
        })
    }

    /// Waits until the subscriber is connected and ready to take samples (or `timeout`).
    pub fn wait_for_subscriber(&self, timeout: Duration) -> Result<bool, ReceiveError> {
        let port = self.port();
        self.core.wait_until(
            timeout,
            &|| self.service.dynamic_config().number_of_subscribers(),
            &|k, ready| {
                let _ = port.update_connections();
                k >= 1 && ready >= 1
            },
        )
    }

    fn port(&self) -> &Publisher<Ipc, [u8], PayloadHeader> {
        self.publisher
            .as_ref()
            .unwrap_or_else(|| unreachable!("the publisher is taken only on drop"))
    }

    /// Publishes a payload of `bytes` bytes that `fill(i)` writes, byte by byte, straight into
    /// the loaned shared memory. `sent` is called once the payload is complete, and its value
    /// travels in the header. Returns the sequence number.
    pub fn publish_with(
        &mut self,
        bytes: usize,
        fill: impl FnMut(usize) -> u8,
        sent: impl FnOnce() -> f64,
    ) -> Result<u64, PublishError> {
        let service = &self.core.service;
        let seq = self.core.sent;
        let sample = self
            .port()
            .loan_slice_uninit(bytes)
            .map_err(|e| PublishError::Loan {
                service: service.clone(),
                detail: detail(e),
            })?;
        let mut sample = sample.write_from_fn(fill);
        *sample.user_header_mut() = PayloadHeader { seq, sent: sent() };
        sample.send().map_err(|e| PublishError::Send {
            service: service.clone(),
            detail: detail(e),
        })?;
        if self.notify {
            self.core.notify_sample()?;
        }
        self.core.sent += 1;
        Ok(seq)
    }

    /// Payloads published so far.
    #[must_use]
    pub fn sent(&self) -> u64 {
        self.core.sent
    }
}

impl Drop for PayloadPublisher {
    fn drop(&mut self) {
        self.publisher.take();
        let _ = self.core.signals.notify(event_id::PUBLISHER_LEFT);
    }
}

/// Receives the byte payloads of `<prefix>/payload`, read in place.
#[derive(Debug)]
pub struct PayloadSubscriber {
    subscriber: Option<Subscriber<Ipc, [u8], PayloadHeader>>,
    service: PayloadPort,
    signals: Signals,
    _node: SharedNode,
    name: String,
    attached_to: std::cell::Cell<usize>,
}

impl PayloadSubscriber {
    /// Opens (or creates) `<prefix>/payload` with a buffer of `buffer` payloads and subscribes.
    pub fn create(topics: &Topics, buffer: usize) -> Result<Self, ConnectError> {
        let name = payload_service(topics);
        let node = shared_node(topics)?;
        let service = open(&node, &name, buffer)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(buffer.max(1))
            .create()
            .map_err(|e| port_error("subscriber", &name, e))?;
        let signals = Signals::open(&node, &name)?;
        let _ = signals.notify(event_id::SUBSCRIBER_CONNECTED);
        Ok(Self {
            subscriber: Some(subscriber),
            service,
            signals,
            _node: node,
            name,
            attached_to: std::cell::Cell::new(usize::MAX),
        })
    }

    fn port(&self) -> &Subscriber<Ipc, [u8], PayloadHeader> {
        self.subscriber
            .as_ref()
            .unwrap_or_else(|| unreachable!("the subscriber is taken only on drop"))
    }

    fn error(&self, e: impl std::fmt::Debug) -> ReceiveError {
        ReceiveError::Receive {
            service: self.name.clone(),
            detail: detail(e),
        }
    }

    /// Hands every payload waiting in the buffer to `on_payload`, in place (no copy), without
    /// blocking. Attaches to a new publisher first and tells it this subscriber is ready.
    /// Returns the number of payloads.
    pub fn receive(
        &self,
        mut on_payload: impl FnMut(&PayloadHeader, &[u8]),
    ) -> Result<usize, ReceiveError> {
        let port = self.port();
        let publishers = self.service.dynamic_config().number_of_publishers();
        if publishers != self.attached_to.get() {
            port.update_connections().map_err(|e| self.error(e))?;
            if publishers > 0 {
                let _ = self.signals.notify(event_id::SUBSCRIBER_READY);
            }
            self.attached_to.set(publishers);
        }
        let mut n = 0;
        while let Some(sample) = port.receive().map_err(|e| self.error(e))? {
            on_payload(sample.user_header(), sample.payload());
            n += 1;
        }
        Ok(n)
    }

    /// Receives until `on_payload` breaks, the publisher left (after the buffer is drained),
    /// or nothing happened for `stall`. Between payloads the thread sleeps in a WaitSet on
    /// the stream's events (`Waiting::Event`, the publisher must notify) or polls
    /// (`Waiting::Spin`). Returns the number of payloads.
    pub fn run(
        &self,
        waiting: Waiting,
        stall: Duration,
        mut on_payload: impl FnMut(&PayloadHeader, &[u8]) -> ControlFlow<()>,
    ) -> Result<u64, ReceiveError> {
        let wait_error = |e: String| ReceiveError::Wait {
            service: self.name.clone(),
            detail: e,
        };
        let waitset = WaitSetBuilder::new()
            .create::<Ipc>()
            .map_err(|e| wait_error(detail(e)))?;
        let _guard = waitset
            .attach_notification(&self.signals.listener)
            .map_err(|e| wait_error(detail(e)))?;
        let mut count = 0;
        let mut seen_publisher = false;
        let mut last_activity = Instant::now();
        // Whether events may be pending since the last drain. The wake-up's events are drained
        // after the payloads it announced were handed over, not before, so that a payload's
        // latency does not include the drain's system calls. Every drain is followed by
        // another look at the buffer, so no wake-up is lost: a payload is in the buffer
        // before its event is sent, and every payload whose event a drain consumed is found
        // by the look after it.
        let mut undrained = false;
        loop {
            // Counted before the look: a publisher gone by now left its payloads in the
            // buffer, so an empty look after it means they were all taken.
            let publishers = self.service.dynamic_config().number_of_publishers();
            let mut stop = false;
            let n = self.receive(|header, payload| {
                if !stop {
                    count += 1;
                    stop = on_payload(header, payload).is_break();
                }
            })?;
            if stop {
                return Ok(count);
            }
            if n > 0 {
                last_activity = Instant::now();
            }
            if undrained {
                self.signals.drain().map_err(wait_error)?;
                undrained = false;
                continue;
            }
            seen_publisher |= publishers > 0;
            if n == 0 && ((seen_publisher && publishers == 0) || last_activity.elapsed() > stall) {
                // The publisher left and its payloads were taken, or nothing came for too long.
                return Ok(count);
            }
            match waiting {
                Waiting::Spin => std::hint::spin_loop(),
                Waiting::Event => {
                    let result = waitset
                        .wait_and_process_once_with_timeout(
                            |_| CallbackProgression::Continue,
                            stall.min(Duration::from_millis(100)),
                        )
                        .map_err(|e| wait_error(detail(e)))?;
                    if matches!(
                        result,
                        WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt
                    ) {
                        return Ok(count);
                    }
                    undrained = true;
                }
            }
        }
    }
}

/// How a [`PayloadSubscriber`] waits for the next payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Waiting {
    /// Asleep in a WaitSet until the publisher's event.
    Event,
    /// Polling the buffer without sleeping.
    Spin,
}

impl Drop for PayloadSubscriber {
    fn drop(&mut self) {
        self.subscriber.take();
        let _ = self.signals.notify(event_id::SUBSCRIBER_LEFT);
    }
}
