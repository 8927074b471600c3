//! `qicp bench bridge --sizes 2k,64k,1m,4m`: where zero copy pays.
//!
//! For each payload size, the same bytes go through iceoryx2 ([`qicp_bridge::payload`]: the
//! publisher writes the payload into the loaned shared memory, the subscriber reads it in
//! place) and through a Unix-domain stream socket (the writer fills its buffer and `write`s
//! it, the reader `read`s it into its own buffer: two copies through the kernel). Both sides
//! do the same work on the payload: the sender writes every byte once, the receiver reads
//! every byte once (a checksum, and a check of the first and last byte). Both readers wait the
//! same way (`event`: asleep in the kernel until woken; `spin`: polling).
//!
//! - **latency** (p50, p99): each message is sent after the previous one was read (every
//!   message pays a wake-up), from the moment its payload is complete to the moment the
//!   reader has read its last byte;
//! - **CPU per message**: CPU time of the sending and the receiving thread together over that
//!   paced run, per message (`/proc/thread-self/schedstat`, ns; `stat` ticks if missing). It
//!   includes writing and reading the payload once, which any transport pays
//!   (`fill_and_read_cpu_us`: the same in one thread, without transport);
//! - **messages/s**: messages sent back to back, from the first send to the last read.
//!
//! The first [`WARMUP`] messages of every run are not counted: they fault in the pages of the
//! shared memory and of the buffers.

use super::{WaitStrategy, load_average, stamp};
use crate::matching::quantile;
use anyhow::{Context, Result, bail, ensure};
use qicp_bridge::Topics;
use qicp_bridge::payload::{PayloadPublisher, PayloadSubscriber, Waiting};
use serde::Serialize;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

/// Largest payload accepted (bytes): 256 MiB.
pub const MAX_PAYLOAD: usize = 256 << 20;
/// Payload bytes a latency run moves at most: large payloads get fewer messages.
const LATENCY_BYTES: usize = 2 << 30;
/// Payload bytes a throughput run moves at most.
const BURST_BYTES: usize = 1 << 30;
/// Fewest messages of a run, whatever the size.
const MIN_MESSAGES: usize = 50;
/// Uncounted messages at the start of every run.
pub const WARMUP: usize = 16;
/// The subscriber's buffer (payloads): the publisher of a burst runs at most this far ahead.
const BUFFER: usize = 4;
/// Every wait of the bench gives up after this long.
const STALL: Duration = Duration::from_secs(20);
/// Shortest run of [`fill_and_read_cpu_us`] (wall time).
const FILL_AND_READ_TIME: Duration = Duration::from_millis(200);
/// The socket frame's header: `seq` (u64) and the send time (f64), like [`PayloadHeader`].
///
/// [`PayloadHeader`]: qicp_bridge::payload::PayloadHeader
const FRAME_HEADER: usize = 16;

/// Parses a payload size: bytes, or with a suffix `k` (KiB) or `m` (MiB), e.g. `2k`, `4m`.
pub fn parse_size(s: &str) -> Result<usize, String> {
    let t = s.trim().to_ascii_lowercase();
    let (digits, unit) = match t.strip_suffix('k') {
        Some(d) => (d, 1usize << 10),
        None => match t.strip_suffix('m') {
            Some(d) => (d, 1 << 20),
            None => (t.as_str(), 1),
        },
    };
    let n: usize = digits
        .parse()
        .map_err(|_| format!("bad size {s:?}: use bytes or k/m, like 2k,64k,1m,4m"))?;
    match n.checked_mul(unit) {
        Some(b) if (1..=MAX_PAYLOAD).contains(&b) => Ok(b),
        _ => Err(format!(
            "size {s:?} out of range: 1 byte to {} MiB",
            MAX_PAYLOAD >> 20
        )),
    }
}

/// One transport's figures at one size.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct PayloadFigures {
    /// Median one-way latency (µs), payload complete to payload read.
    pub p50_us: f64,
    /// 99th percentile one-way latency (µs).
    pub p99_us: f64,
    /// Messages per second, sent back to back.
    pub msgs_per_s: f64,
    /// CPU time of both threads per message (µs), paced; `null` without /proc.
    pub cpu_us_per_msg: Option<f64>,
}

/// Both transports at one payload size.
#[derive(Debug, Clone, Serialize)]
pub struct SizeFigures {
    /// Payload bytes per message.
    pub bytes: usize,
    /// Counted messages of each latency run.
    pub messages: usize,
    /// Counted messages of each throughput run.
    pub burst: usize,
    /// iceoryx2, written and read in place.
    pub iceoryx2: PayloadFigures,
    /// Unix-domain stream socket, the same bytes.
    pub uds: PayloadFigures,
    /// `iceoryx2.p50_us / uds.p50_us`.
    pub p50_ratio: f64,
    /// `iceoryx2.cpu_us_per_msg / uds.cpu_us_per_msg`.
    pub cpu_ratio: Option<f64>,
    /// CPU time of writing the payload once and reading it once in one thread, with no
    /// transport (µs): the part of `cpu_us_per_msg` that any transport pays.
    pub fill_and_read_cpu_us: Option<f64>,
}

/// Result of `qicp bench bridge --sizes`.
#[derive(Debug, Clone, Serialize)]
pub struct PayloadBenchReport {
    /// One entry per size, in the order given.
    pub sizes: Vec<SizeFigures>,
    /// How both readers waited.
    pub wait: WaitStrategy,
    /// /proc/loadavg (1, 5, 15 min) at the start and at the end.
    pub load: [[f64; 3]; 2],
}

/// Runs both transports at every size; `messages` and `burst` cap the counted messages of a
/// run (large payloads get fewer: at most 2 GiB per latency run and 1 GiB per burst).
pub fn payload_bench(
    sizes: &[usize],
    messages: usize,
    burst: usize,
    wait: WaitStrategy,
) -> Result<PayloadBenchReport> {
    ensure!(messages > 0 && burst > 0, "empty bench");
    let load_start = load_average();
    let spin = wait == WaitStrategy::Spin;
    let mut out = Vec::new();
    for &bytes in sizes {
        let count = |cap: usize, budget: usize| cap.min((budget / bytes).max(MIN_MESSAGES));
        let (n, b) = (count(messages, LATENCY_BYTES), count(burst, BURST_BYTES));
        // Interleaved, so that a burst of machine noise hits both transports alike.
        let ice_paced = iceoryx2_run(bytes, n, true, spin)?;
        let uds_paced = uds_run(bytes, n, true, spin)?;
        let ice_burst = iceoryx2_run(bytes, b, false, spin)?;
        let uds_burst = uds_run(bytes, b, false, spin)?;
        let iceoryx2 = PayloadFigures::of(&ice_paced, &ice_burst);
        let uds = PayloadFigures::of(&uds_paced, &uds_burst);
        out.push(SizeFigures {
            bytes,
            messages: n,
            burst: b,
            p50_ratio: iceoryx2.p50_us / uds.p50_us,
            cpu_ratio: iceoryx2
                .cpu_us_per_msg
                .zip(uds.cpu_us_per_msg)
                .map(|(i, u)| i / u),
            fill_and_read_cpu_us: fill_and_read_cpu_us(bytes, n),
            iceoryx2,
            uds,
        });
    }
    Ok(PayloadBenchReport {
        sizes: out,
        wait,
        load: [load_start, load_average()],
    })
}

/// Prints the report as a table.
///
/// # Errors
/// When stdout cannot be written.
pub fn print_table(report: &PayloadBenchReport) -> Result<(), qicp_core::output::StdoutError> {
    qicp_core::say!(
        "{:>9} {:<9} {:>10} {:>10} {:>12} {:>11}",
        "bytes",
        "transport",
        "p50 µs",
        "p99 µs",
        "msgs/s",
        "CPU µs/msg"
    )?;
    let cpu = |c: Option<f64>| c.map_or("?".to_string(), |c| format!("{c:.2}"));
    for s in &report.sizes {
        for (name, f) in [("iceoryx2", s.iceoryx2), ("uds", s.uds)] {
            qicp_core::say!(
                "{:>9} {name:<9} {:>10.2} {:>10.2} {:>12.0} {:>11}",
                s.bytes,
                f.p50_us,
                f.p99_us,
                f.msgs_per_s,
                cpu(f.cpu_us_per_msg)
            )?;
        }
        qicp_core::say!(
            "{:>9} iceoryx2/uds: p50 {:.3}, CPU {}; writing + reading the payload alone {} µs",
            "",
            s.p50_ratio,
            s.cpu_ratio.map_or("?".to_string(), |r| format!("{r:.3}")),
            cpu(s.fill_and_read_cpu_us)
        )?;
    }
    qicp_core::say!(
        "readers {:?}; load {:.2} → {:.2}",
        report.wait,
        report.load[0][0],
        report.load[1][0]
    )
}

/// The payload's byte `i` in message `seq`: what the sender writes and the reader checks.
fn byte(i: usize, seq: u64) -> u8 {
    (i as u8).wrapping_add(seq as u8)
}

/// Reads every byte of `payload` (in 8-byte words) and checks its first and last byte.
fn read_payload(payload: &[u8], seq: u64) -> Result<u64> {
    let words = payload.chunks_exact(8);
    let tail = words.remainder().iter().map(|&b| u64::from(b)).sum::<u64>();
    let sum = words.fold(tail, |acc, w| {
        acc.wrapping_add(u64::from_ne_bytes(w.try_into().unwrap_or_default()))
    });
    let (Some(&first), Some(&last)) = (payload.first(), payload.last()) else {
        bail!("message {seq}: empty payload");
    };
    ensure!(
        first == byte(0, seq) && last == byte(payload.len() - 1, seq),
        "message {seq}: payload corrupted"
    );
    Ok(sum)
}

/// CPU time this thread has run so far (ns): `/proc/thread-self/schedstat` (ns), else
/// `utime + stime` of `/proc/thread-self/stat` (10 ms ticks).
fn thread_cpu_ns() -> Option<u64> {
    if let Ok(text) = std::fs::read_to_string("/proc/thread-self/schedstat")
        && let Some(ns) = text.split_whitespace().next().and_then(|f| f.parse().ok())
    {
        return Some(ns);
    }
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    // Fields after the command name (which may hold spaces); utime and stime are 14 and 15.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i - 3)?.parse::<u64>().ok();
    Some((ticks(14)? + ticks(15)?) * 10_000_000)
}

/// CPU per repetition of writing a payload of `bytes` and reading it back, one thread (µs):
/// at least `reps` repetitions, and as many more as [`FILL_AND_READ_TIME`] takes. A thread
/// that never sleeps has its CPU time in `/proc` brought up to date only at the scheduler's
/// tick (a few ms), so the run must last many ticks to be read to a few per cent.
fn fill_and_read_cpu_us(bytes: usize, reps: usize) -> Option<f64> {
    let mut buf = vec![0u8; bytes];
    let start = thread_cpu_ns()?;
    let clock = Instant::now();
    let mut seq = 0u64;
    while seq < reps as u64 || clock.elapsed() < FILL_AND_READ_TIME {
        for (i, b) in buf.iter_mut().enumerate() {
            *b = byte(i, seq);
        }
        std::hint::black_box(read_payload(std::hint::black_box(&buf), seq).ok());
        seq += 1;
    }
    let end = thread_cpu_ns()?;
    Some((end - start) as f64 / 1e3 / seq as f64)
}

/// One run: the counted messages' latencies, the time from the first counted send to the last
/// read, and both threads' CPU time over the counted messages.
struct Run {
    latencies_us: Vec<f64>,
    elapsed_s: f64,
    cpu_ns: Option<u64>,
    messages: usize,
}

impl PayloadFigures {
    fn of(paced: &Run, burst: &Run) -> Self {
        Self {
            p50_us: quantile(&paced.latencies_us, 0.5),
            p99_us: quantile(&paced.latencies_us, 0.99),
            msgs_per_s: burst.messages as f64 / burst.elapsed_s.max(1e-12),
            cpu_us_per_msg: paced.cpu_ns.map(|c| c as f64 / 1e3 / paced.messages as f64),
        }
    }
}

/// What the sending thread measured: the time of its first counted send and its CPU time over
/// the counted messages.
struct Sent {
    first_send: f64,
    cpu_ns: Option<u64>,
}

/// The receiving side's bookkeeping, shared by both transports.
struct Reader {
    epoch: Instant,
    messages: usize,
    paced: bool,
    ack: std::sync::mpsc::SyncSender<()>,
    received: usize,
    latencies_us: Vec<f64>,
    cpu_start: Option<u64>,
    last_receive: f64,
    checksum: u64,
}

impl Reader {
    fn new(
        epoch: Instant,
        messages: usize,
        paced: bool,
        ack: std::sync::mpsc::SyncSender<()>,
    ) -> Self {
        Self {
            epoch,
            messages,
            paced,
            ack,
            received: 0,
            latencies_us: Vec::with_capacity(messages),
            cpu_start: None,
            last_receive: 0.0,
            checksum: 0,
        }
    }

    fn done(&self) -> bool {
        self.received >= WARMUP + self.messages
    }

    /// One message: read every byte, then stamp (counted messages only), then acknowledge.
    fn take(&mut self, seq: u64, sent: f64, payload: &[u8]) -> Result<()> {
        ensure!(
            seq == self.received as u64,
            "message {seq} arrived as number {}",
            self.received
        );
        if self.received == WARMUP {
            self.cpu_start = thread_cpu_ns();
        }
        self.checksum = self.checksum.wrapping_add(read_payload(payload, seq)?);
        self.last_receive = stamp(self.epoch);
        if self.received >= WARMUP {
            self.latencies_us.push((self.last_receive - sent) * 1e6);
        }
        self.received += 1;
        if self.paced {
            let _ = self.ack.try_send(());
        }
        Ok(())
    }

    fn finish(self, sent: Sent) -> Run {
        std::hint::black_box(self.checksum);
        let cpu_ns = self
            .cpu_start
            .zip(thread_cpu_ns())
            .map(|(a, b)| b - a)
            .zip(sent.cpu_ns)
            .map(|(r, s)| r + s);
        Run {
            latencies_us: self.latencies_us,
            elapsed_s: self.last_receive - sent.first_send,
            cpu_ns,
            messages: self.messages,
        }
    }
}

/// The sending loop of both transports: `send(seq)` the `WARMUP + messages` messages,
/// each after the previous one was read if `paced`.
fn send_all(
    epoch: Instant,
    messages: usize,
    paced: bool,
    ack: &std::sync::mpsc::Receiver<()>,
    mut send: impl FnMut(u64) -> Result<()>,
) -> Result<Sent> {
    let mut sent = Sent {
        first_send: 0.0,
        cpu_ns: None,
    };
    let mut cpu_start = None;
    for seq in 0..(WARMUP + messages) as u64 {
        if seq == WARMUP as u64 {
            cpu_start = thread_cpu_ns();
            sent.first_send = stamp(epoch);
        }
        send(seq)?;
        if paced {
            ack.recv_timeout(STALL).context("the reader stalled")?;
        }
    }
    sent.cpu_ns = cpu_start.zip(thread_cpu_ns()).map(|(a, b)| b - a);
    Ok(sent)
}

/// iceoryx2: a publisher thread writes each payload into loaned shared memory; this thread
/// reads it in place.
fn iceoryx2_run(bytes: usize, messages: usize, paced: bool, spin: bool) -> Result<Run> {
    let topics = Topics::new(&format!(
        "qicp-bench-{}-{bytes}-{}",
        std::process::id(),
        if paced { "paced" } else { "burst" }
    ));
    let subscriber = PayloadSubscriber::create(&topics, BUFFER)?;
    let epoch = Instant::now();
    let (ack_tx, ack_rx) = std::sync::mpsc::sync_channel::<()>(1);
    let (done_tx, done_rx) = std::sync::mpsc::sync_channel::<()>(1);
    let sender = std::thread::spawn(move || -> Result<Sent> {
        let mut p = PayloadPublisher::create(&topics, bytes, BUFFER, !spin, STALL)?;
        ensure!(
            p.wait_for_subscriber(STALL)?,
            "the bench subscriber did not connect"
        );
        let sent = send_all(epoch, messages, paced, &ack_rx, |seq| {
            p.publish_with(bytes, |i| byte(i, seq), || stamp(epoch))?;
            Ok(())
        })?;
        // Keep the publisher (and the payloads still in the subscriber's buffer) until read.
        let _ = done_rx.recv_timeout(STALL);
        Ok(sent)
    });
    let mut reader = Reader::new(epoch, messages, paced, ack_tx);
    let mut failure = None;
    let waiting = if spin { Waiting::Spin } else { Waiting::Event };
    subscriber.run(waiting, STALL, |header, payload| {
        if let Err(e) = reader.take(header.seq, header.sent, payload) {
            failure = Some(e);
            return ControlFlow::Break(());
        }
        if reader.done() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })?;
    if let Some(e) = failure {
        return Err(e);
    }
    let _ = done_tx.try_send(());
    let sent = sender
        .join()
        .map_err(|_| anyhow::anyhow!("the iceoryx2 bench publisher panicked"))??;
    ensure!(reader.done(), "the iceoryx2 bench lost messages");
    drop(subscriber);
    Ok(reader.finish(sent))
}

/// The socket baseline: the writer fills its buffer and writes it to a Unix-domain stream
/// socket; this thread reads each frame into its own buffer.
fn uds_run(bytes: usize, messages: usize, paced: bool, spin: bool) -> Result<Run> {
    use std::io::{Read, Write};
    let frame = FRAME_HEADER + bytes;
    let (mut writer, mut reader_socket) = std::os::unix::net::UnixStream::pair()?;
    reader_socket.set_read_timeout(Some(STALL))?;
    reader_socket.set_nonblocking(spin)?;
    writer.set_write_timeout(Some(STALL))?;
    let epoch = Instant::now();
    let (ack_tx, ack_rx) = std::sync::mpsc::sync_channel::<()>(1);
    let sender = std::thread::spawn(move || -> Result<Sent> {
        let mut buf = vec![0u8; frame];
        send_all(epoch, messages, paced, &ack_rx, |seq| {
            for (i, b) in buf[FRAME_HEADER..].iter_mut().enumerate() {
                *b = byte(i, seq);
            }
            buf[..8].copy_from_slice(&seq.to_ne_bytes());
            buf[8..16].copy_from_slice(&stamp(epoch).to_ne_bytes());
            writer.write_all(&buf)?;
            Ok(())
        })
    });
    let mut reader = Reader::new(epoch, messages, paced, ack_tx);
    let mut buf = vec![0u8; frame];
    let deadline = Instant::now() + STALL + STALL;
    while !reader.done() {
        if spin {
            let mut filled = 0;
            while filled < frame {
                match reader_socket.read(&mut buf[filled..]) {
                    Ok(0) => bail!("the socket closed"),
                    Ok(n) => filled += n,
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        ensure!(Instant::now() < deadline, "the socket bench stalled");
                        std::hint::spin_loop();
                    }
                    Err(e) => return Err(e.into()),
                }
            }
        } else {
            reader_socket
                .read_exact(&mut buf)
                .context("the socket bench stalled")?;
        }
        let seq = u64::from_ne_bytes(buf[..8].try_into()?);
        let sent = f64::from_ne_bytes(buf[8..16].try_into()?);
        reader.take(seq, sent, &buf[FRAME_HEADER..])?;
    }
    let sent = sender
        .join()
        .map_err(|_| anyhow::anyhow!("the socket bench writer panicked"))??;
    Ok(reader.finish(sent))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_in_binary_units_and_out_of_range_is_refused() {
        assert_eq!(parse_size("2k"), Ok(2048));
        assert_eq!(parse_size("64K"), Ok(65536));
        assert_eq!(parse_size("4m"), Ok(4 << 20));
        assert_eq!(parse_size("1500"), Ok(1500));
        for bad in ["0", "-1k", "1g", "k", "257m", "99999999999999999999m"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn both_transports_carry_every_byte_in_order() {
        for (paced, spin) in [(true, false), (false, false), (true, true)] {
            for run in [
                iceoryx2_run(10_001, 30, paced, spin).expect("iceoryx2"),
                uds_run(10_001, 30, paced, spin).expect("uds"),
            ] {
                assert_eq!(run.latencies_us.len(), 30);
                assert!(run.latencies_us.iter().all(|l| *l >= 0.0));
                assert!(run.elapsed_s > 0.0);
            }
        }
    }

    #[test]
    fn a_corrupted_payload_is_caught() {
        let mut p: Vec<u8> = (0..100).map(|i| byte(i, 7)).collect();
        assert!(read_payload(&p, 7).is_ok());
        p[99] ^= 1;
        assert!(read_payload(&p, 7).is_err());
        assert!(read_payload(&p[..0], 7).is_err());
    }
}
