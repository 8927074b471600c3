//! Sequence-number bookkeeping: no message is lost silently.
//!
//! Every data message carries `seq` = 0, 1, 2, … per publisher. The subscriber checks each
//! number against the one it expects and counts what it did not get, in three kinds:
//!
//! - **missed before join**: a subscriber that connects late (or asks for less history than
//!   was sent) first sees `seq = k > 0`; the `k` messages before it are not a transport loss;
//! - **gaps**: a jump inside a publisher's stream (drop-oldest overflow): `gap_events` jumps
//!   losing `missing` messages in total; the end-of-stream marker's `seq` (the number sent)
//!   also reveals a lost tail;
//! - **publisher lost**: a publisher that vanished (killed, crashed, or left without the
//!   end-of-stream marker); what it sent after the last received message is unknown.
//!
//! A stream has one owner: the publisher whose messages it follows. A message of any other
//! publisher while the owner is still connected (possible only on a service that allows more
//! than one publisher, which qicp refuses to create or join) is an **intruder**: counted,
//! never delivered, and its end-of-stream marker never ends the stream.

/// How a stream ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamEnd {
    /// The end-of-stream marker arrived.
    EndOfStream,
    /// The publisher vanished and none came back within the reconnect timeout.
    PublisherLost,
    /// No publisher appeared within the connect timeout.
    NoPublisher,
    /// A publisher is connected but sent nothing within the idle timeout.
    Idle,
    /// SIGINT or SIGTERM.
    Interrupted,
    /// The consumer's callback asked to stop.
    Stopped,
}

impl StreamEnd {
    /// A short name for reports (`end_of_stream`, `publisher_lost`, …).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            StreamEnd::EndOfStream => "end_of_stream",
            StreamEnd::PublisherLost => "publisher_lost",
            StreamEnd::NoPublisher => "no_publisher",
            StreamEnd::Idle => "idle",
            StreamEnd::Interrupted => "interrupted",
            StreamEnd::Stopped => "stopped",
        }
    }
}

/// What a subscriber saw of a stream, reported at its end. It serialises with `end` as
/// [`StreamEnd::name`] (`"running"` while the stream runs).
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize)]
pub struct StreamReport {
    /// Data messages received.
    pub received: u64,
    /// Messages sent before this subscriber joined that it did not get (beyond its history).
    pub missed_before_join: u64,
    /// Jumps in the sequence numbers (each loses one or more messages).
    pub gap_events: u64,
    /// Messages lost in those jumps (and in a lost tail revealed by the end marker).
    pub missing: u64,
    /// Messages that came with a number already seen or lower (never expected).
    pub out_of_order: u64,
    /// Distinct publishers seen (a restarted publisher counts again).
    pub publishers_seen: u64,
    /// Publishers that vanished without an end-of-stream marker.
    pub publishers_lost: u64,
    /// Messages (data or end markers) of another publisher while the owner was connected:
    /// ignored, never mixed into the stream.
    pub intruders: u64,
    /// The number of messages the publisher announced in its end-of-stream marker.
    pub announced: Option<u64>,
    /// How the stream ended (`None` while it runs).
    #[serde(serialize_with = "end_name")]
    pub end: Option<StreamEnd>,
}

fn end_name<S: serde::Serializer>(end: &Option<StreamEnd>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(end.map_or("running", StreamEnd::name))
}

impl StreamReport {
    /// True if the stream ended normally, every message sent was received and no other
    /// publisher intruded.
    #[must_use]
    pub fn is_complete(&self) -> bool {
        self.end == Some(StreamEnd::EndOfStream)
            && self.missing == 0
            && self.missed_before_join == 0
            && self.publishers_lost == 0
            && self.intruders == 0
    }
}

/// What one observed sequence number means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Observation {
    /// The number expected.
    InOrder,
    /// The first message of a new publisher; `skipped` messages were sent before it.
    NewPublisher {
        /// Messages of this publisher sent before the first one received.
        skipped: u64,
    },
    /// A jump: `missing` messages lost before this one.
    Gap {
        /// Messages lost.
        missing: u64,
    },
    /// A number at or below one already received.
    OutOfOrder,
}

/// Whether a message belongs to the stream ([`SequenceTracker::admit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admission {
    /// From the owner, or no stream is open: observe it.
    Admitted,
    /// The owner vanished without its end marker (now counted lost); this publisher follows
    /// it: observe it.
    Succeeds,
    /// Another publisher while the owner is connected: drop it (counted in `intruders`).
    Intruder {
        /// This publisher's first intrusion (report it once).
        first: bool,
    },
}

/// Tracks the sequence numbers of one subscriber's stream (across publisher restarts).
#[derive(Debug, Default)]
pub struct SequenceTracker {
    /// The current publisher (an opaque id) and the next number expected from it.
    current: Option<(u128, u64)>,
    /// Whether the current publisher's stream has ended (marker or loss already counted).
    current_closed: bool,
    /// Publishers whose messages were refused as intruders (each reported once).
    intruder_ids: Vec<u128>,
    report: StreamReport,
}

impl SequenceTracker {
    /// A tracker that has seen nothing.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a data message numbered `seq` from publisher `origin`.
    pub fn observe(&mut self, origin: u128, seq: u64) -> Observation {
        match self.current {
            Some((id, expected)) if id == origin => {
                let observation = if seq == expected {
                    Observation::InOrder
                } else if seq > expected {
                    self.report.gap_events += 1;
                    self.report.missing += seq - expected;
                    Observation::Gap {
                        missing: seq - expected,
                    }
                } else {
                    self.report.out_of_order += 1;
                    return Observation::OutOfOrder;
                };
                self.report.received += 1;
                self.current = Some((id, seq + 1));
                observation
            }
            _ => {
                if self.current.is_some() && !self.current_closed {
                    // The previous publisher was replaced before its end marker.
                    self.report.publishers_lost += 1;
                }
                self.report.publishers_seen += 1;
                self.report.missed_before_join += seq;
                self.report.received += 1;
                self.current = Some((origin, seq + 1));
                self.current_closed = false;
                Observation::NewPublisher { skipped: seq }
            }
        }
    }

    /// Records the end-of-stream marker of `origin`, announcing `sent` data messages.
    pub fn end_of_stream(&mut self, origin: u128, sent: u64) {
        match self.current {
            Some((id, expected)) if id == origin => {
                if sent > expected {
                    self.report.gap_events += 1;
                    self.report.missing += sent - expected;
                }
            }
            _ => {
                // A marker from a publisher we never got data from: everything it sent was
                // before we joined (or all lost, which the marker cannot tell apart).
                if self.current.is_some() && !self.current_closed {
                    self.report.publishers_lost += 1;
                }
                self.report.publishers_seen += 1;
                self.report.missed_before_join += sent;
                self.current = Some((origin, sent));
            }
        }
        self.current_closed = true;
        self.report.announced = Some(sent);
    }

    /// Records that the current publisher vanished without an end marker.
    pub fn publisher_lost(&mut self) {
        if self.current.is_some() && !self.current_closed {
            self.report.publishers_lost += 1;
            self.current_closed = true;
        }
    }

    /// The owner: the publisher of the open stream (seen, neither ended nor counted lost).
    #[must_use]
    pub fn owner(&self) -> Option<u128> {
        match self.current {
            Some((id, _)) if !self.current_closed => Some(id),
            _ => None,
        }
    }

    /// Decides whether a message (data or end marker) of `origin` belongs to the stream,
    /// before [`SequenceTracker::observe`] or [`SequenceTracker::end_of_stream`] is called
    /// for it. A message of another publisher than the owner is the owner's successor if the
    /// owner is gone (`owner_connected(owner)` false: the owner is counted lost) and an
    /// intruder otherwise (counted in `intruders`, to be dropped).
    pub fn admit(&mut self, origin: u128, owner_connected: impl FnOnce(u128) -> bool) -> Admission {
        match self.owner() {
            Some(owner) if owner != origin => {
                if owner_connected(owner) {
                    self.report.intruders += 1;
                    let first = !self.intruder_ids.contains(&origin);
                    if first {
                        self.intruder_ids.push(origin);
                    }
                    Admission::Intruder { first }
                } else {
                    self.publisher_lost();
                    Admission::Succeeds
                }
            }
            _ => Admission::Admitted,
        }
    }

    /// Whether a publisher was seen and has neither ended nor been counted lost.
    #[must_use]
    pub fn has_open_stream(&self) -> bool {
        self.current.is_some() && !self.current_closed
    }

    /// The report so far.
    #[must_use]
    pub fn report(&self) -> &StreamReport {
        &self.report
    }

    /// Ends the stream.
    #[must_use]
    pub fn finish(mut self, end: StreamEnd) -> StreamReport {
        self.report.end = Some(end);
        self.report
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `summary.json`'s `bridge` object embeds the report: its keys, and `end` by name
    /// ("running" until the stream ends).
    #[test]
    fn a_stream_report_serialises_with_its_end_by_name() {
        let running = serde_json::to_value(StreamReport::default()).expect("serialises");
        let keys: Vec<&str> = running
            .as_object()
            .expect("an object")
            .keys()
            .map(String::as_str)
            .collect();
        let mut want = [
            "received",
            "missed_before_join",
            "gap_events",
            "missing",
            "out_of_order",
            "publishers_seen",
            "publishers_lost",
            "intruders",
            "announced",
            "end",
        ];
        want.sort_unstable();
        let mut got = keys.clone();
        got.sort_unstable();
        assert_eq!(got, want);
        assert_eq!(running["end"], "running");
        assert!(running["announced"].is_null());
        let mut t = SequenceTracker::new();
        t.observe(1, 0);
        t.end_of_stream(1, 1);
        let ended = serde_json::to_value(t.finish(StreamEnd::EndOfStream)).expect("serialises");
        assert_eq!(ended["end"], "end_of_stream");
        assert_eq!(ended["received"], 1);
        assert_eq!(ended["announced"], 1);
    }

    #[test]
    fn in_order_stream_is_complete() {
        let mut t = SequenceTracker::new();
        for s in 0..10 {
            t.observe(1, s);
        }
        t.end_of_stream(1, 10);
        let r = t.finish(StreamEnd::EndOfStream);
        assert_eq!(r.received, 10);
        assert!(r.is_complete(), "{r:?}");
    }

    #[test]
    fn gaps_and_lost_tail_are_counted() {
        let mut t = SequenceTracker::new();
        for s in [0, 1, 4, 5, 9] {
            t.observe(1, s);
        }
        t.end_of_stream(1, 12);
        let r = t.finish(StreamEnd::EndOfStream);
        assert_eq!(r.received, 5);
        assert_eq!(r.gap_events, 3);
        assert_eq!(r.missing, 2 + 3 + 2);
        assert_eq!(r.received + r.missing, 12);
        assert!(!r.is_complete());
    }

    #[test]
    fn late_join_is_not_a_gap() {
        let mut t = SequenceTracker::new();
        assert_eq!(t.observe(1, 40), Observation::NewPublisher { skipped: 40 });
        t.observe(1, 41);
        t.end_of_stream(1, 42);
        let r = t.finish(StreamEnd::EndOfStream);
        assert_eq!((r.missed_before_join, r.gap_events, r.received), (40, 0, 2));
    }

    #[test]
    fn restarted_publisher_counts_the_lost_one() {
        let mut t = SequenceTracker::new();
        for s in 0..5 {
            t.observe(1, s);
        }
        t.publisher_lost();
        for s in 0..3 {
            t.observe(2, s);
        }
        t.end_of_stream(2, 3);
        let r = t.finish(StreamEnd::EndOfStream);
        assert_eq!(r.publishers_seen, 2);
        assert_eq!(r.publishers_lost, 1);
        assert_eq!(r.received, 8);
        assert_eq!(r.missing, 0);
    }

    #[test]
    fn replaced_publisher_without_notice_counts_as_lost_once() {
        let mut t = SequenceTracker::new();
        t.observe(1, 0);
        t.observe(2, 0);
        t.publisher_lost();
        t.observe(2, 1);
        let r = t.finish(StreamEnd::Stopped);
        assert_eq!(r.publishers_lost, 2);
        assert_eq!(r.out_of_order, 0);
    }

    /// The trial of issue 14: a second publisher's scans were mixed into the stream and its
    /// end marker ended it, while the first publisher was still connected.
    #[test]
    fn intruder_is_counted_never_mixed_and_its_end_marker_ends_nothing() {
        let mut t = SequenceTracker::new();
        let mut delivered = Vec::new();
        let mut ended = false;
        let messages = [
            (1, 0, false),
            (2, 0, false),
            (1, 1, false),
            (2, 1, false),
            (2, 2, true),
            (1, 2, false),
            (1, 3, true),
        ];
        for (origin, seq, end) in messages {
            match t.admit(origin, |_| true) {
                Admission::Intruder { .. } => continue,
                Admission::Succeeds => panic!("the owner is connected"),
                Admission::Admitted => {}
            }
            if end {
                t.end_of_stream(origin, seq);
                ended = true;
                break;
            }
            t.observe(origin, seq);
            delivered.push((origin, seq));
        }
        assert!(ended);
        assert_eq!(delivered, [(1, 0), (1, 1), (1, 2)]);
        let r = t.finish(StreamEnd::EndOfStream);
        assert_eq!(r.intruders, 3);
        assert_eq!(r.publishers_seen, 1);
        assert_eq!(
            (r.missing, r.missed_before_join, r.announced),
            (0, 0, Some(3))
        );
        assert!(
            !r.is_complete(),
            "an intruded stream is not complete: {r:?}"
        );
    }

    #[test]
    fn intruder_is_reported_once_per_publisher() {
        let mut t = SequenceTracker::new();
        assert_eq!(t.admit(1, |_| true), Admission::Admitted);
        t.observe(1, 0);
        assert_eq!(t.admit(2, |_| true), Admission::Intruder { first: true });
        assert_eq!(t.admit(2, |_| true), Admission::Intruder { first: false });
        assert_eq!(t.admit(3, |_| true), Admission::Intruder { first: true });
        assert_eq!(t.report().intruders, 3);
        assert_eq!(t.owner(), Some(1));
    }

    #[test]
    fn successor_of_a_vanished_owner_is_admitted_and_the_owner_counted_lost() {
        let mut t = SequenceTracker::new();
        t.observe(1, 0);
        t.observe(1, 1);
        assert_eq!(t.admit(2, |owner| owner != 1), Admission::Succeeds);
        assert_eq!(t.observe(2, 0), Observation::NewPublisher { skipped: 0 });
        t.end_of_stream(2, 1);
        let r = t.finish(StreamEnd::EndOfStream);
        assert_eq!(
            (r.publishers_seen, r.publishers_lost, r.intruders),
            (2, 1, 0)
        );
        assert_eq!(r.received, 3);
    }

    #[test]
    fn repeated_number_is_out_of_order() {
        let mut t = SequenceTracker::new();
        t.observe(1, 0);
        t.observe(1, 1);
        assert_eq!(t.observe(1, 1), Observation::OutOfOrder);
        assert_eq!(t.report().received, 2);
    }
}
