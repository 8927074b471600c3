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
use std::io::{BufRead, BufReader};
use std::path::Path;
use thiserror::Error;

/// Why a log or trajectory file could not be read.
#[derive(Debug, Error)]
pub enum LogError {
    /// The file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
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
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        LogError::Io {
            path: path.display().to_string(),
            source,
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
        Ok(Box::new(BufReader::with_capacity(1 << 16, decoder)))
    } else {
        Ok(Box::new(reader))
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
        source: e,
    })? {
        line_no += 1;
        let line = std::str::from_utf8(&buf)
            .map_err(|_| LogError::malformed(name, line_no, "not UTF-8 text"))?
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
