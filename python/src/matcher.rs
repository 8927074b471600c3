//! The matcher ([`Matcher`]: a laser-odometry pipeline of the registry), what it says about
//! a scan ([`MatchResult`]) and the names the registry resolves.

use crate::config::{checked, config_file, section};
use crate::logs::LaserRecord;
use crate::{QicpError, REGISTRY, lock, pose_of, pose_tuple, refusal};
use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArrayLike1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use qicp_io::carmen::{DEFAULT_FLASER_MAX_RANGE, DEFAULT_MAX_BEAMS};
use qicp_matchers::{MatcherConfig, Odometry};
use std::path::PathBuf;
use std::sync::Mutex;

/// A laser-odometry pipeline: feed it scans in time order, get the robot's pose in the world.
#[pyclass(module = "qicp._qicp")]
pub(crate) struct Matcher {
    kind: String,
    config_toml: String,
    odometry: Mutex<Box<dyn Odometry>>,
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
        let amendment = odometry.take_amendment().map(Amendment);
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
            amendment,
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
    /// `odometry` is the robot's pose by odometry (x, y, θ), the same pose every time where
    /// there is none (each scan is then predicted at the last checked velocity;
    /// `[matcher.motion] stall_velocity`), and `laser_offset` the laser's pose on the robot.
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

    /// The points of the reference (the whole map of a boosted matcher) as an N×2 array (m),
    /// without those a full cell replaced.
    fn map_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let odometry = lock(&self.odometry);
        let points = odometry.live_points();
        let flat: Vec<f64> = points.iter().flat_map(|p| [p.x, p.y]).collect();
        PyArray1::from_vec(py, flat).reshape([points.len(), 2])
    }

    fn __repr__(&self) -> String {
        format!("Matcher(kind={:?})", self.kind)
    }
}

/// What a matcher says about one scan.
#[pyclass(module = "qicp._qicp", frozen)]
pub(crate) struct MatchResult {
    timestamp: f64,
    pose: Pose2,
    covariance: [[f64; 3]; 3],
    residual: f64,
    certainty: f64,
    fallback: Option<String>,
    inserted: bool,
    iterations: u32,
    correspondences: usize,
    amendment: Option<Amendment>,
}

#[pymethods]
impl MatchResult {
    /// Time of the scan (s).
    #[getter]
    fn timestamp(&self) -> f64 {
        self.timestamp
    }
    /// A correction of earlier scans' poses that this scan's re-anchoring spread over the
    /// stretch that drifted (`[matcher.revisit] deform`), or None: the command line's
    /// trajectory holds the poses so corrected.
    #[getter]
    fn amendment(&self) -> Option<Amendment> {
        self.amendment.clone()
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

/// The names the registry resolves (`qicp matchers` lists them with their parameters).
#[pyfunction]
pub(crate) fn matcher_names<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    PyList::new(py, REGISTRY.names())
}

/// A correction of earlier scans' poses (`MatchResult.amendment`): the pose of the scan
/// numbered `first + k` (counted from the matcher's first scan, 0) moves by `shares[k]` of
/// `correction`, applied in the world (on the left).
#[pyclass(module = "qicp._qicp", frozen)]
#[derive(Clone)]
pub(crate) struct Amendment(qicp_matchers::trail::Amendment);

#[pymethods]
impl Amendment {
    /// The number of the first scan it moves (counted from the matcher's first, 0).
    #[getter]
    fn first(&self) -> usize {
        self.0.first
    }
    /// The whole correction (x, y, θ) in the world, which the re-anchored scan took.
    #[getter]
    fn correction(&self) -> (f64, f64, f64) {
        pose_tuple(&self.0.correction)
    }
    /// Per scan from `first` on, the share of the correction it takes (0 to 1).
    #[getter]
    fn shares<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.0.shares)
    }
    /// `pose` (x, y, θ) of scan number `scan` moved as this amendment moves that scan.
    fn moved(&self, scan: usize, pose: (f64, f64, f64)) -> PyResult<(f64, f64, f64)> {
        let p = pose_of(pose, "pose")?;
        Ok(pose_tuple(&self.0.moved(scan).map_or(p, |by| by * p)))
    }
    /// Moves, in place, the poses of `trajectory`, a list whose item i is scan i's pose
    /// (x, y, θ) or a tuple ending in it (t, x, y, θ).
    fn apply(&self, trajectory: &Bound<'_, PyList>) -> PyResult<()> {
        for scan in self.0.records().take_while(|&k| k < trajectory.len()) {
            let item = trajectory.get_item(scan)?;
            let values: Vec<f64> = item.extract()?;
            let Some(split) = values.len().checked_sub(3) else {
                return Err(QicpError::new_err(format!(
                    "trajectory[{scan}] holds {} numbers: a pose is (x, y, θ)",
                    values.len()
                )));
            };
            let (x, y, theta) = (values[split], values[split + 1], values[split + 2]);
            let moved = self.moved(scan, (x, y, theta))?;
            let mut out = values[..split].to_vec();
            out.extend([moved.0, moved.1, moved.2]);
            trajectory.set_item(scan, pyo3::types::PyTuple::new(trajectory.py(), out)?)?;
        }
        Ok(())
    }
    fn __repr__(&self) -> String {
        let c = &self.0.correction;
        format!(
            "Amendment(first={}, scans={}, correction=({:.4}, {:.4}, {:.5}))",
            self.0.first,
            self.0.shares.len(),
            c.x,
            c.y,
            c.theta
        )
    }
}
