//! # qicp-io
//!
//! Where records and trajectories come from and go to: CARMEN logs (`carmen`, read whole or
//! streamed in bounded memory), TUM trajectories (`tum`), Freiburg benchmark relations
//! (`relations`), ROS 2 bags in MCAP storage (`rosbag`, read streamed and written). A
//! [`RecordSource`] yields records in time order: the streaming CARMEN reader here, the
//! simulator (`qicp-sim`) and the bridge's scan subscriber (`qicp_bridge::Records`, from
//! `ScanSubscriber::records`) alike, all through the blanket impl for iterators of
//! `Result<Record, E>` (so `qicp-bridge` does not depend on this crate).
//!
//! Every reader names the file and the 1-based line of the first problem it meets; none
//! panics on bad input.

#![warn(missing_docs)]

pub mod carmen;
pub mod relations;
pub mod rosbag;
mod source;
pub mod tum;

pub use source::{LogOptions, LogReader};

/// Records in time order, one at a time: what a matcher is fed.
///
/// Implemented by every iterator of `Result<Record, E>` (the streaming CARMEN reader, the
/// simulator's drive, the bridge's `qicp_bridge::Records`), so a run is written once for all
/// of them.
pub trait RecordSource {
    /// Why a record could not be produced.
    type Error: std::error::Error + Send + Sync + 'static;
    /// The next record; `None` at the end.
    fn next_record(&mut self) -> Option<Result<qicp_core::Record, Self::Error>>;
}

impl<I, E> RecordSource for I
where
    I: Iterator<Item = Result<qicp_core::Record, E>>,
    E: std::error::Error + Send + Sync + 'static,
{
    type Error = E;
    fn next_record(&mut self) -> Option<Result<qicp_core::Record, E>> {
        self.next()
    }
}

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use thiserror::Error;

/// Why a log or trajectory file could not be read.
#[derive(Debug, Error)]
pub enum LogError {
    /// The file could not be opened or read.
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: String,
        /// The cause: part of the message, not a separate `source()`, so that it is printed
        /// once where a chain of causes is printed.
        cause: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {why}")]
    Malformed {
        /// The file.
        path: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// The file holds no laser record.
    #[error("{path}: no laser records (FLASER or ROBOTLASER1) to match; read {report}")]
    Empty {
        /// The file.
        path: String,
        /// What was read instead ([`carmen::LogInfo::report`]).
        report: String,
    },
    /// A ROS 2 bag cannot be read or written, or does not hold what was asked for.
    #[error("{path}: {why}")]
    Bag {
        /// The bag.
        path: String,
        /// What is wrong.
        why: String,
    },
    /// A trajectory file holds no pose of the kind asked for (an empty TUM file, a log
    /// without `TRUEPOS` read as ground truth).
    #[error("{path}: {why}")]
    NoPoses {
        /// The file.
        path: String,
        /// What it lacks.
        why: String,
    },
    /// A reader option is not usable (e.g. a negative field of view).
    #[error("option `{name}`: {why}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// What is wrong with it.
        why: String,
    },
}

impl LogError {
    pub(crate) fn io(path: &Path, cause: std::io::Error) -> Self {
        LogError::Io {
            path: path.display().to_string(),
            cause,
        }
    }

    /// A log that held no laser record.
    pub fn empty(path: &Path, info: &carmen::LogInfo) -> Self {
        LogError::Empty {
            path: path.display().to_string(),
            report: info.report(),
        }
    }

    pub(crate) fn malformed(path: &str, line: usize, why: impl Into<String>) -> Self {
        LogError::Malformed {
            path: path.to_string(),
            line,
            why: why.into(),
        }
    }
}

/// The magic bytes that open every bzip2 stream.
const BZIP2_MAGIC: &[u8] = b"BZh";

/// Opens a text file for buffered reading, decompressing it on the fly when it is bzip2
/// (recognised by its magic bytes, not its name; concatenated streams as written by `pbzip2`
/// are read in full).
pub fn open_text(path: &Path) -> Result<Box<dyn BufRead + Send>, LogError> {
    let file = File::open(path).map_err(|e| LogError::io(path, e))?;
    let mut reader = BufReader::with_capacity(1 << 16, file);
    let head = reader.fill_buf().map_err(|e| LogError::io(path, e))?;
    if head.starts_with(BZIP2_MAGIC) {
        let decoder = bzip2::read::MultiBzDecoder::new(reader);
        let ahead = ReadAhead::spawn(decoder).map_err(|e| LogError::io(path, e))?;
        Ok(Box::new(BufReader::with_capacity(1 << 16, ahead)))
    } else {
        Ok(Box::new(reader))
    }
}

/// Size of the chunks a [`ReadAhead`] thread reads (bytes).
const AHEAD_CHUNK: usize = 1 << 16;
/// Chunks a [`ReadAhead`] thread may read before they are taken: the bound on its memory
/// (256 KiB with [`AHEAD_CHUNK`]).
const AHEAD_CHUNKS: usize = 4;

/// A reader whose source is read on its own thread, a few chunks ahead: decompressing a bz2
/// log (about 1 s of CPU for Intel: 5-7 % of a boosted match, 15-20 % of a scan-to-scan one)
/// runs beside the matching on a second core instead of before it. Bytes and errors arrive in the source's
/// order; the thread ends at the source's end or error, or when the reader is dropped.
#[derive(Debug)]
pub struct ReadAhead {
    chunks: std::sync::mpsc::Receiver<std::io::Result<Vec<u8>>>,
    chunk: Vec<u8>,
    at: usize,
    done: bool,
}

impl ReadAhead {
    /// Starts the thread reading `source`.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn spawn<R: Read + Send + 'static>(mut source: R) -> std::io::Result<Self> {
        let (send, chunks) = std::sync::mpsc::sync_channel(AHEAD_CHUNKS);
        std::thread::Builder::new()
            .name("qicp-read-ahead".into())
            .spawn(move || {
                loop {
                    let mut chunk = vec![0; AHEAD_CHUNK];
                    let got = loop {
                        match source.read(&mut chunk) {
                            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                            other => break other,
                        }
                    };
                    let last = !matches!(got, Ok(n) if n > 0);
                    let item = got.map(|n| {
                        chunk.truncate(n);
                        chunk
                    });
                    // A dropped reader wants no more.
                    if send.send(item).is_err() || last {
                        return;
                    }
                }
            })?;
        Ok(Self {
            chunks,
            chunk: Vec::new(),
            at: 0,
            done: false,
        })
    }
}

impl Read for ReadAhead {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.at == self.chunk.len() {
            if self.done {
                return Ok(0);
            }
            match self.chunks.recv() {
                Ok(Ok(chunk)) => {
                    self.done = chunk.is_empty();
                    self.chunk = chunk;
                    self.at = 0;
                }
                Ok(Err(e)) => {
                    self.done = true;
                    return Err(e);
                }
                // The thread panicked (a source that panics): say so, do not end quietly.
                Err(_) => {
                    self.done = true;
                    return Err(std::io::Error::other("the read-ahead thread stopped"));
                }
            }
        }
        let n = buf.len().min(self.chunk.len() - self.at);
        buf[..n].copy_from_slice(&self.chunk[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// Reads lines as bytes into `buf` (cleared first), returning `false` at the end of input.
/// Strips the line terminator (`\n` or `\r\n`).
pub fn next_line<R: BufRead + ?Sized>(reader: &mut R, buf: &mut Vec<u8>) -> std::io::Result<bool> {
    buf.clear();
    if reader.read_until(b'\n', buf)? == 0 {
        return Ok(false);
    }
    if buf.last() == Some(&b'\n') {
        buf.pop();
        if buf.last() == Some(&b'\r') {
            buf.pop();
        }
    }
    Ok(true)
}

/// A file's first line without the byte-order mark some editors put before it (it is not
/// part of the line's first field).
#[must_use]
pub fn without_bom(first_line: &str) -> &str {
    first_line.strip_prefix('\u{feff}').unwrap_or(first_line)
}

/// Parses a number the way C's `strtod` writes them, accepting `nan`, `-nan` and `inf`.
/// Reads rows of eight finite numbers, one per line, skipping blank lines and `#` comments,
/// and hands each to `row` with its 1-based line number. `layout` names the columns in errors
/// (e.g. `timestamp x y z qx qy qz qw`).
pub(crate) fn read_rows8<R: BufRead + ?Sized>(
    reader: &mut R,
    name: &str,
    layout: &str,
    mut row: impl FnMut(usize, [f64; 8]) -> Result<(), LogError>,
) -> Result<(), LogError> {
    let mut buf = Vec::new();
    let mut line_no = 0;
    while next_line(reader, &mut buf).map_err(|e| LogError::Io {
        path: name.to_string(),
        cause: e,
    })? {
        line_no += 1;
        let line = std::str::from_utf8(&buf)
            .map_err(|_| LogError::malformed(name, line_no, "not UTF-8 text"))?;
        let line = if line_no == 1 {
            without_bom(line)
        } else {
            line
        }
        .trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut v = [0.0; 8];
        let mut n = 0;
        for tok in line.split_ascii_whitespace() {
            if n == 8 {
                return Err(LogError::malformed(
                    name,
                    line_no,
                    format!("more than 8 fields (expected `{layout}`)"),
                ));
            }
            v[n] = parse_f64(tok).filter(|x| x.is_finite()).ok_or_else(|| {
                LogError::malformed(name, line_no, format!("not a finite number: `{tok}`"))
            })?;
            n += 1;
        }
        if n != 8 {
            return Err(LogError::malformed(
                name,
                line_no,
                format!("{n} fields, expected 8 (`{layout}`)"),
            ));
        }
        row(line_no, v)?;
    }
    Ok(())
}

/// A decimal number as the logs write it; `None` if the token is not one.
pub fn parse_f64(token: &str) -> Option<f64> {
    token.parse::<f64>().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    /// Hands out its bytes a few at a time (as a decoder does), then, if told, an error.
    struct Trickle {
        bytes: Vec<u8>,
        at: usize,
        step: usize,
        fail_at_end: bool,
        dropped: Arc<AtomicBool>,
    }

    impl Read for Trickle {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.at == self.bytes.len() && self.fail_at_end {
                return Err(std::io::Error::other("corrupt stream"));
            }
            let n = buf.len().min(self.step).min(self.bytes.len() - self.at);
            buf[..n].copy_from_slice(&self.bytes[self.at..self.at + n]);
            self.at += n;
            Ok(n)
        }
    }

    impl Drop for Trickle {
        fn drop(&mut self) {
            self.dropped.store(true, Ordering::SeqCst);
        }
    }

    fn trickle(len: usize, step: usize, fail_at_end: bool) -> (Trickle, Arc<AtomicBool>) {
        let dropped = Arc::new(AtomicBool::new(false));
        let bytes = (0..len).map(|k| (k * 7 + k / 251) as u8).collect();
        let source = Trickle {
            bytes,
            at: 0,
            step,
            fail_at_end,
            dropped: Arc::clone(&dropped),
        };
        (source, dropped)
    }

    #[test]
    fn read_ahead_gives_the_sources_bytes_in_order() {
        for len in [
            0,
            1,
            1000,
            AHEAD_CHUNK - 1,
            AHEAD_CHUNK,
            AHEAD_CHUNK + 1,
            700_001,
        ] {
            for step in [1 << 20, 4093] {
                let (source, _) = trickle(len, step, false);
                let want = source.bytes.clone();
                let mut got = Vec::new();
                ReadAhead::spawn(source)
                    .unwrap()
                    .read_to_end(&mut got)
                    .unwrap();
                assert!(got == want, "{len} bytes read {step} at a time");
            }
        }
    }

    #[test]
    fn read_ahead_passes_on_the_sources_error_after_its_bytes() {
        let (source, _) = trickle(200_000, 5000, true);
        let want = source.bytes.clone();
        let mut reader = ReadAhead::spawn(source).unwrap();
        let mut got = vec![0; want.len()];
        reader.read_exact(&mut got).unwrap();
        assert!(got == want);
        let err = reader.read(&mut [0; 16]).unwrap_err();
        assert_eq!(err.to_string(), "corrupt stream");
    }

    #[test]
    fn a_dropped_read_ahead_stops_its_thread() {
        let (source, dropped) = trickle(10 << 20, 1 << 16, false);
        let mut reader = ReadAhead::spawn(source).unwrap();
        reader.read_exact(&mut [0; 100]).unwrap();
        drop(reader);
        // The thread sees the closed channel at its next chunk and drops the source.
        for _ in 0..500 {
            if dropped.load(Ordering::SeqCst) {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        panic!("the source of a dropped reader is still held after 5 s");
    }
}
