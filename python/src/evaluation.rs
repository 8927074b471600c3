//! Evaluation and trajectories: scores against Freiburg relations and ground truth (ATE, RPE)
//! as `qicp eval` computes them, and TUM trajectories read and written.

use crate::{QicpError, refusal, refusal_in};
use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArrayLike2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use qicp_core::Pose2;
use qicp_eval::{AteOptions, AteReport, RelationsReport};
use qicp_io::tum::Stamped;
use std::path::PathBuf;

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
pub(crate) fn evaluate_relations<'py>(
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
pub(crate) fn ate<'py>(
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
pub(crate) fn read_tum<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let traj = qicp_io::tum::read_tum(&path).map_err(refusal)?;
    trajectory_array(py, &traj)
}

/// Writes a trajectory (N×4: t, x, y, θ) as TUM, number for number as `qicp match` writes
/// its `trajectory.tum`, and like it to a temporary file renamed into place when complete.
#[pyfunction]
pub(crate) fn write_tum(
    path: PathBuf,
    trajectory: PyArrayLike2<'_, f64, AllowTypeChange>,
) -> PyResult<()> {
    let traj = stamped("trajectory", trajectory)?;
    // A temporary file beside `path`, renamed when complete: a failed write leaves no partial
    // trajectory, and an existing file is replaced whole or not at all.
    let mut file = qicp_runner::output::OutputFile::create(&path)
        .map_err(|e| QicpError::new_err(format!("{e:#}")))?;
    qicp_io::tum::write_tum(&mut file, &traj)
        .map_err(|e| refusal_in(format!("writing {}", path.display()), e))?;
    file.commit()
        .map_err(|e| QicpError::new_err(format!("{e:#}")))
}
