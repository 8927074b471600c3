//! One way in for every log format: a CARMEN log (plain or bzip2) or a ROS 2 bag (MCAP), told
//! apart by the file's first bytes.

use crate::LogError;
use crate::carmen::{CarmenOptions, CarmenReader};
use crate::rosbag::{BagOptions, BagReader, OdometrySource, is_mcap};
use qicp_core::Record;
use std::io::BufRead;
use std::path::Path;

/// How to read a log of either format.
#[derive(Debug, Clone, PartialEq)]
pub struct LogOptions {
    /// For CARMEN logs.
    pub carmen: CarmenOptions,
    /// For ROS 2 bags. Default: scans on `/scan`, odometry on `/odom`.
    pub bag: BagOptions,
}

impl Default for LogOptions {
    fn default() -> Self {
        Self {
            carmen: CarmenOptions::default(),
            bag: BagOptions::new("/scan", OdometrySource::Topic("/odom".into())),
        }
    }
}

/// The records of a log, streamed, whatever its format: a CARMEN log's in time order (lines
/// put back in order within a window), a bag's in bag order (which a late scan can break).
#[derive(Debug)]
pub enum LogReader {
    /// A CARMEN log.
    Carmen(Box<CarmenReader<Box<dyn BufRead + Send>>>),
    /// A rosbag2 MCAP file.
    Bag(Box<BagReader<std::io::BufReader<std::fs::File>>>),
}

impl LogReader {
    /// Opens `path` as a ROS 2 bag when it starts with MCAP's magic bytes, else as CARMEN.
    /// A bag is refused with CARMEN's laser options set (field of view, range limits): its
    /// scans carry their own, and the options would be ignored.
    pub fn open(path: &Path, opts: &LogOptions) -> Result<Self, LogError> {
        if is_mcap(path) {
            let c = &opts.carmen;
            let set = [
                ("flaser_fov_deg", c.flaser_fov_deg.is_some()),
                ("max_range", c.max_range.is_some()),
                ("min_range", c.min_range != 0.0),
            ];
            if let Some((name, _)) = set.into_iter().find(|(_, set)| *set) {
                return Err(LogError::InvalidOption {
                    name,
                    why: format!(
                        "describes a CARMEN log's laser; {} is a ROS 2 bag, whose scans carry \
                         their own",
                        path.display()
                    ),
                });
            }
            Ok(Self::Bag(Box::new(BagReader::open(path, &opts.bag)?)))
        } else {
            Ok(Self::Carmen(Box::new(CarmenReader::open(
                path,
                &opts.carmen,
            )?)))
        }
    }

    /// Records delivered so far.
    #[must_use]
    pub fn records(&self) -> usize {
        match self {
            Self::Carmen(r) => r.info.records,
            Self::Bag(r) => r.info().records,
        }
    }

    /// Time of the first and of the last record delivered (s).
    #[must_use]
    pub fn span(&self) -> Option<(f64, f64)> {
        match self {
            Self::Carmen(r) => r.info.span,
            Self::Bag(r) => r.info().span,
        }
    }

    /// Lines skipped as malformed (CARMEN with `lenient`; 0 for bags).
    #[must_use]
    pub fn skipped_lines(&self) -> usize {
        match self {
            Self::Carmen(r) => r.info.skipped_lines,
            Self::Bag(_) => 0,
        }
    }

    /// Records dropped: CARMEN lines too far out of time order, bag scans without odometry.
    #[must_use]
    pub fn dropped(&self) -> usize {
        match self {
            Self::Carmen(r) => r.info.late,
            Self::Bag(r) => r.info().without_odometry,
        }
    }

    /// Laser lines whose timestamp runs back against the line before (CARMEN; 0 for bags):
    /// matched in file order, or sorted with [`RecordOrder::Time`](crate::carmen::RecordOrder).
    #[must_use]
    pub fn out_of_order(&self) -> usize {
        match self {
            Self::Carmen(r) => r.info.out_of_order,
            Self::Bag(_) => 0,
        }
    }

    /// Prints the warnings of the read on stderr (skips and drops).
    pub fn warn(&self, path: &Path) {
        match self {
            Self::Carmen(r) => r.info.warn(path),
            Self::Bag(r) => r.info().warn(path),
        }
    }

    /// The error for a log that gave no record (a bag reports its own at its end).
    #[must_use]
    pub fn empty(&self, path: &Path) -> LogError {
        match self {
            Self::Carmen(r) => LogError::empty(path, &r.info),
            Self::Bag(r) => LogError::Bag {
                path: path.display().to_string(),
                why: format!("no laser records; topics: {}", r.info().topic_list()),
            },
        }
    }
}

impl Iterator for LogReader {
    type Item = Result<Record, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Self::Carmen(r) => r.next(),
            Self::Bag(r) => r.next(),
        }
    }
}
