//! The bridge commands: scans and poses between processes over iceoryx2 (crate `qicp-bridge`).
//!
//! - `qicp sim CONFIG --publish [--rate realtime|max|Nx]`: publish a simulated drive;
//! - `qicp replay LOG --publish [--rate …]`: publish a CARMEN log;
//! - `qicp match --subscribe [--matcher KIND] [--out DIR]`: match the scans of whoever
//!   publishes, publish the poses, write the outputs of `qicp match`;
//! - `qicp bench bridge [--json]`: one-way latency and throughput, iceoryx2 against a
//!   Unix-domain socket carrying the same bytes;
//! - `qicp bench bridge --sizes 2k,64k,1m,4m [--json]`: where zero copy pays, payload size by
//!   payload size: latency, messages/s and CPU time per message ([`payload_bench`]);
//! - `qicp bench bridge-park [CONFIG] [--runs N] [--json]`: wall and CPU time of a whole drive
//!   simulated and matched in one process, against `qicp sim --publish` feeding
//!   `qicp match --subscribe`.
//!
//! Services: `<prefix>/scan` and `<prefix>/pose` (`--service-prefix`, default `qicp`).

use crate::logs::LogError;
use crate::logs::carmen::{CarmenOptions, CarmenReader};
use crate::matching::{MatchLoop, Matching, RunWriter, quantile, write_run};
use anyhow::{Context, Result, bail};
use qicp_bridge::{
    BackPressure, ConnectError, PoseMessage, PosePublisher, PublisherOptions, ScanHeader,
    ScanPublisher, ScanSubscriber, StreamEnd, StreamEvent, StreamReport, SubscriberOptions, Topics,
    WaitOptions,
};
use qicp_core::Record;
use qicp_matchers::MatcherConfig;
use serde::Serialize;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod latency_bench;
mod park_bench;
pub mod payload_bench;
mod subscribe;

pub use latency_bench::*;
pub use park_bench::*;
pub use subscribe::*;

/// The longest wait any timing option accepts (s): one day. A bound catches `inf`, `1e300` and
/// a typo, and keeps every wait a valid `Duration`.
pub const MAX_SECONDS: f64 = 86_400.0;

/// Slowest and fastest `--rate` factor (`0.001x` .. `1000000x`).
pub const RATE_FACTOR_RANGE: (f64, f64) = (1e-3, 1e6);

/// Parses a timing option (seconds): finite, above 0 and at most [`MAX_SECONDS`]. clap names
/// the option in its error.
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if v.is_finite() && v > 0.0 && v <= MAX_SECONDS {
        Ok(v)
    } else {
        Err(format!(
            "{s} s is out of range: a wait must be finite, above 0 and at most {MAX_SECONDS} s \
             (a day)"
        ))
    }
}

/// How fast a recorded or simulated drive is published.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// At the pace of the record timestamps.
    Realtime,
    /// As fast as the subscribers take them (back-pressure permitting).
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

impl Rate {
    fn speed(self) -> Option<f64> {
        match self {
            Rate::Realtime => Some(1.0),
            Rate::Max => None,
            Rate::Factor(f) => Some(f),
        }
    }
}

/// Publisher flags shared by `qicp sim --publish` and `qicp replay --publish`.
#[derive(Debug, Clone, clap::Args)]
pub struct PublishArgs {
    /// Publish the scans on `<prefix>/scan` instead of writing files.
    #[arg(long)]
    pub publish: bool,
    /// Pace: realtime, max, or a speed-up factor such as 10x.
    #[arg(long, default_value = "max", requires = "publish")]
    pub rate: Rate,
    /// block (lossless, waits for slow subscribers) or drop-oldest (live: subscribers count
    /// what they miss).
    #[arg(long, default_value = "block", requires = "publish")]
    pub backpressure: BackPressure,
    /// Service prefix: services `<prefix>/scan` and `<prefix>/pose`.
    #[arg(long, default_value = qicp_bridge::DEFAULT_PREFIX)]
    pub service_prefix: String,
    /// Subscribers to wait for before the first scan (default: 1 in block mode, 0 in
    /// drop-oldest mode).
    #[arg(long)]
    pub wait_subscribers: Option<usize>,
    /// Seconds to wait for them (above 0, at most a day, like every timing option).
    #[arg(long, default_value_t = 60.0, value_parser = parse_seconds)]
    pub connect_timeout: f64,
    /// Seconds to wait after the end-of-stream marker for the subscribers to leave.
    #[arg(long, default_value_t = 10.0, value_parser = parse_seconds)]
    pub linger: f64,
    /// Seconds one send may wait for a full subscriber in block mode before failing.
    #[arg(long, default_value_t = 30.0, value_parser = parse_seconds)]
    pub block_timeout: f64,
    /// iceoryx2 configuration file (TOML) of this process's node. Default: iceoryx2's built-in
    /// settings; qicp never reads `config/iceoryx2.toml` from the working directory (nor the
    /// user's or the system's iceoryx2.toml). All processes of one bridge need the same.
    #[arg(long, value_name = "FILE")]
    pub iceoryx2_config: Option<PathBuf>,
}

/// The topics of `prefix` in the iceoryx2 configuration of `file` (built-in defaults if none).
fn topics(prefix: &str, file: Option<&Path>) -> Result<Topics> {
    let topics = Topics::new(prefix);
    Ok(match file {
        Some(file) => topics.with_config_file(file)?,
        None => topics,
    })
}

/// What a publisher reports at its end (printed as JSON on stdout).
#[derive(Debug, Clone, Serialize)]
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

/// A wait of `s` seconds; the options are bounded by [`parse_seconds`], and anything else
/// (negative, NaN, beyond [`MAX_SECONDS`]) is clamped rather than trusted.
fn secs(s: f64) -> Duration {
    let s = if s.is_nan() { 0.0 } else { s };
    Duration::from_secs_f64(s.clamp(0.0, MAX_SECONDS))
}

/// Records a source may produce ahead of the publisher while it starts (about 1.5 MB of
/// 181-beam scans).
const PREFETCH: usize = 1024;

/// Publishes `records` (in time order) on `<prefix>/scan`, then the end-of-stream marker.
/// No record may have more than `beams` ranges: the shared-memory segment is sized for
/// that once ([`PublisherOptions::fixed_size`]).
///
/// Start-up overlaps with the source: while this thread sets up its iceoryx2 ports and waits
/// for subscribers, a second thread already pulls records (a simulator computes its first
/// scans), up to [`PREFETCH`] ahead. Once the subscribers are ready, this thread publishes
/// that backlog while the source goes on; when it has caught up, the source thread stops and
/// hands the source back, and this thread pulls the rest itself, so the drive does not pay a
/// thread hand-off per record. (Paced by `--rate`, it never catches up: the source thread
/// then runs to the end.) Order, pacing (counted from the first scan sent) and back-pressure
/// are unchanged.
pub fn publish_records(
    records: impl Iterator<Item = Result<Record>> + Send,
    beams: usize,
    args: &PublishArgs,
) -> Result<PublishReport> {
    use std::sync::atomic::{AtomicBool, Ordering};
    // A bad --iceoryx2-config is refused before the source starts.
    topics(&args.service_prefix, args.iceoryx2_config.as_deref())?;
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
                    if tx.send(record).is_err() {
                        break;
                    }
                }
                records
            })
            .context("starting the source thread")?;
        // On an error `rx` is dropped on return: the source stops before the scope joins it.
        let mut publisher = connect(beams, args)?;
        let mut drive = Drive::new(args.rate);
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
        let records = source
            .join()
            .map_err(|_| anyhow::anyhow!("the record source panicked"))?;
        if !drive.interrupted {
            for record in records {
                if !drive.publish(&mut publisher, record?)? {
                    break;
                }
            }
        }
        publisher.end_of_stream()?;
        let wall_seconds = drive.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let subscribers_left = publisher.linger(secs(args.linger))?;
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
fn connect(beams: usize, args: &PublishArgs) -> Result<ScanPublisher> {
    let topics = topics(&args.service_prefix, args.iceoryx2_config.as_deref())?;
    let publisher = ScanPublisher::create(
        &topics,
        &PublisherOptions {
            backpressure: args.backpressure,
            beams,
            fixed_size: true,
            block_timeout: secs(args.block_timeout),
        },
    )
    .map_err(|e| match e {
        ConnectError::Owned { .. } => anyhow::anyhow!(
            "{e}; its subscribers would see two streams mixed, so this one does not start"
        ),
        e => e.into(),
    })?;
    let want = args.wait_subscribers.unwrap_or(match args.backpressure {
        BackPressure::Block => 1,
        BackPressure::DropOldest => 0,
    });
    if want > 0 {
        eprintln!("waiting for {want} subscriber(s) on {}", topics.scan());
        if !publisher.wait_for_subscribers(want, secs(args.connect_timeout))? {
            if publisher.interrupted() {
                bail!("interrupted while waiting for subscribers");
            }
            bail!(
                "no subscriber on {} within {} s (--connect-timeout)",
                topics.scan(),
                args.connect_timeout
            );
        }
    }
    Ok(publisher)
}

/// Pacing of a published drive.
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

    /// How long to wait before `record` is due at `speed`; refused (naming the scan) if that is
    /// not a finite wait of at most [`MAX_SECONDS`], e.g. a log whose time jumps by 1e20 s.
    fn wait_for(
        &self,
        record: &Record,
        speed: f64,
        elapsed: Duration,
        index: u64,
    ) -> Result<Duration> {
        let t = record.timestamp();
        let due = (t - self.first_timestamp) / speed;
        let wait = due - elapsed.as_secs_f64();
        if !due.is_finite() || wait > MAX_SECONDS {
            bail!(
                "scan {index} (t = {t} s) is due {due} s after the first (t = {} s) at --rate {}: \
                 a wait beyond {MAX_SECONDS} s; the log's time jumps (publish it with --rate max)",
                self.first_timestamp,
                match self.rate {
                    Rate::Realtime => "realtime".to_string(),
                    Rate::Max => "max".to_string(),
                    Rate::Factor(f) => format!("{f}x"),
                }
            );
        }
        Ok(secs(wait))
    }

    /// Publishes `record` when it is due; false once SIGINT/SIGTERM arrived (not published).
    fn publish(&mut self, publisher: &mut ScanPublisher, record: Record) -> Result<bool> {
        let started = *self.started.get_or_insert_with(|| {
            self.first_timestamp = record.timestamp();
            Instant::now()
        });
        if let Some(speed) = self.rate.speed() {
            let wait = self.wait_for(&record, speed, started.elapsed(), publisher.sent())?;
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

/// Prints a publisher's report on stdout.
pub fn print_publish_report(report: &PublishReport) -> Result<()> {
    println!("{}", serde_json::to_string_pretty(report)?);
    Ok(())
}

/// Arguments of `qicp replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// CARMEN log (plain or .bz2).
    pub log: PathBuf,
    /// Skip and count malformed log lines instead of failing.
    #[arg(long)]
    pub lenient: bool,
    /// Publisher flags (`--publish` is required: replay has no other output).
    #[command(flatten)]
    pub bridge: PublishArgs,
}

/// Runs `qicp replay`.
pub fn run_replay(args: ReplayArgs) -> Result<()> {
    if !args.bridge.publish {
        bail!("qicp replay publishes a log: give --publish");
    }
    // A bad --iceoryx2-config is refused before the log is read.
    topics(
        &args.bridge.service_prefix,
        args.bridge.iceoryx2_config.as_deref(),
    )?;
    // Scan by scan: the log is read as it is published, never held whole.
    let options = CarmenOptions {
        lenient: args.lenient,
        ..CarmenOptions::default()
    };
    let mut reader = CarmenReader::open(&args.log, &options)?;
    let Some(first) = reader.next().transpose()? else {
        return Err(LogError::empty(&args.log, &reader.info).into());
    };
    // The scan service's slices start at the first scan's size and grow if a later one is
    // longer.
    let beams = first.scan.beams();
    let records = std::iter::once(Ok(first)).chain(reader.by_ref().map(|r| r.map_err(Into::into)));
    let report = publish_records(records, beams, &args.bridge)?;
    reader.info.warn(&args.log);
    print_publish_report(&report)
}
