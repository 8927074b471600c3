//! Python bindings of qicp (the `qicp._qicp` extension module of the `qicp` package).
//!
//! The matchers are the command line's: a [`Matcher`] is built from the registry of the `qicp`
//! command (the built-in algorithms and PL-ICP) and runs the same pipeline, so a log fed
//! through it gives the trajectory `qicp match` writes, to the last bit. Errors raise
//! `qicp.QicpError` with the message the command line prints; the GIL is released while a
//! scan is matched or a log line parsed.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use qicp_core::Pose2;
use qicp_matchers::Registry;
use std::sync::{LazyLock, Mutex, MutexGuard};

mod config;
mod evaluation;
mod logs;
mod matcher;
mod sweep;

use evaluation::{ate, evaluate_relations, read_tum, write_tum};
use logs::{LaserRecord, Log, read_bag, read_carmen};
use matcher::{Amendment, MatchResult, Matcher, matcher_names};
use sweep::{reference_relations, sweep_relations, sweep_report, sweep_run, sweep_variants};

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

/// The qicp extension module.
#[pymodule]
fn _qicp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("QicpError", m.py().get_type::<QicpError>())?;
    m.add_class::<Matcher>()?;
    m.add_class::<MatchResult>()?;
    m.add_class::<Amendment>()?;
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
    m.add_function(wrap_pyfunction!(sweep_relations, m)?)?;
    m.add_function(wrap_pyfunction!(reference_relations, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_report, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
