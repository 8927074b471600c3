//! Logs: one laser record ([`LaserRecord`], `Record` in Python) and the records of a CARMEN
//! log or a ROS 2 bag, read as they are asked for ([`Log`]).

use crate::{QicpError, lock, pose_tuple, refusal};
use numpy::PyArray1;
use pyo3::prelude::*;
use qicp_core::Record;
use qicp_io::carmen::{CarmenOptions, CarmenReader, DEFAULT_MAX_BEAMS, RecordOrder};
use qicp_io::rosbag::{BagOptions, OdometrySource, is_mcap};
use qicp_io::{LogOptions, LogReader};
use std::path::PathBuf;
use std::sync::Mutex;

/// One laser record of a log: a scan, the robot's odometry and, where the log has it, truth.
#[pyclass(module = "qicp._qicp", name = "Record", frozen)]
pub(crate) struct LaserRecord(pub(crate) Record);

#[pymethods]
impl LaserRecord {
    /// Time of the scan (s).
    #[getter]
    fn timestamp(&self) -> f64 {
        self.0.timestamp()
    }
    /// Raw ranges as measured (m).
    #[getter]
    fn ranges<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.0.scan.ranges())
    }
    /// Bearing of the first beam (rad).
    #[getter]
    fn angle_min(&self) -> f64 {
        self.0.scan.geometry.angle_min
    }
    /// Bearing step between beams (rad).
    #[getter]
    fn angle_increment(&self) -> f64 {
        self.0.scan.geometry.angle_increment
    }
    /// Readings at or above this are no-returns (m).
    #[getter]
    fn range_max(&self) -> f64 {
        self.0.scan.geometry.max_range
    }
    /// Readings below this are dropped (m).
    #[getter]
    fn range_min(&self) -> f64 {
        self.0.scan.geometry.min_range
    }
    /// Robot pose by odometry (x, y, θ).
    #[getter]
    fn odometry(&self) -> (f64, f64, f64) {
        pose_tuple(&self.0.odometry)
    }
    /// Robot pose by ground truth, where the log has it.
    #[getter]
    fn truth(&self) -> Option<(f64, f64, f64)> {
        self.0.truth.as_ref().map(pose_tuple)
    }
    /// Pose of the laser on the robot (x, y, θ).
    #[getter]
    fn laser_offset(&self) -> (f64, f64, f64) {
        pose_tuple(&self.0.laser_offset)
    }
    fn __repr__(&self) -> String {
        format!(
            "Record(timestamp={}, beams={})",
            self.0.timestamp(),
            self.0.scan.beams()
        )
    }
}

/// The laser records of a log (CARMEN or ROS 2 bag), read as they are asked for (see
/// `read_carmen` and `read_bag`).
#[pyclass(module = "qicp._qicp")]
pub(crate) struct Log {
    path: PathBuf,
    reader: Mutex<LogReader>,
}

#[pymethods]
impl Log {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Option<LaserRecord>> {
        let mut reader = lock(&self.reader);
        let reader = &mut *reader;
        match py.detach(|| reader.next()) {
            Some(Ok(record)) => Ok(Some(LaserRecord(record))),
            Some(Err(e)) => Err(refusal(e)),
            None if reader.records() == 0 => Err(refusal(reader.empty(&self.path))),
            None => Ok(None),
        }
    }

    /// Records delivered so far.
    #[getter]
    fn records(&self) -> usize {
        lock(&self.reader).records()
    }

    /// Lines skipped as malformed so far (CARMEN with `lenient=True`).
    #[getter]
    fn skipped_lines(&self) -> usize {
        lock(&self.reader).skipped_lines()
    }

    /// Records dropped so far: CARMEN lines too far out of time order, bag scans that no
    /// odometry surrounds in time.
    #[getter]
    fn dropped(&self) -> usize {
        lock(&self.reader).dropped()
    }
}

/// Streams the laser records of a CARMEN log (plain or bzip2) as `qicp match` reads them, in
/// file order (`order="file"`, the order the laser took them) or sorted by time
/// (`order="time"`, as `qicp convert` writes a bag): an iterator of `Record`. A malformed line
/// raises `QicpError` naming its line (with `lenient=True` it is skipped and counted); a log
/// without a laser record raises too. `fov_deg`, `max_range` and `min_range` describe the laser
/// where the log's lines and `PARAM`s do not say it right (as `qicp match --fov-deg`,
/// `--max-range`, `--min-range`); each given wins over the log. Without `max_range`, a log
/// that does not say its maximum range (`FLASER` lines with no `PARAM robot_front_laser_max`)
/// has its first 1,000 laser records probed for a no-return code below the guessed 81 m (a
/// range far more of them read than the metre below it, across the field of view), which is
/// then read as a no-return: each `Record`'s `range_max` says where.
#[pyfunction]
#[pyo3(signature = (
    path, *, lenient = false, max_beams = DEFAULT_MAX_BEAMS, order = "file", fov_deg = None,
    max_range = None, min_range = 0.0
))]
pub(crate) fn read_carmen(
    path: PathBuf,
    lenient: bool,
    max_beams: usize,
    order: &str,
    fov_deg: Option<f64>,
    max_range: Option<f64>,
    min_range: f64,
) -> PyResult<Log> {
    let order: RecordOrder = order.parse().map_err(QicpError::new_err)?;
    let options = CarmenOptions {
        lenient,
        max_beams,
        order,
        flaser_fov_deg: fov_deg,
        max_range,
        min_range,
        ..CarmenOptions::default()
    };
    let reader = CarmenReader::open(&path, &options).map_err(refusal)?;
    Ok(Log {
        path,
        reader: Mutex::new(LogReader::Carmen(Box::new(reader))),
    })
}

/// Streams the laser records of a ROS 2 bag (rosbag2, MCAP storage), as `qicp match BAG`
/// reads them: scans from `scan_topic`, odometry from `odom_topic` or, with `odom_frame`, from
/// the /tf transform `odom_frame` -> `base_frame`, interpolated to each scan's stamp; with
/// `odom_topic=None` and no `odom_frame`, none: every scan at one pose (as `qicp match
/// --no-odometry`). A missing topic raises `QicpError` listing the bag's topics.
#[pyfunction]
#[pyo3(signature = (path, *, scan_topic = "/scan", odom_topic = "/odom", odom_frame = None,
                    base_frame = "base_link", max_beams = DEFAULT_MAX_BEAMS))]
pub(crate) fn read_bag(
    path: PathBuf,
    scan_topic: &str,
    odom_topic: Option<&str>,
    odom_frame: Option<String>,
    base_frame: &str,
    max_beams: usize,
) -> PyResult<Log> {
    if !is_mcap(&path) {
        let why = if path.is_file() {
            "not a ROS 2 bag in MCAP storage (no MCAP magic bytes)"
        } else {
            "no such file"
        };
        return Err(QicpError::new_err(format!("{}: {why}", path.display())));
    }
    let odometry = match (odom_topic, odom_frame.as_deref()) {
        (None, None) => OdometrySource::None,
        (topic, frame) => OdometrySource::from_names(topic.unwrap_or("/odom"), frame, base_frame),
    };
    let options = LogOptions {
        bag: BagOptions {
            max_beams,
            ..BagOptions::new(scan_topic, odometry)
        },
        ..LogOptions::default()
    };
    let reader = LogReader::open(&path, &options).map_err(refusal)?;
    Ok(Log {
        path,
        reader: Mutex::new(reader),
    })
}
