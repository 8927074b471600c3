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

pub mod payload_bench;

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

/// Subscriber flags of `qicp match --subscribe`.
#[derive(Debug, Clone, clap::Args)]
pub struct SubscribeArgs {
    /// Match the scans published on `<prefix>/scan` (by `qicp sim --publish`, `qicp replay`
    /// or a robot process) and publish the poses on `<prefix>/pose`.
    #[arg(long, conflicts_with = "log")]
    pub subscribe: bool,
    /// Service prefix.
    #[arg(long = "service-prefix", default_value = qicp_bridge::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Scans sent before this subscriber started that it asks for (at most
    /// qicp_bridge::SCAN_HISTORY_MAX = 64).
    #[arg(long, default_value_t = 0)]
    pub history: usize,
    /// Subscriber buffer (scans); in block mode the publisher runs at most this far ahead.
    #[arg(long, default_value_t = 64)]
    pub buffer: usize,
    /// Require this back-pressure mode (default: adopt the publisher's; block if first).
    #[arg(long)]
    pub backpressure: Option<BackPressure>,
    /// Seconds to wait for a publisher to appear (above 0, at most a day, like every timing
    /// option).
    #[arg(long, default_value_t = 60.0, value_parser = parse_seconds)]
    pub connect_timeout: f64,
    /// Seconds to wait for a new publisher after one was lost.
    #[arg(long, default_value_t = 10.0, value_parser = parse_seconds)]
    pub reconnect_timeout: f64,
    /// Seconds without a scan, a publisher being connected, before giving up.
    #[arg(long, default_value_t = 120.0, value_parser = parse_seconds)]
    pub idle_timeout: f64,
    /// iceoryx2 configuration file (TOML) of this process's node. Default: iceoryx2's built-in
    /// settings; qicp never reads `config/iceoryx2.toml` from the working directory (nor the
    /// user's or the system's iceoryx2.toml). All processes of one bridge need the same.
    #[arg(long, value_name = "FILE")]
    pub iceoryx2_config: Option<PathBuf>,
    /// Sleep this long after each scan (tests: a slow subscriber).
    #[arg(long, default_value_t = 0, hide = true)]
    pub delay_ms: u64,
}

/// The bridge figures added to `summary.json` under `"bridge"`.
#[derive(Debug, Clone, Serialize)]
pub struct SubscribeSummary {
    /// The scan service.
    pub service: String,
    /// The service's back-pressure mode.
    pub backpressure: String,
    /// How the stream ended (`end_of_stream`, `publisher_lost`, `no_publisher`, `idle`,
    /// `interrupted`).
    pub end: String,
    /// Scans received.
    pub received: u64,
    /// Scans sent before this subscriber joined that it did not get.
    pub missed_before_join: u64,
    /// Jumps in the sequence numbers.
    pub gap_events: u64,
    /// Scans lost in them.
    pub missing: u64,
    /// Scans received out of order (ignored).
    pub out_of_order: u64,
    /// Publishers seen (a restart counts again).
    pub publishers_seen: u64,
    /// Publishers that vanished without an end-of-stream marker.
    pub publishers_lost: u64,
    /// Messages of a second publisher, sent while the first was connected: ignored, never
    /// mixed in (any makes the run fail).
    pub intruders: u64,
    /// Scans the last publisher announced in its end marker.
    pub announced: Option<u64>,
    /// Scans whose message could not be turned into a scan (bad geometry, NaN time).
    pub rejected: u64,
    /// Poses published on `<prefix>/pose`.
    pub poses_published: u64,
}

impl SubscribeSummary {
    fn of(
        report: &StreamReport,
        service: String,
        backpressure: BackPressure,
        rejected: u64,
        poses: u64,
    ) -> Self {
        Self {
            service,
            backpressure: backpressure.name().to_string(),
            end: report.end.map_or("running", StreamEnd::name).to_string(),
            received: report.received,
            missed_before_join: report.missed_before_join,
            gap_events: report.gap_events,
            missing: report.missing,
            out_of_order: report.out_of_order,
            publishers_seen: report.publishers_seen,
            publishers_lost: report.publishers_lost,
            intruders: report.intruders,
            announced: report.announced,
            rejected,
            poses_published: poses,
        }
    }
}

/// Runs `qicp match --subscribe`: matches every scan received, publishes its pose, and at the
/// end writes what `qicp match` writes (when `out` is given) plus the stream's figures.
///
/// Returns an error (after writing the outputs) when the stream did not end with its marker
/// (publisher lost, none appeared, or it went idle) or another publisher intruded. Refuses to
/// start when another process already publishes poses on `<prefix>/pose` (a second matcher):
/// the pose service, like every service, has one owner.
pub fn run_subscribe(
    config: &MatcherConfig,
    out: Option<&Path>,
    json: bool,
    args: &SubscribeArgs,
) -> Result<()> {
    let topics = topics(&args.prefix, args.iceoryx2_config.as_deref())?;
    // The outputs are opened before the first scan: a bad --out fails at once, and rows and
    // poses go to disk as they come (renamed into place at the end), not into memory.
    let mut writer = out.map(RunWriter::create).transpose()?;
    // The pose publisher first: a second matcher on the same prefix is refused before it
    // subscribes to the scans (where it would hold a block-mode publisher back).
    let mut poses = PosePublisher::create(&topics).map_err(|e| match e {
        ConnectError::Owned { .. } => anyhow::anyhow!(
            "{e}; is another `qicp match --subscribe` running with --service-prefix {}?",
            args.prefix
        ),
        e => e.into(),
    })?;
    let scans = ScanSubscriber::create(
        &topics,
        &SubscriberOptions {
            history: args.history,
            buffer: args.buffer,
            backpressure: args.backpressure,
            wait: WaitOptions {
                connect_timeout: secs(args.connect_timeout),
                reconnect_timeout: secs(args.reconnect_timeout),
                idle_timeout: secs(args.idle_timeout),
                ..WaitOptions::default()
            },
        },
    )?;
    let backpressure = scans.backpressure();
    let mut matching = MatchLoop::new(config)?;
    let mut rejected = 0u64;
    let mut publish_error = None;
    let mut write_error = None;
    eprintln!(
        "matching scans from {} ({} mode) with {}",
        topics.scan(),
        backpressure.name(),
        config.kind()
    );
    let report = scans.run(|event| {
        match event {
            StreamEvent::Data(view) => match view.header.to_record(view.ranges) {
                Ok(record) => {
                    let (estimate, row) = matching.push(&record);
                    if let Some(w) = &mut writer
                        && let Err(e) = w.push(record.timestamp(), &estimate.pose, &row)
                    {
                        write_error = Some(e);
                        return ControlFlow::Break(());
                    }
                    let message = PoseMessage {
                        scan_publisher: view.header.publisher,
                        ..PoseMessage::of(
                            0,
                            view.header.seq,
                            record.timestamp(),
                            estimate.pose,
                            &estimate.result,
                            estimate.inserted,
                        )
                    };
                    if let Err(e) = poses.publish(message) {
                        publish_error = Some(e);
                        return ControlFlow::Break(());
                    }
                }
                Err(e) => {
                    rejected += 1;
                    eprintln!("warning: scan {} rejected: {e}", view.header.seq);
                }
            },
            StreamEvent::PublisherJoined { skipped } if skipped > 0 => {
                eprintln!("publisher joined; {skipped} scans were sent before this subscriber")
            }
            StreamEvent::PublisherJoined { .. } => eprintln!("publisher joined"),
            StreamEvent::PublisherLost => eprintln!(
                "publisher lost without end-of-stream; waiting {} s for a new one",
                args.reconnect_timeout
            ),
            StreamEvent::Gap { missing } => eprintln!("gap: {missing} scans lost"),
            StreamEvent::Intruder => eprintln!(
                "error: a second publisher sends on {} while the first is connected; its scans \
                 are ignored and the run will fail",
                topics.scan()
            ),
        }
        if args.delay_ms > 0 {
            std::thread::sleep(Duration::from_millis(args.delay_ms));
        }
        ControlFlow::Continue(())
    })?;
    // Leave the scan stream first: a lingering publisher may exit now.
    drop(scans);
    if let Some(e) = publish_error {
        return Err(e).context("publishing a pose");
    }
    if let Some(e) = write_error {
        return Err(e);
    }
    poses.end_of_stream().context("ending the pose stream")?;

    let bridge = SubscribeSummary::of(&report, topics.scan(), backpressure, rejected, poses.sent());
    let mut summary = serde_json::to_value(matching.summary())?;
    summary["bridge"] = serde_json::to_value(&bridge)?;
    let text = serde_json::to_string_pretty(&summary)?;
    if let Some(writer) = writer {
        writer.commit(config, Some(&text))?;
    }
    if json {
        println!("{text}");
    } else {
        eprintln!("{text}");
    }
    // Give pose subscribers a moment to read the tail before this process's memory goes.
    poses.linger(Duration::from_secs(5))?;
    if report.intruders > 0 {
        bail!(
            "{} messages of a second publisher on {} were ignored (a service has one owner); \
             outputs cover the {} scans of the first",
            report.intruders,
            topics.scan(),
            report.received
        );
    }
    match report.end {
        Some(StreamEnd::EndOfStream | StreamEnd::Interrupted | StreamEnd::Stopped) => Ok(()),
        Some(end) => bail!(
            "scan stream ended without its end marker ({}); outputs cover the {} scans received",
            end.name(),
            report.received
        ),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------
// qicp bench bridge

/// Arguments of `qicp bench bridge`.
#[derive(Debug, Clone, clap::Args)]
pub struct BridgeBenchArgs {
    /// Messages per latency run (each waits for the previous one to arrive); with --sizes, at
    /// most this many, and at most 2 GiB of payload.
    #[arg(long, default_value_t = 2000)]
    pub messages: usize,
    /// Messages per throughput run (sent back to back); with --sizes, at most this many, and
    /// at most 1 GiB of payload.
    #[arg(long, default_value_t = 20000)]
    pub burst: usize,
    /// Beams per scan (scans through the scan service; not with --sizes).
    #[arg(long, default_value_t = 181)]
    pub beams: usize,
    /// Payload sizes to measure instead of scans, e.g. `2k,64k,1m,4m` (bytes; k = 1024,
    /// m = 1024²): latency, messages/s and CPU time per message of iceoryx2 (written and read
    /// in place) and of the socket, size by size. JSON:
    /// `{"sizes": [{"bytes", "iceoryx2": {"p50_us", "p99_us", "msgs_per_s", "cpu_us_per_msg"},
    /// "uds": {…}, …}], …}`.
    #[arg(
        long,
        value_delimiter = ',',
        value_parser = payload_bench::parse_size,
        conflicts_with = "beams"
    )]
    pub sizes: Vec<usize>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// How both readers wait: `event` (block in the kernel until woken: the WaitSet for
    /// iceoryx2, `read` for the socket; what qicp's subscribers do) or `spin` (poll without
    /// sleeping: the transport's own cost, without the wake-up).
    #[arg(long, value_enum, default_value_t = WaitStrategy::Event)]
    pub wait: WaitStrategy,
}

/// How the bench's readers wait for a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum WaitStrategy {
    /// Block until woken by the kernel.
    Event,
    /// Busy-poll.
    Spin,
}

/// One transport's figures.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TransportFigures {
    /// Median one-way latency (µs).
    pub p50_us: f64,
    /// 99th percentile one-way latency (µs).
    pub p99_us: f64,
    /// Messages per second, sent back to back.
    pub msgs_per_s: f64,
}

/// Result of `qicp bench bridge`.
#[derive(Debug, Clone, Serialize)]
pub struct BridgeBenchReport {
    /// Through iceoryx2 (`ScanPublisher` → `ScanSubscriber`, WaitSet wake-up).
    pub iceoryx2: TransportFigures,
    /// Through a Unix-domain stream socket (blocking read wake-up), same bytes.
    pub uds: TransportFigures,
    /// Beams per scan.
    pub beams: usize,
    /// Bytes per message (header + ranges).
    pub bytes: usize,
    /// Messages per latency run.
    pub messages: usize,
    /// Messages per throughput run.
    pub burst: usize,
    /// `iceoryx2.p50_us / uds.p50_us`.
    pub p50_ratio: f64,
    /// How both readers waited.
    pub wait: WaitStrategy,
}

/// Runs `qicp bench bridge`.
pub fn run_bench(args: &BridgeBenchArgs) -> Result<()> {
    if !args.sizes.is_empty() {
        let report =
            payload_bench::payload_bench(&args.sizes, args.messages, args.burst, args.wait)?;
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        } else {
            payload_bench::print_table(&report);
        }
        return Ok(());
    }
    let report = bridge_bench(args)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{:<10} {:>10} {:>10} {:>14}",
            "transport", "p50 µs", "p99 µs", "msgs/s"
        );
        for (name, f) in [("iceoryx2", report.iceoryx2), ("uds", report.uds)] {
            println!(
                "{name:<10} {:>10.2} {:>10.2} {:>14.0}",
                f.p50_us, f.p99_us, f.msgs_per_s
            );
        }
        println!(
            "{} beams, {} bytes per message, readers {:?}; p50 ratio iceoryx2/uds = {:.2}",
            report.beams, report.bytes, report.wait, report.p50_ratio
        );
    }
    Ok(())
}

/// Both transports, one after the other, in one run.
pub fn bridge_bench(args: &BridgeBenchArgs) -> Result<BridgeBenchReport> {
    anyhow::ensure!(
        args.beams > 0 && args.messages > 0 && args.burst > 0,
        "empty bench"
    );
    let ranges: Vec<f64> = (0..args.beams).map(|i| 1.0 + i as f64 * 0.01).collect();
    let spin = args.wait == WaitStrategy::Spin;
    let iceoryx2 = TransportFigures::of(
        &iceoryx2_run(&ranges, args.messages, true, spin)?,
        iceoryx2_run(&ranges, args.burst, false, spin)?,
    );
    let uds = TransportFigures::of(
        &uds_run(&ranges, args.messages, true, spin)?,
        uds_run(&ranges, args.burst, false, spin)?,
    );
    Ok(BridgeBenchReport {
        iceoryx2,
        uds,
        beams: args.beams,
        bytes: std::mem::size_of::<ScanHeader>() + 8 * args.beams,
        messages: args.messages,
        burst: args.burst,
        p50_ratio: iceoryx2.p50_us / uds.p50_us,
        wait: args.wait,
    })
}

/// One run's measurements: one-way latencies (µs) or the elapsed time of a burst.
struct RunTimes {
    latencies_us: Vec<f64>,
    elapsed: Duration,
    messages: usize,
}

impl TransportFigures {
    fn of(latency: &RunTimes, burst: RunTimes) -> Self {
        Self {
            p50_us: quantile(&latency.latencies_us, 0.5),
            p99_us: quantile(&latency.latencies_us, 0.99),
            msgs_per_s: burst.messages as f64 / burst.elapsed.as_secs_f64().max(1e-12),
        }
    }
}

/// The clock both threads stamp with: seconds since a shared `Instant`.
fn stamp(epoch: Instant) -> f64 {
    epoch.elapsed().as_secs_f64()
}

/// iceoryx2: publisher thread → this thread's `ScanSubscriber`. With `paced`, each message
/// is sent after the previous one arrived (latency: every message pays a wake-up); without,
/// back to back (throughput).
fn iceoryx2_run(ranges: &[f64], messages: usize, paced: bool, spin: bool) -> Result<RunTimes> {
    let topics = Topics::new(&format!(
        "qicp-bench-{}-{}",
        std::process::id(),
        if paced { "latency" } else { "burst" }
    ));
    let subscriber = ScanSubscriber::create(
        &topics,
        &SubscriberOptions {
            buffer: 64,
            backpressure: Some(BackPressure::Block),
            wait: WaitOptions {
                connect_timeout: Duration::from_secs(10),
                reconnect_timeout: Duration::from_secs(2),
                idle_timeout: Duration::from_secs(10),
                ..WaitOptions::default()
            },
            ..SubscriberOptions::default()
        },
    )?;
    let epoch = Instant::now();
    let (ack_tx, ack_rx) = std::sync::mpsc::sync_channel::<()>(1);
    let owned = ranges.to_vec();
    let publisher = std::thread::spawn(move || -> Result<f64> {
        let mut p = ScanPublisher::create(
            &topics,
            &PublisherOptions {
                beams: owned.len(),
                fixed_size: true,
                ..PublisherOptions::default()
            },
        )?;
        if !p.wait_for_subscribers(1, Duration::from_secs(10))? {
            bail!("bench subscriber did not connect");
        }
        let first_send = stamp(epoch);
        let header = ScanHeader {
            angle_increment: 0.01,
            max_range: 80.0,
            ..ScanHeader::default()
        };
        for _ in 0..messages {
            let h = ScanHeader {
                timestamp: stamp(epoch),
                ..header
            };
            p.publish_with(h, owned.len(), |i| owned[i])?;
            if paced {
                ack_rx
                    .recv_timeout(Duration::from_secs(10))
                    .context("bench subscriber stalled")?;
            }
        }
        p.end_of_stream()?;
        p.linger(Duration::from_secs(10))?;
        Ok(first_send)
    });
    let mut latencies_us = Vec::with_capacity(messages);
    let mut checksum = 0.0;
    let mut last_receive = 0.0;
    let mut on_scan = |view: qicp_bridge::ScanView<'_>| {
        last_receive = stamp(epoch);
        latencies_us.push((last_receive - view.header.timestamp) * 1e6);
        // Touch every range, as the socket reader must.
        checksum += view.ranges.iter().sum::<f64>();
        if paced {
            let _ = ack_tx.try_send(());
        }
    };
    let report = if spin {
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut received = 0;
        while received < messages {
            received += subscriber.poll(&mut on_scan)?;
            if publisher.is_finished() && received < messages {
                // It failed (or sent less): stop spinning; its error is reported below.
                received += subscriber.poll(&mut on_scan)?;
                break;
            }
            anyhow::ensure!(
                Instant::now() < deadline,
                "spinning bench stalled: {received} of {messages} messages after 60 s"
            );
            std::hint::spin_loop();
        }
        StreamReport {
            received: received as u64,
            end: Some(StreamEnd::EndOfStream),
            ..StreamReport::default()
        }
    } else {
        subscriber.run(|event| {
            if let StreamEvent::Data(view) = event {
                on_scan(view);
            }
            ControlFlow::Continue(())
        })?
    };
    drop(subscriber);
    let first_send = publisher
        .join()
        .map_err(|_| anyhow::anyhow!("bench publisher panicked"))??;
    anyhow::ensure!(
        report.is_complete() && report.received == messages as u64,
        "bench stream incomplete: {report:?}"
    );
    std::hint::black_box(checksum);
    Ok(RunTimes {
        latencies_us,
        elapsed: secs(last_receive - first_send),
        messages,
    })
}

/// The socket baseline: the same header and ranges, serialised into one frame per message,
/// written to a Unix-domain stream socket and read back by a thread blocked in `read`.
fn uds_run(ranges: &[f64], messages: usize, paced: bool, spin: bool) -> Result<RunTimes> {
    use std::io::{Read, Write};
    let header_bytes = std::mem::size_of::<ScanHeader>();
    let frame = header_bytes + 8 * ranges.len();
    let (mut writer, mut reader) = std::os::unix::net::UnixStream::pair()?;
    reader.set_read_timeout(Some(Duration::from_secs(10)))?;
    reader.set_nonblocking(spin)?;
    let epoch = Instant::now();
    let (ack_tx, ack_rx) = std::sync::mpsc::sync_channel::<()>(1);
    let owned = ranges.to_vec();
    let sender = std::thread::spawn(move || -> Result<f64> {
        let mut buf = vec![0u8; frame];
        let first_send = stamp(epoch);
        for seq in 0..messages as u64 {
            // Serialise as the header would lie in memory: seq at 8, timestamp at 16,
            // beams at 128, ranges after the 136-byte header.
            buf[8..16].copy_from_slice(&seq.to_le_bytes());
            buf[16..24].copy_from_slice(&stamp(epoch).to_le_bytes());
            buf[128..132].copy_from_slice(&(owned.len() as u32).to_le_bytes());
            for (chunk, r) in buf[header_bytes..].chunks_exact_mut(8).zip(&owned) {
                chunk.copy_from_slice(&r.to_le_bytes());
            }
            writer.write_all(&buf)?;
            if paced {
                ack_rx
                    .recv_timeout(Duration::from_secs(10))
                    .context("socket reader stalled")?;
            }
        }
        Ok(first_send)
    });
    let mut buf = vec![0u8; frame];
    let mut latencies_us = Vec::with_capacity(messages);
    let mut checksum = 0.0;
    let mut last_receive = 0.0;
    let deadline = Instant::now() + Duration::from_secs(60);
    for _ in 0..messages {
        if spin {
            // Non-blocking reads until the frame is complete.
            let mut filled = 0;
            while filled < frame {
                match reader.read(&mut buf[filled..]) {
                    Ok(0) => bail!("socket closed"),
                    Ok(n) => filled += n,
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        anyhow::ensure!(Instant::now() < deadline, "spinning socket stalled");
                        std::hint::spin_loop();
                    }
                    Err(e) => return Err(e.into()),
                }
            }
        } else {
            reader.read_exact(&mut buf)?;
        }
        last_receive = stamp(epoch);
        let sent = f64::from_le_bytes(buf[16..24].try_into()?);
        latencies_us.push((last_receive - sent) * 1e6);
        checksum += buf[header_bytes..]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap_or_default()))
            .sum::<f64>();
        if paced {
            let _ = ack_tx.try_send(());
        }
    }
    let first_send = sender
        .join()
        .map_err(|_| anyhow::anyhow!("socket writer panicked"))??;
    std::hint::black_box(checksum);
    Ok(RunTimes {
        latencies_us,
        elapsed: secs(last_receive - first_send),
        messages,
    })
}

// ---------------------------------------------------------------------------------------
// qicp bench bridge-park

/// Arguments of `qicp bench bridge-park`.
#[derive(Debug, Clone, clap::Args)]
pub struct ParkBenchArgs {
    /// The drive to simulate.
    #[arg(default_value = "configs/worlds/park.toml")]
    pub config: PathBuf,
    /// Matcher kind.
    #[arg(long, default_value = "q-wsm")]
    pub matcher: String,
    /// Runs of each arm, interleaved (in-process, two-process, in-process, …).
    #[arg(long, default_value_t = 7)]
    pub runs: usize,
    /// Scratch directory for the outputs: must not exist yet (it is created) or be an empty
    /// directory of this user, not a link; it is made private (0700) and kept. Default: a
    /// fresh private directory with a random name under the system's temp dir, removed at
    /// the end.
    #[arg(long)]
    pub scratch: Option<PathBuf>,
    /// Print one JSON object instead of a line.
    #[arg(long)]
    pub json: bool,
    /// Internal: be the in-process arm, writing its outputs to this directory.
    #[arg(long, hide = true)]
    pub in_process_once: Option<PathBuf>,
}

/// Wall times of one arm (s).
#[derive(Debug, Clone, Serialize)]
pub struct ArmTimes {
    /// Median over the runs.
    pub median_s: f64,
    /// Every run, in order.
    pub runs_s: Vec<f64>,
    /// CPU time (user + system) of the arm's processes, mean per run (s; from the kernel's
    /// accounting of reaped children, 10 ms ticks; `null` where /proc is missing).
    pub cpu_s: Option<f64>,
}

impl ArmTimes {
    fn of(runs_s: Vec<f64>, cpu_total_s: Option<f64>) -> Self {
        let n = runs_s.len().max(1) as f64;
        Self {
            median_s: quantile(&runs_s, 0.5),
            runs_s,
            cpu_s: cpu_total_s.map(|c| c / n),
        }
    }
}

/// CPU seconds (user + system) of this process's reaped children so far: `cutime + cstime`
/// of /proc/self/stat, in USER_HZ (100 per second on Linux).
fn children_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start at field 3 (state);
    // cutime and cstime are fields 16 and 17.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i - 3)?.parse::<f64>().ok();
    Some((ticks(16)? + ticks(17)?) / 100.0)
}

/// Result of `qicp bench bridge-park`.
#[derive(Debug, Clone, Serialize)]
pub struct ParkBenchReport {
    /// The drive.
    pub config: String,
    /// The matcher.
    pub matcher: String,
    /// Scans in the drive.
    pub scans: u64,
    /// `qicp bench bridge-park CONFIG --in-process-once DIR`: simulate and match in one
    /// process; spawn to exit.
    pub in_process: ArmTimes,
    /// `qicp match --subscribe …` and `qicp sim CONFIG --publish …` spawned together; spawn
    /// of the first to exit of the last.
    pub two_process: ArmTimes,
    /// `two_process.median_s / in_process.median_s`.
    pub ratio: f64,
    /// Whether every two-process trajectory equals the in-process one byte for byte.
    pub identical: bool,
    /// /proc/loadavg (1, 5, 15 min) at the start and at the end.
    pub load: [[f64; 3]; 2],
}

fn load_average() -> [f64; 3] {
    let text = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let mut it = text
        .split_whitespace()
        .map(|w| w.parse::<f64>().unwrap_or(f64::NAN));
    [
        it.next().unwrap_or(f64::NAN),
        it.next().unwrap_or(f64::NAN),
        it.next().unwrap_or(f64::NAN),
    ]
}

/// The in-process arm: simulate the drive and match each scan as it is produced, then write
/// what `qicp match --subscribe --out` writes (trajectory, per-scan figures, config, summary).
fn park_in_process(config: &Path, kind: &str, out: &Path) -> Result<()> {
    let cfg = qicp_sim::SimConfig::load(config)?;
    let mut matcher = crate::registry().config(kind)?;
    matcher.validate()?;
    matcher.fill_defaults();
    let mut matching = Matching::new(&matcher)?;
    for record in qicp_sim::Simulation::new(cfg)? {
        matching.push(&record?);
    }
    let run = matching.finish();
    write_run(out, &run, &matcher)?;
    let text = serde_json::to_string_pretty(&run.summary)?;
    std::fs::write(out.join("summary.json"), text).context("writing summary.json")?;
    Ok(())
}

/// Waits for every child (polling each millisecond, at most `timeout`); fails on a non-zero
/// exit or the timeout (killing what still runs). Returns the stdout of each.
fn wait_all(
    children: &mut [(&'static str, std::process::Child)],
    timeout: Duration,
) -> Result<Vec<String>> {
    use std::io::Read;
    let deadline = Instant::now() + timeout;
    let mut done = vec![false; children.len()];
    let kill_all = |children: &mut [(&'static str, std::process::Child)]| {
        for (_, c) in children.iter_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    };
    while done.iter().any(|d| !d) {
        let mut failed = None;
        for (i, (name, child)) in children.iter_mut().enumerate() {
            if done[i] {
                continue;
            }
            if let Some(status) = child.try_wait()? {
                done[i] = true;
                if !status.success() {
                    let mut err = String::new();
                    if let Some(mut s) = child.stderr.take() {
                        let _ = s.read_to_string(&mut err);
                    }
                    failed = Some(format!("{name} failed ({status}): {err}"));
                    break;
                }
            }
        }
        if let Some(failure) = failed {
            kill_all(children);
            bail!(failure);
        }
        if Instant::now() > deadline {
            kill_all(children);
            bail!("bench children did not finish within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let mut outs = Vec::new();
    for (_, child) in children.iter_mut() {
        let mut out = String::new();
        if let Some(mut s) = child.stdout.take() {
            s.read_to_string(&mut out)?;
        }
        outs.push(out);
    }
    Ok(outs)
}

/// Runs `qicp bench bridge-park`: the whole park drive matched in one process against the
/// same drive published by `qicp sim --publish` to `qicp match --subscribe`, both arms run
/// as fresh processes of this binary, interleaved, `--runs` times each.
pub fn run_park_bench(args: &ParkBenchArgs) -> Result<()> {
    if let Some(out) = &args.in_process_once {
        return park_in_process(&args.config, &args.matcher, out);
    }
    anyhow::ensure!(args.runs > 0, "--runs must be at least 1");
    let exe = std::env::current_exe().context("locating the qicp binary")?;
    let scratch = Scratch::prepare(args.scratch.as_deref())?;
    let scratch = scratch.path();
    let config = args.config.to_string_lossy().to_string();
    let kind = crate::registry().config(&args.matcher)?.kind();
    let kind = kind.as_str();
    let spawn =
        |name: &'static str, argv: &[&str]| -> Result<(&'static str, std::process::Child)> {
            let child = std::process::Command::new(&exe)
                .args(argv)
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .with_context(|| format!("spawning {name}"))?;
            Ok((name, child))
        };
    let timeout = Duration::from_secs(300);
    let load_start = load_average();
    let (mut inproc, mut twoproc) = (Vec::new(), Vec::new());
    let (mut inproc_cpu, mut twoproc_cpu) = (Some(0.0), Some(0.0));
    let add = |total: &mut Option<f64>, before: Option<f64>| {
        *total = match (*total, before, children_cpu_s()) {
            (Some(t), Some(b), Some(a)) => Some(t + a - b),
            _ => None,
        };
    };
    let mut identical = true;
    let mut scans = 0;
    for run in 0..args.runs {
        let one = scratch.join("in-process");
        Scratch::clear(&one)?;
        let one_s = one.to_string_lossy().to_string();
        let cpu0 = children_cpu_s();
        let t0 = Instant::now();
        let mut children = vec![spawn(
            "in-process run",
            &[
                "bench",
                "bridge-park",
                &config,
                "--matcher",
                kind,
                "--in-process-once",
                &one_s,
            ],
        )?];
        wait_all(&mut children, timeout)?;
        inproc.push(t0.elapsed().as_secs_f64());
        add(&mut inproc_cpu, cpu0);

        let two = scratch.join("two-process");
        Scratch::clear(&two)?;
        let two_s = two.to_string_lossy().to_string();
        let prefix = format!("qicp-bench-park-{}-{run}", std::process::id());
        let cpu0 = children_cpu_s();
        let t0 = Instant::now();
        let mut children = vec![
            spawn(
                "qicp match --subscribe",
                &[
                    "match",
                    "--subscribe",
                    "--matcher",
                    kind,
                    "--service-prefix",
                    &prefix,
                    "--out",
                    &two_s,
                ],
            )?,
            spawn(
                "qicp sim --publish",
                &["sim", &config, "--publish", "--service-prefix", &prefix],
            )?,
        ];
        let outs = wait_all(&mut children, timeout)?;
        twoproc.push(t0.elapsed().as_secs_f64());
        add(&mut twoproc_cpu, cpu0);
        let report: serde_json::Value =
            serde_json::from_str(&outs[1]).context("reading the publisher's report")?;
        scans = report["published"].as_u64().unwrap_or(0);
        let read = |d: &Path| std::fs::read(d.join("trajectory.tum")).unwrap_or_default();
        identical &= !read(&one).is_empty() && read(&one) == read(&two);
    }
    let in_process = ArmTimes::of(inproc, inproc_cpu);
    let two_process = ArmTimes::of(twoproc, twoproc_cpu);
    let report = ParkBenchReport {
        config,
        matcher: kind.to_string(),
        scans,
        ratio: two_process.median_s / in_process.median_s,
        in_process,
        two_process,
        identical,
        load: [load_start, load_average()],
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        let cpu = |a: &ArmTimes| a.cpu_s.map_or("?".to_string(), |c| format!("{c:.3}"));
        println!(
            "{} scans, {}: in-process {:.3} s, two processes {:.3} s (median of {}), ratio {:.3}; \
             CPU per run {} s against {} s; load {:.2}{}",
            report.scans,
            report.matcher,
            report.in_process.median_s,
            report.two_process.median_s,
            args.runs,
            report.ratio,
            cpu(&report.in_process),
            cpu(&report.two_process),
            report.load[0][0],
            if report.identical {
                ""
            } else {
                "; TRAJECTORIES DIFFER"
            }
        );
    }
    anyhow::ensure!(report.identical, "the two-process trajectory differs");
    Ok(())
}

/// The scratch directory of `qicp bench bridge-park`, private to this user so that nobody
/// can plant a link in it for the runs to write through.
#[derive(Debug)]
enum Scratch {
    /// Fresh, random name, 0700, removed when dropped.
    Temporary(tempfile::TempDir),
    /// The user's `--scratch`, kept.
    Given(PathBuf),
}

impl Scratch {
    /// A fresh private directory, or the user's `given` one if it does not exist yet (it is
    /// created, 0700) or is an empty directory of this user that is not a link (it is made
    /// 0700).
    fn prepare(given: Option<&Path>) -> Result<Self> {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
        let Some(dir) = given else {
            let dir = tempfile::Builder::new()
                .prefix("qicp-bench-park-")
                .permissions(std::fs::Permissions::from_mode(0o700))
                .tempdir()
                .context("creating a scratch directory")?;
            return Ok(Scratch::Temporary(dir));
        };
        let refuse = |why: &str| anyhow::anyhow!("--scratch {}: {why}", dir.display());
        match std::fs::symlink_metadata(dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                // mkdir does not follow a link planted meanwhile: it fails on any entry.
                std::fs::DirBuilder::new()
                    .mode(0o700)
                    .create(dir)
                    .with_context(|| format!("creating --scratch {}", dir.display()))?;
            }
            Err(e) => return Err(e).with_context(|| format!("--scratch {}", dir.display())),
            Ok(meta) if meta.file_type().is_symlink() => {
                return Err(refuse("is a symbolic link; give a directory"));
            }
            Ok(meta) if !meta.is_dir() => return Err(refuse("is not a directory")),
            Ok(meta) => {
                let me = tempfile::tempfile()
                    .and_then(|f| f.metadata())
                    .context("finding this process's user")?
                    .uid();
                if meta.uid() != me {
                    return Err(refuse("belongs to another user"));
                }
                if let Some(entry) = std::fs::read_dir(dir)?.next() {
                    return Err(refuse(&format!(
                        "is not empty (it holds {:?}); give a new or an empty directory",
                        entry?.file_name()
                    )));
                }
                std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))?;
            }
        }
        Ok(Scratch::Given(dir.to_path_buf()))
    }

    fn path(&self) -> &Path {
        match self {
            Scratch::Temporary(dir) => dir.path(),
            Scratch::Given(dir) => dir,
        }
    }

    /// Removes a run's output directory before the run (a link is removed, never followed).
    fn clear(dir: &Path) -> Result<()> {
        match std::fs::symlink_metadata(dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(e).with_context(|| format!("clearing {}", dir.display())),
            Ok(meta) if meta.is_dir() => {
                std::fs::remove_dir_all(dir).with_context(|| format!("clearing {}", dir.display()))
            }
            Ok(_) => {
                std::fs::remove_file(dir).with_context(|| format!("clearing {}", dir.display()))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn mode(p: &Path) -> u32 {
        std::fs::metadata(p).expect("metadata").permissions().mode() & 0o777
    }

    /// Issue 14: the default scratch was `/tmp/qicp-bench-park-<pid>`, reused if it existed.
    #[test]
    fn default_scratch_is_fresh_private_and_unpredictable() {
        let a = Scratch::prepare(None).expect("scratch");
        let b = Scratch::prepare(None).expect("scratch");
        assert_ne!(a.path(), b.path());
        assert_eq!(mode(a.path()), 0o700);
        let name = a.path().file_name().expect("name").to_string_lossy();
        assert!(name.starts_with("qicp-bench-park-"), "{name}");
        assert!(
            !name.contains(&std::process::id().to_string()),
            "predictable: {name}"
        );
        let path = a.path().to_path_buf();
        drop(a);
        assert!(!path.exists(), "a temporary scratch is removed");
    }

    #[test]
    fn given_scratch_is_created_private_or_must_be_empty() {
        let root = tempfile::tempdir().expect("root");
        let new = root.path().join("new");
        let made = Scratch::prepare(Some(&new)).expect("created");
        assert_eq!(mode(made.path()), 0o700);
        drop(made);
        assert!(new.is_dir(), "a given scratch is kept");
        // Empty and open to all: accepted, and closed.
        std::fs::set_permissions(&new, std::fs::Permissions::from_mode(0o777)).expect("chmod");
        Scratch::prepare(Some(&new)).expect("empty is fine");
        assert_eq!(mode(&new), 0o700);
        // Something planted inside: refused.
        std::os::unix::fs::symlink("/etc/passwd", new.join("in-process")).expect("link");
        let err = Scratch::prepare(Some(&new)).expect_err("not empty");
        assert!(err.to_string().contains("not empty"), "{err}");
        // A link to a directory: refused.
        let link = root.path().join("link");
        std::os::unix::fs::symlink(root.path(), &link).expect("link");
        let err = Scratch::prepare(Some(&link)).expect_err("a link");
        assert!(err.to_string().contains("symbolic link"), "{err}");
    }

    #[test]
    fn clearing_a_run_directory_removes_a_link_not_its_target() {
        let root = tempfile::tempdir().expect("root");
        let victim = root.path().join("victim");
        std::fs::create_dir(&victim).expect("victim");
        std::fs::write(victim.join("keep"), "x").expect("file");
        let run = root.path().join("two-process");
        std::os::unix::fs::symlink(&victim, &run).expect("link");
        Scratch::clear(&run).expect("clear");
        assert!(!run.exists() && victim.join("keep").exists());
    }
}
