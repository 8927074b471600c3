//! `qicp match --subscribe`: the matcher as its own process, scans in and poses out.

use super::*;

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

/// The bridge figures added to `summary.json` under `"bridge"`: the service, its mode, the
/// subscriber's [`StreamReport`] (how the stream ended, what was received, lost or ignored)
/// and what the matcher made of it.
#[derive(Debug, Clone, Serialize)]
pub struct SubscribeSummary {
    /// The scan service.
    pub service: String,
    /// The service's back-pressure mode.
    pub backpressure: String,
    /// What the subscriber saw of the stream.
    #[serde(flatten)]
    pub stream: StreamReport,
    /// Scans whose message could not be turned into a scan (bad geometry, NaN time).
    pub rejected: u64,
    /// Poses published on `<prefix>/pose`.
    pub poses_published: u64,
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
    // iceoryx2 ends the loop cleanly on SIGINT and SIGTERM (the outputs are then written);
    // a hangup would end the process with the temporary files in place.
    if out.is_some() {
        crate::matching::remove_on_hangup()?;
    }
    // The outputs are opened before the first scan: a bad --out fails at once, and rows and
    // poses go to disk as they come (renamed into place at the end), not into memory.
    // A matcher that spreads its re-anchorings keeps the poses until the end instead.
    let mut matching = MatchLoop::new(config)?;
    let amends = matching.amends();
    let mut writer = out
        .map(|dir| RunWriter::create(dir).map(|w| w.keeping_poses(amends)))
        .transpose()?;
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
    let mut rejected = 0u64;
    let mut publish_error = None;
    let mut write_error = None;
    qicp_core::note!(
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
                    // The poses published stand; the trajectory written takes the
                    // amendments of a re-anchoring spread over the records before it.
                    if let (Some(w), Some(amendment)) = (&mut writer, matching.take_amendment())
                        && let Err(e) = w.amend(&amendment)
                    {
                        write_error = Some(e);
                        return ControlFlow::Break(());
                    }
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
                    qicp_core::note!("warning: scan {} rejected: {e}", view.header.seq);
                }
            },
            StreamEvent::PublisherJoined { skipped } if skipped > 0 => {
                qicp_core::note!(
                    "publisher joined; {skipped} scans were sent before this subscriber"
                )
            }
            StreamEvent::PublisherJoined { .. } => qicp_core::note!("publisher joined"),
            StreamEvent::PublisherLost => qicp_core::note!(
                "publisher lost without end-of-stream; waiting {} s for a new one",
                args.reconnect_timeout
            ),
            StreamEvent::Gap { missing } => qicp_core::note!("gap: {missing} scans lost"),
            StreamEvent::Intruder => qicp_core::note!(
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

    let bridge = SubscribeSummary {
        service: topics.scan(),
        backpressure: backpressure.name().to_string(),
        stream: report.clone(),
        rejected,
        poses_published: poses.sent(),
    };
    let totals = matching.summary();
    if let Some(warning) = totals.fallback_warning() {
        qicp_core::note!("warning: {warning}");
    }
    let mut summary = serde_json::to_value(&totals)?;
    summary["bridge"] = serde_json::to_value(&bridge)?;
    let text = serde_json::to_string_pretty(&summary)?;
    if let Some(writer) = writer {
        writer.commit(config, Some(&text))?;
    }
    if json {
        qicp_core::say!("{text}")?;
    } else {
        qicp_core::note!("{text}");
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
