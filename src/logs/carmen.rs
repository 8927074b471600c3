//! CARMEN text logs: `FLASER`, `ROBOTLASER1`, `ODOM`, `PARAM` (plain or `.bz2`).
//! (Owned by the log helper; signatures fixed, bodies to come.)

use super::LogError;
use qicp_core::Record;
use std::io::Write;
use std::path::Path;

/// How to read a CARMEN log.
#[derive(Debug, Clone, PartialEq)]
pub struct CarmenOptions {
    /// Skip and count malformed lines instead of failing on the first.
    pub lenient: bool,
}

impl Default for CarmenOptions {
    fn default() -> Self {
        Self { lenient: false }
    }
}

/// A log read into memory, laser records sorted by timestamp.
#[derive(Debug, Clone, Default)]
pub struct CarmenLog {
    /// Laser records in time order.
    pub records: Vec<Record>,
    /// Malformed lines skipped (lenient mode only).
    pub skipped_lines: usize,
}

/// Reads a CARMEN log.
pub fn read_carmen(path: &Path, _opts: &CarmenOptions) -> Result<CarmenLog, LogError> {
    Err(LogError::Malformed {
        path: path.display().to_string(),
        line: 0,
        why: "reader not implemented yet".into(),
    })
}

/// Writes records as a CARMEN log.
pub fn write_carmen<W: Write>(_w: W, _records: &[Record]) -> std::io::Result<()> {
    Err(std::io::Error::other("writer not implemented yet"))
}
