//! `qicp bench bridge`: iceoryx2 against a Unix socket, message latency and CPU.

use super::*;

/// Messages a latency or throughput run may ask for.
const MAX_MESSAGES: u64 = 10_000_000;
/// Beams a benchmark scan may have (8 MB of ranges): a scan is allocated whole.
const MAX_BEAMS: u64 = 1_000_000;

/// A count from 1 to `max` on the command line.
fn count(max: u64) -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::new().range(1..=max)
}

/// Arguments of `qicp bench bridge`.
#[derive(Debug, Clone, clap::Args)]
pub struct BridgeBenchArgs {
    /// Messages per latency run (each waits for the previous one to arrive); with --sizes, at
    /// most this many, and at most 2 GiB of payload.
    #[arg(long, default_value_t = 2000, value_parser = count(MAX_MESSAGES))]
    pub messages: usize,
    /// Messages per throughput run (sent back to back); with --sizes, at most this many, and
    /// at most 1 GiB of payload.
    #[arg(long, default_value_t = 20000, value_parser = count(MAX_MESSAGES))]
    pub burst: usize,
    /// Beams per scan (scans through the scan service; not with --sizes), at most a million.
    #[arg(long, default_value_t = 181, value_parser = count(MAX_BEAMS))]
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
            qicp_core::say!("{}", serde_json::to_string(&report)?)?;
        } else {
            payload_bench::print_table(&report)?;
        }
        return Ok(());
    }
    let report = bridge_bench(args)?;
    if args.json {
        qicp_core::say!("{}", serde_json::to_string(&report)?)?;
    } else {
        qicp_core::say!(
            "{:<10} {:>10} {:>10} {:>14}",
            "transport",
            "p50 µs",
            "p99 µs",
            "msgs/s"
        )?;
        for (name, f) in [("iceoryx2", report.iceoryx2), ("uds", report.uds)] {
            qicp_core::say!(
                "{name:<10} {:>10.2} {:>10.2} {:>14.0}",
                f.p50_us,
                f.p99_us,
                f.msgs_per_s
            )?;
        }
        qicp_core::say!(
            "{} beams, {} bytes per message, readers {:?}; p50 ratio iceoryx2/uds = {:.2}",
            report.beams,
            report.bytes,
            report.wait,
            report.p50_ratio
        )?;
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
pub(super) struct RunTimes {
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
pub(super) fn stamp(epoch: Instant) -> f64 {
    epoch.elapsed().as_secs_f64()
}

/// iceoryx2: publisher thread → this thread's `ScanSubscriber`. With `paced`, each message
/// is sent after the previous one arrived (latency: every message pays a wake-up); without,
/// back to back (throughput).
pub(super) fn iceoryx2_run(
    ranges: &[f64],
    messages: usize,
    paced: bool,
    spin: bool,
) -> Result<RunTimes> {
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
pub(super) fn uds_run(
    ranges: &[f64],
    messages: usize,
    paced: bool,
    spin: bool,
) -> Result<RunTimes> {
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
