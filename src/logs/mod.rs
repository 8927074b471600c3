//! Log readers and writers: CARMEN (`carmen`), TUM trajectories (`tum`).

pub mod carmen;
pub mod tum;

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
}
