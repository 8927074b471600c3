//! A scan subscriber as an iterator of owned records ([`Records`]): the pull side of
//! [`Subscriber::run`](super::Subscriber::run), driven by the same receive loop.

use super::receive::{Attached, Session};
use super::*;

/// The scans of a [`ScanSubscriber`], pulled one at a time as owned [`Record`]s
/// ([`ScanSubscriber::records`]).
///
/// Each `next` runs the subscriber's receive loop (the one [`Subscriber::run`] runs, with the
/// same connect, reconnect and idle timeouts, liveness checks and SIGINT/SIGTERM handling)
/// until the next scan, and copies it out of shared memory once
/// ([`ScanHeader::to_record`], as `qicp match --subscribe` does). It yields:
///
/// - `Some(Ok(record))`: the next scan of the stream, in order;
/// - `Some(Err(ReceiveError::Rejected { .. }))`: a scan that arrived but cannot become a
///   record (a pose that is not finite, a bad geometry): it counts in
///   [`StreamReport::received`] and [`Records::rejected`], and the iteration goes on;
/// - `Some(Err(_))`, any other error: the transport failed; the iteration ends there
///   (`None` next, [`Records::report`] keeps `end` at `None`);
/// - `None`: the stream ended (end-of-stream marker, publisher lost, no publisher, idle,
///   interrupted), as [`Records::report`]'s `end` says.
///
/// The stream's events (a publisher joined, a gap, a lost publisher, an intruder) are not
/// items: they are counted in [`Records::report`], as [`Subscriber::run`] counts them.
///
/// Being an `Iterator<Item = Result<Record, ReceiveError>>` whose error is
/// `Error + Send + Sync + 'static`, it is a `qicp_io::RecordSource` by that trait's blanket
/// impl (this crate does not depend on `qicp-io`): a matcher reads it as it reads a log.
pub struct Records<'s> {
    subscriber: &'s ScanSubscriber,
    attached: Attached<'s>,
    state: State,
    last_header: Option<ScanHeader>,
    rejected: u64,
}

/// A [`Records`] iteration: running, or ended with its report.
#[derive(Debug)]
enum State {
    Running(Box<Session>),
    Ended(StreamReport),
}

impl std::fmt::Debug for Records<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Records")
            .field("service", &self.subscriber.name)
            .field("state", &self.state)
            .field("last_header", &self.last_header)
            .field("rejected", &self.rejected)
            .finish_non_exhaustive()
    }
}

impl ScanSubscriber {
    /// The scans of this subscriber as an iterator of owned [`Record`]s that blocks for each
    /// (see [`Records`]). The stream starts when the iterator is made: the connect timeout
    /// counts from here.
    pub fn records(&mut self) -> Result<Records<'_>, ReceiveError> {
        let subscriber: &ScanSubscriber = self;
        Ok(Records {
            attached: subscriber.attach()?,
            subscriber,
            state: State::Running(Box::new(Session::new())),
            last_header: None,
            rejected: 0,
        })
    }
}

impl Records<'_> {
    /// What the subscriber saw of the stream so far; after the iteration ended, how it ended
    /// (`end`: `None` while running, or after a transport error).
    #[must_use]
    pub fn report(&self) -> &StreamReport {
        match &self.state {
            State::Running(session) => session.report(),
            State::Ended(report) => report,
        }
    }

    /// Whether the iteration has ended (`next` returns `None`).
    #[must_use]
    pub fn is_finished(&self) -> bool {
        matches!(self.state, State::Ended(_))
    }

    /// The header of the last scan yielded (a record or a rejected scan): its `seq` and
    /// `publisher` are what a pose answering it carries (`PoseMessage::scan_seq`,
    /// `PoseMessage::scan_publisher`).
    #[must_use]
    pub fn last_header(&self) -> Option<&ScanHeader> {
        self.last_header.as_ref()
    }

    /// Scans received that could not become records (yielded as
    /// [`ReceiveError::Rejected`]).
    #[must_use]
    pub fn rejected(&self) -> u64 {
        self.rejected
    }
}

impl Iterator for Records<'_> {
    type Item = Result<Record, ReceiveError>;

    fn next(&mut self) -> Option<Self::Item> {
        let State::Running(session) = &mut self.state else {
            return None;
        };
        let subscriber = self.subscriber;
        let (waitset, _) = &self.attached;
        let mut scan = None;
        loop {
            let step = subscriber.step(session, waitset, &mut |event| {
                if let StreamEvent::Data(view) = event {
                    scan = Some((*view.header, view.header.to_record(view.ranges)));
                }
                ControlFlow::Continue(())
            });
            match step {
                Ok(ControlFlow::Continue(())) => {}
                Ok(ControlFlow::Break(end)) => {
                    let report = match std::mem::replace(
                        &mut self.state,
                        State::Ended(StreamReport::default()),
                    ) {
                        State::Running(session) => session.finish(end),
                        State::Ended(report) => report,
                    };
                    self.state = State::Ended(report);
                    return None;
                }
                Err(e) => {
                    self.state = State::Ended(session.report().clone());
                    return Some(Err(e));
                }
            }
            if let Some((header, record)) = scan.take() {
                self.last_header = Some(header);
                return Some(record.map_err(|why| {
                    self.rejected += 1;
                    ReceiveError::Rejected {
                        service: subscriber.name.clone(),
                        seq: header.seq,
                        publisher: header.publisher,
                        why,
                    }
                }));
            }
        }
    }
}
