//! Python bindings of qicp (the `qicp._qicp` extension module of the `qicp` package).
//!
//! The matchers are the command line's: a [`Matcher`] is built from the registry of the `qicp`
//! command (the built-in algorithms and PL-ICP) and runs the same pipeline, so a log fed
//! through it gives the trajectory `qicp match` writes, to the last bit. Errors raise
//! `qicp.QicpError` with the message the command line prints; the GIL is released while a
//! scan is matched or a log line parsed.

use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use qicp_eval::{AteOptions, AteReport, RelationsReport};
use qicp_io::carmen::{CarmenOptions, CarmenReader, DEFAULT_FLASER_MAX_RANGE, DEFAULT_MAX_BEAMS};
use qicp_io::rosbag::{BagOptions, OdometrySource, is_mcap};
use qicp_io::tum::Stamped;
use qicp_io::{LogOptions, LogReader};
use qicp_matchers::{MatcherConfig, Odometry, Registry};
use std::path::PathBuf;
use std::sync::{LazyLock, Mutex, MutexGuard};

create_exception!(
    _qicp,
    QicpError,
    PyException,
    "A refusal of qicp: a bad configuration, an unreadable log, a scan that cannot be a laser's. \
     The message is the one the command line prints."
);

/// The registry of the `qicp` command: the built-in algorithms and indexes, and PL-ICP.
static REGISTRY: LazyLock<Registry> = LazyLock::new(|| {
    let mut registry = Registry::builtin();
    qicp_plicp::register(&mut registry);
    registry
});

/// An error as the command line prints it: its message, then its causes, joined by ": ".
fn refusal(err: impl std::error::Error) -> PyErr {
    let mut message = err.to_string();
    let mut source = err.source();
    while let Some(cause) = source {
        message.push_str(": ");
        message.push_str(&cause.to_string());
        source = cause.source();
    }
    QicpError::new_err(message)
}

/// `context: error`, as the command line's `with_context` prints it.
fn refusal_in(context: String, err: impl std::error::Error) -> PyErr {
    let inner = refusal(err);
    let message = Python::attach(|py| inner.value(py).to_string());
    QicpError::new_err(format!("{context}: {message}"))
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while matching cannot leave the pipeline half-updated in a way later calls could
    // observe more wrongly than the panic itself, which Python already saw as an exception.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn pose_tuple(p: &Pose2) -> (f64, f64, f64) {
    (p.x, p.y, p.theta)
}

fn pose_of((x, y, theta): (f64, f64, f64), name: &str) -> PyResult<Pose2> {
    if x.is_finite() && y.is_finite() && theta.is_finite() {
        Ok(Pose2::new(x, y, theta))
    } else {
        Err(QicpError::new_err(format!(
            "{name} ({x}, {y}, {theta}) must be finite"
        )))
    }
}

/// A Python value of a configuration section as TOML.
fn toml_value(key: &str, value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    if let Ok(b) = value.cast::<pyo3::types::PyBool>() {
        return Ok(toml::Value::Boolean(b.is_true()));
    }
    if let Ok(i) = value.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = value.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    if let Ok(s) = value.extract::<String>() {
        return Ok(toml::Value::String(s));
    }
    if let Ok(d) = value.cast::<PyDict>() {
        return section(key, d).map(toml::Value::Table);
    }
    Err(QicpError::new_err(format!(
        "matcher.{key}: {} is not a number, a boolean, a string or a table",
        value.repr()?
    )))
}

fn section(prefix: &str, dict: &Bound<'_, PyDict>) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    for (k, v) in dict.iter() {
        let k: String = k.extract()?;
        let path = format!("{prefix}.{k}");
        table.insert(k, toml_value(&path, &v)?);
    }
    Ok(table)
}

/// A laser-odometry pipeline: feed it scans in time order, get the robot's pose in the world.
#[pyclass(module = "qicp._qicp")]
struct Matcher {
    kind: String,
    config_toml: String,
    odometry: Mutex<Box<dyn Odometry>>,
}

/// A configuration checked and completed, as the command line's `load_config` leaves it.
fn checked(mut config: MatcherConfig) -> PyResult<MatcherConfig> {
    config.validate().map_err(refusal)?;
    config.fill_defaults();
    Ok(config)
}

/// The `[matcher]` of a TOML file, resolved by the registry, with the command line's messages.
fn config_file(path: &std::path::Path) -> PyResult<MatcherConfig> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| refusal_in(format!("reading {}", path.display()), e))?;
    let config = REGISTRY
        .parse(&text)
        .map_err(|e| refusal_in(format!("in {}", path.display()), e))?;
    checked(config)
}

impl Matcher {
    /// A matcher of a [`checked`] configuration.
    fn from_config(config: MatcherConfig) -> PyResult<Self> {
        let odometry = config.build().map_err(refusal)?;
        Ok(Self {
            kind: config.kind(),
            config_toml: config.to_toml(),
            odometry: Mutex::new(odometry),
        })
    }

    fn run(&self, py: Python<'_>, record: &Record) -> MatchResult {
        let mut odometry = lock(&self.odometry);
        let odometry = &mut **odometry;
        let estimate = py.detach(|| odometry.process(record));
        let result = &estimate.result;
        let matched = result.fallback.is_none();
        MatchResult {
            timestamp: record.timestamp(),
            pose: estimate.pose,
            covariance: result.covariance.into(),
            residual: if matched { result.residual } else { f64::NAN },
            certainty: if matched {
                result.certainty()
            } else {
                f64::NAN
            },
            fallback: result.fallback.map(|f| f.to_string()),
            inserted: estimate.inserted,
            iterations: result.iterations,
            correspondences: result.correspondences,
        }
    }
}

#[pymethods]
impl Matcher {
    /// `Matcher(kind="q-wsm", **sections)`: the matcher the registry names `kind`, with the
    /// TOML sections of `[matcher]` given as dicts, e.g. `icp={"max_dist_start": 0.7}`.
    #[new]
    #[pyo3(signature = (kind = "q-wsm", **sections))]
    fn new(kind: &str, sections: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let Some(sections) = sections.filter(|s| !s.is_empty()) else {
            return Self::from_config(checked(REGISTRY.config(kind).map_err(refusal)?)?);
        };
        let mut matcher = section("matcher", sections)?;
        for (name, value) in &matcher {
            if !value.is_table() {
                return Err(QicpError::new_err(format!(
                    "matcher.{name}: give a section as a dict, e.g. {name}={{\"key\": value}}"
                )));
            }
        }
        matcher.insert("kind".into(), kind.into());
        let mut doc = toml::Table::new();
        doc.insert("matcher".into(), toml::Value::Table(matcher));
        let text = toml::to_string(&doc).map_err(refusal)?;
        Self::from_config(checked(REGISTRY.parse(&text).map_err(refusal)?)?)
    }

    /// The matcher a TOML file describes (`[matcher]`, as `qicp match --config FILE` reads it).
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        Self::from_config(config_file(&path)?)
    }

    /// The registry name of the matcher, e.g. `"q-wsm"`.
    #[getter]
    fn kind(&self) -> &str {
        &self.kind
    }

    /// The whole configuration, every default filled in, as TOML.
    fn config_toml(&self) -> &str {
        &self.config_toml
    }

    /// Matches one scan. `ranges` (m) is read in place when it is a float64 array and
    /// converted otherwise; beam i points at `angle_min + i * angle_increment` (rad) in the
    /// laser frame. Readings at or above `range_max` are no-returns, below `range_min` dropped.
    /// `odometry` is the robot's pose by odometry (x, y, θ) and `laser_offset` the laser's pose
    /// on the robot.
    #[pyo3(signature = (ranges, angle_min, angle_increment, *, odometry, timestamp,
                        range_max = DEFAULT_FLASER_MAX_RANGE, range_min = 0.0,
                        laser_offset = (0.0, 0.0, 0.0)))]
    #[allow(clippy::too_many_arguments)]
    fn process(
        &self,
        py: Python<'_>,
        ranges: PyArrayLike1<'_, f64, AllowTypeChange>,
        angle_min: f64,
        angle_increment: f64,
        odometry: (f64, f64, f64),
        timestamp: f64,
        range_max: f64,
        range_min: f64,
        laser_offset: (f64, f64, f64),
    ) -> PyResult<MatchResult> {
        let geometry = BeamGeometry {
            angle_min,
            angle_increment,
            max_range: range_max,
            min_range: range_min,
        };
        let ranges = ranges.as_array();
        if ranges.len() > DEFAULT_MAX_BEAMS {
            return Err(QicpError::new_err(format!(
                "a scan of {} beams is more than any laser gives (at most {DEFAULT_MAX_BEAMS})",
                ranges.len()
            )));
        }
        // The scan keeps its own copy of the readings; a strided array is gathered into it.
        let scan = Scan::new(timestamp, geometry, ranges.to_vec()).map_err(refusal)?;
        let record = Record {
            scan,
            odometry: pose_of(odometry, "odometry")?,
            truth: None,
            laser_offset: pose_of(laser_offset, "laser_offset")?,
        };
        Ok(self.run(py, &record))
    }

    /// Matches one record of a log (see `read_carmen`), exactly as `qicp match` does.
    fn process_record(&self, py: Python<'_>, record: &LaserRecord) -> MatchResult {
        self.run(py, &record.0)
    }

    /// The points of the reference (the whole map of a boosted matcher) as an N×2 array (m).
    fn map_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let odometry = lock(&self.odometry);
        let points = odometry.reference_points();
        let flat: Vec<f64> = points.iter().flat_map(|p| [p.x, p.y]).collect();
        PyArray1::from_vec(py, flat).reshape([points.len(), 2])
    }

    fn __repr__(&self) -> String {
        format!("Matcher(kind={:?})", self.kind)
    }
}

/// What a matcher says about one scan.
#[pyclass(module = "qicp._qicp", frozen)]
struct MatchResult {
    timestamp: f64,
    pose: Pose2,
    covariance: [[f64; 3]; 3],
    residual: f64,
    certainty: f64,
    fallback: Option<String>,
    inserted: bool,
    iterations: u32,
    correspondences: usize,
}

#[pymethods]
impl MatchResult {
    /// Time of the scan (s).
    #[getter]
    fn timestamp(&self) -> f64 {
        self.timestamp
    }
    /// The robot's pose in the world (x, y, θ), as the command line's trajectory has it.
    #[getter]
    fn pose(&self) -> (f64, f64, f64) {
        pose_tuple(&self.pose)
    }
    /// 3×3 covariance (x, y, θ) of the match, in the reference frame.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        // nalgebra's `into` gives columns; the matrix is symmetric, but keep rows honest.
        let c = self.covariance;
        let rows: Vec<Vec<f64>> = (0..3).map(|i| (0..3).map(|j| c[j][i]).collect()).collect();
        PyArray2::from_vec2(py, &rows).map_err(|e| QicpError::new_err(e.to_string()))
    }
    /// Residual correlation distance (m): mean distance of the final pairs; NaN for a fallback.
    #[getter]
    fn residual(&self) -> f64 {
        self.residual
    }
    /// Matching certainty sqrt(σxx² + σyy²) of the paper (m²); NaN for a fallback.
    #[getter]
    fn certainty(&self) -> f64 {
        self.certainty
    }
    /// Why the pose is odometry's rather than a match's, or None.
    #[getter]
    fn fallback(&self) -> Option<&str> {
        self.fallback.as_deref()
    }
    /// Whether the scan entered the reference.
    #[getter]
    fn inserted(&self) -> bool {
        self.inserted
    }
    /// Iterations the matcher ran.
    #[getter]
    fn iterations(&self) -> u32 {
        self.iterations
    }
    /// Correspondences in the final iteration.
    #[getter]
    fn correspondences(&self) -> usize {
        self.correspondences
    }
    fn __repr__(&self) -> String {
        let p = self.pose;
        format!(
            "MatchResult(timestamp={}, pose=({}, {}, {}), fallback={:?})",
            self.timestamp, p.x, p.y, p.theta, self.fallback
        )
    }
}

/// One laser record of a log: a scan, the robot's odometry and, where the log has it, truth.
#[pyclass(module = "qicp._qicp", name = "Record", frozen)]
struct LaserRecord(Record);

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
struct Log {
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

/// Streams the laser records of a CARMEN log (plain or bzip2), in time order, as `qicp match`
/// reads them: an iterator of `Record`. A malformed line raises `QicpError` naming its line
/// (with `lenient=True` it is skipped and counted); a log without a laser record raises too.
#[pyfunction]
#[pyo3(signature = (path, *, lenient = false, max_beams = DEFAULT_MAX_BEAMS))]
fn read_carmen(path: PathBuf, lenient: bool, max_beams: usize) -> PyResult<Log> {
    let options = CarmenOptions {
        lenient,
        max_beams,
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
/// the /tf transform `odom_frame` -> `base_frame`, interpolated to each scan's stamp. A
/// missing topic raises `QicpError` listing the bag's topics.
#[pyfunction]
#[pyo3(signature = (path, *, scan_topic = "/scan", odom_topic = "/odom", odom_frame = None,
                    base_frame = "base_link", max_beams = DEFAULT_MAX_BEAMS))]
fn read_bag(
    path: PathBuf,
    scan_topic: &str,
    odom_topic: &str,
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
    let odometry = OdometrySource::from_names(odom_topic, odom_frame.as_deref(), base_frame);
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

/// A trajectory given as an N×4 array (or a sequence of (t, x, y, θ)).
fn stamped(name: &str, traj: PyArrayLike2<'_, f64, AllowTypeChange>) -> PyResult<Vec<Stamped>> {
    let a = traj.as_array();
    if a.ncols() != 4 {
        return Err(QicpError::new_err(format!(
            "{name} must have 4 columns (t, x, y, θ), not {}",
            a.ncols()
        )));
    }
    Ok(a.rows()
        .into_iter()
        .map(|r| (r[0], Pose2::new(r[1], r[2], r[3])))
        .collect())
}

fn trajectory_array<'py>(py: Python<'py>, traj: &[Stamped]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = traj
        .iter()
        .flat_map(|(t, p)| [*t, p.x, p.y, p.theta])
        .collect();
    PyArray1::from_vec(py, flat).reshape([traj.len(), 4])
}

fn relations_dict<'py>(py: Python<'py>, r: &RelationsReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("n", r.n)?;
    d.set_item("missing", r.missing)?;
    d.set_item("trans_mean", r.trans_mean)?;
    d.set_item("trans_std", r.trans_std)?;
    d.set_item("trans_max", r.trans_max)?;
    d.set_item("rot_mean_deg", r.rot_mean_deg)?;
    d.set_item("rot_std_deg", r.rot_std_deg)?;
    d.set_item("rot_max_deg", r.rot_max_deg)?;
    Ok(d)
}

fn ate_dict<'py>(py: Python<'py>, r: &AteReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("n", r.n)?;
    d.set_item("missing", r.missing)?;
    d.set_item("ate_rmse_m", r.ate_rmse_m)?;
    d.set_item("ate_mean_m", r.ate_mean_m)?;
    d.set_item("ate_max_m", r.ate_max_m)?;
    d.set_item("final_error_m", r.final_error_m)?;
    d.set_item("final_heading_error_deg", r.final_heading_error_deg)?;
    d.set_item("path_length_m", r.path_length_m)?;
    d.set_item("rpe_segment_m", r.rpe_segment_m)?;
    d.set_item("rpe_segments", r.rpe_segments)?;
    d.set_item("rpe_trans_per_m", r.rpe_trans_per_m)?;
    d.set_item("rpe_rot_deg_per_m", r.rpe_rot_deg_per_m)?;
    Ok(d)
}

/// Scores a trajectory (N×4: t, x, y, θ) with Freiburg benchmark relations, as
/// `qicp eval relations` does; the dict has the keys of its JSON. No relation within reach of
/// the trajectory raises, as the command line fails.
#[pyfunction]
#[pyo3(signature = (trajectory, relations_path, *, max_dt = qicp_eval::DEFAULT_MAX_DT))]
fn evaluate_relations<'py>(
    py: Python<'py>,
    trajectory: PyArrayLike2<'py, f64, AllowTypeChange>,
    relations_path: PathBuf,
    max_dt: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let traj = stamped("trajectory", trajectory)?;
    let relations = qicp_io::relations::read_relations(&relations_path).map_err(refusal)?;
    let report = qicp_eval::evaluate_relations(&traj, &relations, max_dt)
        .map_err(|e| refusal_in("scoring the trajectory".into(), e))?;
    if report.n == 0 {
        return Err(QicpError::new_err(format!(
            "no relation of {} has poses within {max_dt} s in the trajectory ({} relations): is \
             it the trajectory's relations file?",
            relations_path.display(),
            relations.len()
        )));
    }
    relations_dict(py, &report)
}

/// Compares an estimate with ground truth (both N×4: t, x, y, θ) as `qicp eval ate` does:
/// origin-aligned ATE, RPE per metre and final error; the dict has the keys of its JSON.
#[pyfunction]
#[pyo3(signature = (estimate, truth, *, max_dt = qicp_eval::DEFAULT_MAX_DT,
                    rpe_segment_m = qicp_eval::DEFAULT_RPE_SEGMENT_M))]
fn ate<'py>(
    py: Python<'py>,
    estimate: PyArrayLike2<'py, f64, AllowTypeChange>,
    truth: PyArrayLike2<'py, f64, AllowTypeChange>,
    max_dt: f64,
    rpe_segment_m: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let est = stamped("estimate", estimate)?;
    let truth = stamped("truth", truth)?;
    let opts = AteOptions {
        max_dt,
        rpe_segment_m,
    };
    let report = qicp_eval::evaluate_ate(&est, &truth, &opts)
        .map_err(|e| refusal_in("comparing the estimate with the truth".into(), e))?;
    ate_dict(py, &report)
}

/// Reads a TUM trajectory as an N×4 array (t, x, y, θ).
#[pyfunction]
fn read_tum<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let traj = qicp_io::tum::read_tum(&path).map_err(refusal)?;
    trajectory_array(py, &traj)
}

/// Writes a trajectory (N×4: t, x, y, θ) as TUM, number for number as `qicp match` writes
/// its `trajectory.tum`.
#[pyfunction]
fn write_tum(path: PathBuf, trajectory: PyArrayLike2<'_, f64, AllowTypeChange>) -> PyResult<()> {
    let traj = stamped("trajectory", trajectory)?;
    let file = std::fs::File::create(&path)
        .map_err(|e| refusal_in(format!("creating {}", path.display()), e))?;
    qicp_io::tum::write_tum(file, &traj)
        .map_err(|e| refusal_in(format!("writing {}", path.display()), e))
}

/// The matcher a sweep runs: the registry's `matcher`, or the `[matcher]` of a TOML file.
fn sweep_config(matcher: &str, config: Option<PathBuf>) -> PyResult<MatcherConfig> {
    match config {
        None => checked(REGISTRY.config(matcher).map_err(refusal)?),
        Some(path) => config_file(&path),
    }
}

/// An `anyhow` error as the command line prints it on one line.
fn anyhow_refusal(e: &anyhow::Error) -> PyErr {
    QicpError::new_err(format!("{e:#}"))
}

fn sweep_input(
    log: &std::path::Path,
    relations: &std::path::Path,
    scans: Option<usize>,
    lenient: bool,
) -> PyResult<qicp_runner::sweep::SweepInput> {
    let scans = scans.and_then(std::num::NonZeroUsize::new);
    qicp_runner::sweep::SweepInput::load(log, relations, scans, lenient)
        .map_err(|e| anyhow_refusal(&e))
}

/// The variants `qicp sweep` runs for a matcher, in report order (the default run aside).
#[pyfunction]
#[pyo3(signature = (matcher = "q-wsm", *, config = None))]
fn sweep_variants(matcher: &str, config: Option<PathBuf>) -> PyResult<Vec<String>> {
    let config = sweep_config(matcher, config)?;
    Ok(qicp_runner::sweep::all_variants(&config)
        .into_iter()
        .map(|v| v.name)
        .collect())
}

/// One run of `qicp sweep`: `variant` (`"default"` or a name of `sweep_variants`) of the
/// matcher on the log's first `scans` records, scored with the relations. Returns the run's
/// figures (the keys of a variant in `qicp sweep --json`); a run that cannot be made raises
/// `QicpError` with the message the sweep reports. Each call reads the log: one call is one
/// task of a distributed sweep.
#[pyfunction]
#[pyo3(signature = (log, relations, variant = "default", *, matcher = "q-wsm", config = None,
                    scans = None, lenient = false))]
#[allow(clippy::too_many_arguments)]
fn sweep_run<'py>(
    py: Python<'py>,
    log: PathBuf,
    relations: PathBuf,
    variant: &str,
    matcher: &str,
    config: Option<PathBuf>,
    scans: Option<usize>,
    lenient: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let config = sweep_config(matcher, config)?;
    let job = qicp_runner::sweep::Job::named(&config, variant).map_err(|e| anyhow_refusal(&e))?;
    let figures = py.detach(|| -> anyhow::Result<_> {
        let input = qicp_runner::sweep::SweepInput::load(
            &log,
            &relations,
            scans.and_then(std::num::NonZeroUsize::new),
            lenient,
        )?;
        job.run(&input)
    });
    let figures = figures.map_err(|e| anyhow_refusal(&e))?;
    let value = serde_json::to_value(&figures).map_err(refusal)?;
    let d = PyDict::new(py);
    if let serde_json::Value::Object(map) = value {
        for (k, v) in map {
            match v {
                serde_json::Value::Number(n) if n.is_u64() => d.set_item(k, n.as_u64())?,
                serde_json::Value::Number(n) => d.set_item(k, n.as_f64())?,
                _ => d.set_item(k, f64::NAN)?,
            }
        }
    }
    Ok(d)
}

/// The report of `qicp sweep --json` from the runs' results: `results` maps each run's name
/// (`"default"` and the variants, in report order) to its figures (a dict of `sweep_run`) or
/// to the message of its failure. Returns the report's JSON text, as `qicp sweep --json`
/// prints it.
#[pyfunction]
#[pyo3(signature = (log, relations, results, *, matcher = "q-wsm", config = None, scans = None,
                    lenient = false))]
#[allow(clippy::too_many_arguments)]
fn sweep_report(
    py: Python<'_>,
    log: PathBuf,
    relations: PathBuf,
    results: Vec<(String, Bound<'_, PyAny>)>,
    matcher: &str,
    config: Option<PathBuf>,
    scans: Option<usize>,
    lenient: bool,
) -> PyResult<String> {
    use qicp_runner::sweep::{RunFigures, report, variant_report};
    let config = sweep_config(matcher, config)?;
    let input = py.detach(|| sweep_input(&log, &relations, scans, lenient))?;
    let figures = |v: &Bound<'_, PyAny>| -> PyResult<Result<RunFigures, String>> {
        if let Ok(message) = v.extract::<String>() {
            return Ok(Err(message));
        }
        let d = v.cast::<PyDict>()?;
        let get = |k: &str| -> PyResult<Bound<'_, PyAny>> {
            d.get_item(k)?
                .ok_or_else(|| QicpError::new_err(format!("the figures have no `{k}`")))
        };
        Ok(Ok(RunFigures {
            trans_mean: get("trans_mean")?.extract()?,
            trans_max: get("trans_max")?.extract()?,
            rot_mean_deg: get("rot_mean_deg")?.extract()?,
            ms_per_scan_median: get("ms_per_scan_median")?.extract()?,
            map_points: get("map_points")?.extract()?,
            scans: get("scans")?.extract()?,
            relations: get("relations")?.extract()?,
            relations_missing: get("relations_missing")?.extract()?,
            relations_over_0_5_m: get("relations_over_0_5_m")?.extract()?,
        }))
    };
    let mut runs = results.iter();
    let default = match runs.next() {
        Some((name, v)) if name == "default" => match figures(v)? {
            Ok(f) => f,
            Err(e) => return Err(QicpError::new_err(format!("the default run failed: {e}"))),
        },
        _ => {
            return Err(QicpError::new_err(
                "the first result must be the default run",
            ));
        }
    };
    let variants = runs
        .map(|(name, v)| Ok(variant_report(name, figures(v)?, &default)))
        .collect::<PyResult<Vec<_>>>()?;
    let report = report(&input, &config, default, variants);
    serde_json::to_string_pretty(&report).map_err(refusal)
}

/// The names the registry resolves (`qicp matchers` lists them with their parameters).
#[pyfunction]
fn matcher_names<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    PyList::new(py, REGISTRY.names())
}

/// The qicp extension module.
#[pymodule]
fn _qicp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("QicpError", m.py().get_type::<QicpError>())?;
    m.add_class::<Matcher>()?;
    m.add_class::<MatchResult>()?;
    m.add_class::<LaserRecord>()?;
    m.add_class::<Log>()?;
    m.add_function(wrap_pyfunction!(read_carmen, m)?)?;
    m.add_function(wrap_pyfunction!(read_bag, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate_relations, m)?)?;
    m.add_function(wrap_pyfunction!(ate, m)?)?;
    m.add_function(wrap_pyfunction!(read_tum, m)?)?;
    m.add_function(wrap_pyfunction!(write_tum, m)?)?;
    m.add_function(wrap_pyfunction!(matcher_names, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_variants, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_run, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_report, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
