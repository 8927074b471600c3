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
//!
//! The publishing driver (pacing, prefetch, connecting) is `qicp_bridge::drive`; this module
//! parses the flags into its [`DriveOptions`] and wires the commands to it.

use crate::logs::LogError;
use crate::logs::carmen::{CarmenOptions, CarmenReader};
use crate::matching::{MatchLoop, Matching, RunWriter, quantile, write_run};
use anyhow::{Context, Result, bail};
pub use qicp_bridge::drive::{MAX_SECONDS, RATE_FACTOR_RANGE};
use qicp_bridge::drive::{secs, topics};
use qicp_bridge::{
    BackPressure, ConnectError, PoseMessage, PosePublisher, PublisherOptions, ScanHeader,
    ScanPublisher, ScanSubscriber, StreamEnd, StreamEvent, StreamReport, SubscriberOptions, Topics,
    WaitOptions,
};
pub use qicp_bridge::{DriveOptions, PublishReport, Rate};
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

impl PublishArgs {
    /// The driver's options of these flags (`--publish` itself is the caller's).
    pub fn options(&self) -> DriveOptions {
        DriveOptions {
            prefix: self.service_prefix.clone(),
            iceoryx2_config: self.iceoryx2_config.clone(),
            rate: self.rate,
            backpressure: self.backpressure,
            wait_subscribers: self.wait_subscribers,
            connect_timeout: self.connect_timeout,
            linger: self.linger,
            block_timeout: self.block_timeout,
        }
    }
}

/// Publishes `records` as the flags say ([`qicp_bridge::publish_records`]).
pub fn publish_records<E>(
    records: impl Iterator<Item = Result<Record, E>> + Send,
    beams: usize,
    args: &PublishArgs,
) -> Result<PublishReport>
where
    E: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    Ok(qicp_bridge::publish_records(
        records,
        beams,
        &args.options(),
    )?)
}

/// Prints a publisher's report on stdout.
pub fn print_publish_report(report: &PublishReport) -> Result<()> {
    qicp_core::say!("{}", serde_json::to_string_pretty(report)?)?;
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
    /// The log's laser.
    #[command(flatten)]
    pub laser: crate::match_cmd::LaserArgs,
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
    let options = args.laser.apply(CarmenOptions {
        lenient: args.lenient,
        ..CarmenOptions::default()
    });
    let mut reader = CarmenReader::open(&args.log, &options)?;
    let Some(first) = reader.next().transpose()? else {
        return Err(LogError::empty(&args.log, &reader.info).into());
    };
    // The scan service's slices start at the first scan's size and grow if a later one is
    // longer.
    let beams = first.scan.beams();
    let records = std::iter::once(Ok(first)).chain(reader.by_ref());
    let report = publish_records(records, beams, &args.bridge)?;
    reader.info.warn(&args.log);
    print_publish_report(&report)
}
