//! The publishing driver: a drive (a log, a simulation, any iterator of records) published on
//! `<prefix>/scan` at a chosen pace, then the end-of-stream marker.
//!
//! [`publish_records`] creates the [`ScanPublisher`], waits for the subscribers it needs,
//! paces the scans ([`Rate`]) and reports what it did ([`PublishReport`]); the options are a
//! plain [`DriveOptions`] (the command line's `qicp sim --publish` and
//! `qicp replay --publish` fill it from their flags). Its errors are [`DriveError`]s.

use crate::error::{ConnectError, DriveError};
use crate::transport::{BackPressure, DEFAULT_PREFIX, PublisherOptions, ScanPublisher, Topics};
use qicp_core::Record;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The longest wait any timing option accepts (s): one day. A bound catches `inf`, `1e300` and
/// a typo, and keeps every wait a valid `Duration`.
pub const MAX_SECONDS: f64 = 86_400.0;

/// Slowest and fastest `--rate` factor (`0.001x` .. `1000000x`).
pub const RATE_FACTOR_RANGE: (f64, f64) = (1e-3, 1e6);

/// Records a source may produce ahead of the publisher while it starts (about 1.5 MB of
/// 181-beam scans).
pub const PREFETCH: usize = 1024;

/// How fast a recorded or simulated drive is published.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Rate {
    /// At the pace of the record timestamps.
    Realtime,
    /// As fast as the subscribers take them (back-pressure permitting).
    #[default]
    Max,
    /// `N` times the pace of the timestamps (`--rate 10x`).
    Factor(f64),
}

impl std::str::FromStr for Rate {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "realtime" => Ok(Rate::Realtime),
            "max" => Ok(Rate::Max),
            other => {
                let (slowest, fastest) = RATE_FACTOR_RANGE;
                other
                    .strip_suffix('x')
                    .and_then(|f| f.parse::<f64>().ok())
                    .filter(|f| (slowest..=fastest).contains(f))
                    .map(Rate::Factor)
                    .ok_or_else(|| {
                        format!(
                            "bad rate {other:?}: use realtime, max or a factor from {slowest}x \
                             to {fastest}x, like 10x"
                        )
                    })
            }
        }
    }
}

/// `realtime`, `max` or `Nx`, as `--rate` takes it.
impl std::fmt::Display for Rate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Rate::Realtime => f.write_str("realtime"),
            Rate::Max => f.write_str("max"),
            Rate::Factor(factor) => write!(f, "{factor}x"),
        }
    }
}

impl Rate {
    /// The speed-up over the timestamps' pace; `None` for [`Rate::Max`] (no pacing).
    #[must_use]
    pub fn speed(self) -> Option<f64> {
        match self {
            Rate::Realtime => Some(1.0),
            Rate::Max => None,
            Rate::Factor(f) => Some(f),
        }
    }
}

/// How [`publish_records`] publishes a drive. The timing options are seconds, as the command
/// line takes them (finite, above 0, at most [`MAX_SECONDS`]); anything else is clamped by
/// [`secs`].
#[derive(Debug, Clone, PartialEq)]
pub struct DriveOptions {
    /// Service prefix: the scans go on `<prefix>/scan` (default [`DEFAULT_PREFIX`]).
    pub prefix: String,
    /// iceoryx2 configuration file (TOML) of the publisher's node (default `None`: iceoryx2's
    /// built-in settings; never a file found in the working directory).
    pub iceoryx2_config: Option<PathBuf>,
    /// Pace (default [`Rate::Max`]).
    pub rate: Rate,
    /// Back-pressure mode (default [`BackPressure::Block`]).
    pub backpressure: BackPressure,
    /// Subscribers to wait for before the first scan (default `None`: 1 in block mode, 0 in
    /// drop-oldest mode).
    pub wait_subscribers: Option<usize>,
    /// Seconds to wait for them (default 60).
    pub connect_timeout: f64,
    /// Seconds to wait after the end-of-stream marker for the subscribers to leave (default 10).
    pub linger: f64,
    /// Seconds one send may wait for a full subscriber in block mode before failing (default
    /// 30).
    pub block_timeout: f64,
}

impl Default for DriveOptions {
    fn default() -> Self {
        Self {
            prefix: DEFAULT_PREFIX.to_string(),
            iceoryx2_config: None,
            rate: Rate::Max,
            backpressure: BackPressure::Block,
            wait_subscribers: None,
            connect_timeout: 60.0,
            linger: 10.0,
            block_timeout: 30.0,
        }
    }
}

impl DriveOptions {
    /// The subscribers to wait for: [`DriveOptions::wait_subscribers`], else 1 in block mode
    /// and 0 in drop-oldest mode.
    #[must_use]
    pub fn subscribers_wanted(&self) -> usize {
        self.wait_subscribers.unwrap_or(match self.backpressure {
            BackPressure::Block => 1,
            BackPressure::DropOldest => 0,
        })
    }

    /// The topics of [`DriveOptions::prefix`] in the iceoryx2 configuration given.
    pub fn topics(&self) -> Result<Topics, ConnectError> {
        topics(&self.prefix, self.iceoryx2_config.as_deref())
    }
}

/// The topics of `prefix` in the iceoryx2 configuration of `file` (built-in defaults if none).
pub fn topics(prefix: &str, file: Option<&Path>) -> Result<Topics, ConnectError> {
    let topics = Topics::new(prefix);
    match file {
        Some(file) => topics.with_config_file(file),
        None => Ok(topics),
    }
}

/// What a publisher reports at its end (the command line prints it as JSON on stdout).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PublishReport {
    /// The scan service.
    pub service: String,
    /// Back-pressure mode.
    pub backpressure: String,
    /// Scans published.
    pub published: u64,
    /// Sends that found a subscriber full and waited (block mode).
    pub blocked_sends: u64,
    /// Whether SIGINT/SIGTERM cut the drive short (the end marker is still sent).
    pub interrupted: bool,
    /// Whether every subscriber left before the linger timeout.
    pub subscribers_left: bool,
    /// Wall time from the first scan to the end marker (s).
    pub wall_seconds: f64,
}

/// A wait of `s` seconds; timing options are bounded where they are parsed, and anything else
/// (negative, NaN, beyond [`MAX_SECONDS`]) is clamped rather than trusted.
#[must_use]
pub fn secs(s: f64) -> Duration {
    let s = if s.is_nan() { 0.0 } else { s };
    Duration::from_secs_f64(s.clamp(0.0, MAX_SECONDS))
}

/// The error of a record source.
fn source_error(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> DriveError {
    DriveError::Source(e.into())
}

/// Publishes `records` (in time order) on `<prefix>/scan`, then the end-of-stream marker.
/// No record may have more than `beams` ranges: the shared-memory segment is sized for
/// that once ([`PublisherOptions::fixed_size`]). A record the source fails to make ends the
/// drive with [`DriveError::Source`] (no end marker).
///
/// Start-up overlaps with the source: while this thread sets up its iceoryx2 ports and waits
/// for subscribers, a second thread already pulls records (a simulator computes its first
/// scans), up to [`PREFETCH`] ahead. Once the subscribers are ready, this thread publishes
/// that backlog while the source goes on; when it has caught up, the source thread stops and
/// hands the source back, and this thread pulls the rest itself, so the drive does not pay a
/// thread hand-off per record. (Paced by [`DriveOptions::rate`], it never catches up: the
/// source thread then runs to the end.) Order, pacing (counted from the first scan sent) and
/// back-pressure are unchanged.
pub fn publish_records<E>(
    records: impl Iterator<Item = Result<Record, E>> + Send,
    beams: usize,
    options: &DriveOptions,
) -> Result<PublishReport, DriveError>
where
    E: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    use std::sync::atomic::{AtomicBool, Ordering};
    // A bad iceoryx2 configuration is refused before the source starts.
    options.topics()?;
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let (tx, rx) = std::sync::mpsc::sync_channel(PREFETCH);
        let stop = &stop;
        let source = std::thread::Builder::new()
            .name("qicp-source".to_string())
            .spawn_scoped(scope, move || {
                let mut records = records;
                while !stop.load(Ordering::Acquire) {
                    let Some(record) = records.next() else { break };
                    // The publisher gave up (an error, an interrupt): stop producing.
                    if tx.send(record.map_err(source_error)).is_err() {
                        break;
                    }
                }
                records
            })
            .map_err(DriveError::SourceThread)?;
        // On an error `rx` is dropped on return: the source stops before the scope joins it.
        let mut publisher = connect(beams, options)?;
        let mut drive = Drive::new(options.rate);
        // Publish the backlog while the source keeps producing (a full subscriber buffer
        // holds this thread up, not the simulator), until this thread has caught up with it.
        loop {
            match rx.try_recv() {
                Ok(record) => {
                    if !drive.publish(&mut publisher, record?)? {
                        break;
                    }
                }
                Err(std::sync::mpsc::TryRecvError::Empty) => break,
                Err(std::sync::mpsc::TryRecvError::Disconnected) => break,
            }
        }
        stop.store(true, Ordering::Release);
        // What the source made before it saw `stop` (at most the record in progress); the
        // loop ends when it has returned.
        for record in rx {
            if drive.interrupted || !drive.publish(&mut publisher, record?)? {
                break;
            }
        }
        let records = source.join().map_err(|_| DriveError::SourcePanicked)?;
        if !drive.interrupted {
            for record in records {
                if !drive.publish(&mut publisher, record.map_err(source_error)?)? {
                    break;
                }
            }
        }
        publisher.end_of_stream()?;
        let wall_seconds = drive.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let subscribers_left = publisher.linger(secs(options.linger))?;
        Ok(PublishReport {
            service: publisher.service().to_string(),
            backpressure: publisher.backpressure().name().to_string(),
            published: publisher.sent(),
            blocked_sends: publisher.blocked_sends(),
            interrupted: drive.interrupted,
            subscribers_left,
            wall_seconds,
        })
    })
}

/// Creates the scan publisher and waits for the subscribers it needs.
fn connect(beams: usize, options: &DriveOptions) -> Result<ScanPublisher, DriveError> {
    let topics = options.topics()?;
    let publisher = ScanPublisher::create(
        &topics,
        &PublisherOptions {
            backpressure: options.backpressure,
            beams,
            fixed_size: true,
            block_timeout: secs(options.block_timeout),
        },
    )
    .map_err(|e| match e {
        ConnectError::Owned { .. } => DriveError::Owned(e),
        e => e.into(),
    })?;
    let want = options.subscribers_wanted();
    if want > 0 {
        qicp_core::note!("waiting for {want} subscriber(s) on {}", topics.scan());
        if !publisher.wait_for_subscribers(want, secs(options.connect_timeout))? {
            if publisher.interrupted() {
                return Err(DriveError::Interrupted);
            }
            return Err(DriveError::NoSubscriber {
                service: topics.scan(),
                timeout: options.connect_timeout,
            });
        }
    }
    Ok(publisher)
}

/// Pacing of a published drive.
#[derive(Debug)]
struct Drive {
    rate: Rate,
    started: Option<Instant>,
    first_timestamp: f64,
    interrupted: bool,
}

impl Drive {
    fn new(rate: Rate) -> Self {
        Self {
            rate,
            started: None,
            first_timestamp: 0.0,
            interrupted: false,
        }
    }

    /// How long to wait before the scan of timestamp `t` is due at `speed`; refused (naming the
    /// scan) if that is not a finite wait of at most [`MAX_SECONDS`], e.g. a log whose time
    /// jumps by 1e20 s.
    fn wait_for(
        &self,
        t: f64,
        speed: f64,
        elapsed: Duration,
        index: u64,
    ) -> Result<Duration, DriveError> {
        let due = (t - self.first_timestamp) / speed;
        let wait = due - elapsed.as_secs_f64();
        if !due.is_finite() || wait > MAX_SECONDS {
            return Err(DriveError::TimeJump {
                index,
                t,
                due,
                first: self.first_timestamp,
                rate: self.rate,
            });
        }
        Ok(secs(wait))
    }

    /// Publishes `record` when it is due; false once SIGINT/SIGTERM arrived (not published).
    fn publish(
        &mut self,
        publisher: &mut ScanPublisher,
        record: Record,
    ) -> Result<bool, DriveError> {
        let started = *self.started.get_or_insert_with(|| {
            self.first_timestamp = record.timestamp();
            Instant::now()
        });
        if let Some(speed) = self.rate.speed() {
            let wait = self.wait_for(
                record.timestamp(),
                speed,
                started.elapsed(),
                publisher.sent(),
            )?;
            if !wait.is_zero() {
                std::thread::sleep(wait);
            }
        }
        if publisher.interrupted() {
            self.interrupted = true;
            return Ok(false);
        }
        publisher.publish(&record)?;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_parse_and_refuse() {
        assert_eq!("realtime".parse::<Rate>(), Ok(Rate::Realtime));
        assert_eq!("max".parse::<Rate>(), Ok(Rate::Max));
        assert_eq!("10x".parse::<Rate>(), Ok(Rate::Factor(10.0)));
        assert_eq!("0.001x".parse::<Rate>(), Ok(Rate::Factor(1e-3)));
        assert_eq!("1000000x".parse::<Rate>(), Ok(Rate::Factor(1e6)));
        for bad in [
            "0x", "-1x", "infx", "inf", "NaNx", "nanx", "1e-300x", "1e7x", "10", "x", "fast", "",
        ] {
            let e = bad.parse::<Rate>().expect_err(bad);
            assert!(e.starts_with(&format!("bad rate {bad:?}")), "{e}");
            assert!(e.contains("from 0.001x to 1000000x"), "{e}");
        }
    }

    #[test]
    fn rates_print_as_they_parse() {
        for s in ["realtime", "max", "10x", "0.5x"] {
            assert_eq!(s.parse::<Rate>().map(|r| r.to_string()), Ok(s.to_string()));
        }
        assert_eq!(Rate::Max.speed(), None);
        assert_eq!(Rate::Realtime.speed(), Some(1.0));
        assert_eq!(Rate::Factor(4.0).speed(), Some(4.0));
    }

    #[test]
    fn secs_clamps() {
        assert_eq!(secs(1.5), Duration::from_millis(1500));
        assert_eq!(secs(0.0), Duration::ZERO);
        assert_eq!(secs(-3.0), Duration::ZERO);
        assert_eq!(secs(f64::NAN), Duration::ZERO);
        assert_eq!(secs(f64::NEG_INFINITY), Duration::ZERO);
        assert_eq!(secs(f64::INFINITY), Duration::from_secs(86_400));
        assert_eq!(secs(1e300), Duration::from_secs(86_400));
        assert_eq!(secs(MAX_SECONDS), Duration::from_secs(86_400));
    }

    fn drive_from(rate: Rate, first: f64) -> Drive {
        Drive {
            first_timestamp: first,
            started: Some(Instant::now()),
            ..Drive::new(rate)
        }
    }

    #[test]
    fn waits_follow_the_timestamps() {
        let drive = drive_from(Rate::Realtime, 100.0);
        let wait = drive.wait_for(102.5, 1.0, Duration::from_millis(500), 3);
        assert_eq!(wait.ok(), Some(Duration::from_secs(2)));
        let drive = drive_from(Rate::Factor(10.0), 100.0);
        let wait = drive.wait_for(110.0, 10.0, Duration::from_millis(250), 3);
        assert_eq!(wait.ok(), Some(Duration::from_millis(750)));
        // Late: no wait.
        let wait = drive.wait_for(101.0, 10.0, Duration::from_secs(1), 3);
        assert_eq!(wait.ok(), Some(Duration::ZERO));
        // A wait of exactly a day is allowed.
        let drive = drive_from(Rate::Realtime, 0.0);
        let wait = drive.wait_for(MAX_SECONDS, 1.0, Duration::ZERO, 1);
        assert_eq!(wait.ok(), Some(Duration::from_secs(86_400)));
    }

    #[test]
    fn a_time_jump_is_refused_naming_the_scan() {
        let drive = drive_from(Rate::Factor(2.0), 5.0);
        let e = drive
            .wait_for(1e20, 2.0, Duration::ZERO, 7)
            .expect_err("a 1e20 s jump");
        let text = e.to_string();
        assert!(matches!(e, DriveError::TimeJump { index: 7, .. }), "{e:?}");
        assert!(
            text.starts_with("scan 7 (t = 100000000000000000000 s) is due"),
            "{text}"
        );
        assert!(
            text.contains("after the first (t = 5 s) at --rate 2x"),
            "{text}"
        );
        assert!(text.contains("a wait beyond 86400 s"), "{text}");
        assert!(text.ends_with("(publish it with --rate max)"), "{text}");
        // Not finite: refused too, even though the wait is not beyond a day.
        let drive = drive_from(Rate::Realtime, f64::MIN);
        let e = drive.wait_for(f64::MAX, 1.0, Duration::ZERO, 2);
        assert!(matches!(e, Err(DriveError::TimeJump { index: 2, .. })));
        let drive = drive_from(Rate::Realtime, 0.0);
        let e = drive.wait_for(MAX_SECONDS + 1.0, 1.0, Duration::ZERO, 1);
        assert!(e.is_err());
    }

    #[test]
    fn defaults_match_the_command_line() {
        let o = DriveOptions::default();
        assert_eq!(o.prefix, "qicp");
        assert_eq!(o.rate, Rate::Max);
        assert_eq!(o.backpressure, BackPressure::Block);
        assert_eq!(o.subscribers_wanted(), 1);
        let drop = DriveOptions {
            backpressure: BackPressure::DropOldest,
            ..DriveOptions::default()
        };
        assert_eq!(drop.subscribers_wanted(), 0);
        let two = DriveOptions {
            wait_subscribers: Some(2),
            ..drop
        };
        assert_eq!(two.subscribers_wanted(), 2);
        assert_eq!(
            (o.connect_timeout, o.linger, o.block_timeout),
            (60.0, 10.0, 30.0)
        );
    }

    #[test]
    fn reports_keep_their_field_names() {
        let report = PublishReport {
            service: "qicp/scan".to_string(),
            backpressure: "block".to_string(),
            published: 3,
            blocked_sends: 1,
            interrupted: false,
            subscribers_left: true,
            wall_seconds: 0.5,
        };
        let json = serde_json::to_value(&report).expect("serialises");
        let mut keys: Vec<_> = json
            .as_object()
            .expect("an object")
            .keys()
            .cloned()
            .collect();
        keys.sort();
        assert_eq!(
            keys,
            [
                "backpressure",
                "blocked_sends",
                "interrupted",
                "published",
                "service",
                "subscribers_left",
                "wall_seconds"
            ]
        );
        let back: PublishReport = serde_json::from_value(json).expect("deserialises");
        assert_eq!(back, report);
    }
}
