//! The ports' options and what they hand over: back-pressure, publisher, wait and subscriber
//! options, a subscriber's stream events and a received scan.

use super::*;

/// What a publisher does when a subscriber's buffer is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BackPressure {
    /// The publisher waits until the subscriber has room: lossless (replay, simulation).
    #[default]
    Block,
    /// The newest sample overwrites the subscriber's oldest; the subscriber counts the gap
    /// (live sensors, where a stale scan is worth less than a fresh one).
    DropOldest,
}

impl BackPressure {
    /// `block` or `drop-oldest`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            BackPressure::Block => "block",
            BackPressure::DropOldest => "drop-oldest",
        }
    }

    pub(super) fn safe_overflow(self) -> bool {
        self == BackPressure::DropOldest
    }

    pub(super) fn of_overflow(safe_overflow: bool) -> Self {
        if safe_overflow {
            BackPressure::DropOldest
        } else {
            BackPressure::Block
        }
    }
}

impl std::fmt::Display for BackPressure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for BackPressure {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "block" => Ok(BackPressure::Block),
            "drop-oldest" => Ok(BackPressure::DropOldest),
            other => Err(format!(
                "unknown back-pressure {other:?}: use block or drop-oldest"
            )),
        }
    }
}

/// Options of a scan publisher.
#[derive(Debug, Clone)]
pub struct PublisherOptions {
    /// Back-pressure mode (must match the service's if it already exists).
    pub backpressure: BackPressure,
    /// Beams per scan the shared-memory segment is first sized for; longer scans grow it
    /// (unless `fixed_size`).
    pub beams: usize,
    /// No scan will have more than `beams` ranges (a simulator's laser, a log whose longest
    /// scan is known): the segment is allocated once and never grows, and a longer scan fails
    /// to publish. Saves about 4 ms of start-up: iceoryx2 keeps per-chunk counters for each
    /// of the 255 segments a growing publisher may allocate (2,130 chunks × 255 × 8 bytes).
    pub fixed_size: bool,
    /// In `block` mode, how long one send may wait for a full subscriber before it fails.
    pub block_timeout: Duration,
}

impl Default for PublisherOptions {
    fn default() -> Self {
        Self {
            backpressure: BackPressure::Block,
            beams: 361,
            fixed_size: false,
            block_timeout: Duration::from_secs(30),
        }
    }
}

/// How long a subscriber waits for what.
#[derive(Debug, Clone, Copy)]
pub struct WaitOptions {
    /// For the first publisher to appear.
    pub connect_timeout: Duration,
    /// For a new publisher after one was lost.
    pub reconnect_timeout: Duration,
    /// For the next message while a publisher is connected.
    pub idle_timeout: Duration,
    /// How often a quiet subscriber checks that its publisher is alive.
    pub tick: Duration,
}

impl Default for WaitOptions {
    fn default() -> Self {
        Self {
            connect_timeout: Duration::from_secs(60),
            reconnect_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(120),
            tick: Duration::from_millis(100),
        }
    }
}

/// Options of a subscriber.
#[derive(Debug, Clone, Default)]
pub struct SubscriberOptions {
    /// Messages sent before this subscriber connected that it asks for (at most the
    /// service's history size).
    pub history: usize,
    /// Its buffer (0: the service's largest); raised to `history` if smaller.
    pub buffer: usize,
    /// The back-pressure mode to require; `None` adopts the mode of an existing service
    /// (and creates a `block` one if none exists yet).
    pub backpressure: Option<BackPressure>,
    /// Timeouts.
    pub wait: WaitOptions,
}

/// What a subscriber's callback is told.
#[derive(Debug)]
pub enum StreamEvent<M> {
    /// A data message.
    Data(M),
    /// A publisher's first message; `skipped` of its messages were sent before it.
    PublisherJoined {
        /// Messages of the new publisher sent before the first one received.
        skipped: u64,
    },
    /// The publisher vanished without an end-of-stream marker.
    PublisherLost,
    /// `missing` messages were lost just before the next one.
    Gap {
        /// Messages lost.
        missing: u64,
    },
    /// Another publisher sent on the service while the owner was connected (told once per
    /// intruder): its messages are dropped and counted ([`StreamReport::intruders`]).
    Intruder,
}

/// A received scan, read in place from shared memory.
#[derive(Debug, Clone, Copy)]
pub struct ScanView<'a> {
    /// The header.
    pub header: &'a ScanHeader,
    /// The ranges, still in the publisher's shared-memory segment.
    pub ranges: &'a [f64],
}
