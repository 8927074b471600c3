//! The sweep of `qicp sweep`, one run at a time: its variants, one run's figures and the
//! report of the runs' results (a distributed sweep's tasks).

use crate::config::{checked, config_file};
use crate::{QicpError, REGISTRY, refusal};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use qicp_matchers::MatcherConfig;
use std::path::PathBuf;

/// The matcher a sweep runs: the registry's `matcher`, or the `[matcher]` of a TOML file.
fn sweep_config(matcher: &str, config: Option<PathBuf>) -> PyResult<MatcherConfig> {
    match config {
        None => checked(REGISTRY.config(matcher).map_err(refusal)?),
        Some(path) => config_file(&path),
    }
}

/// The run `variant` (`"default"` or a variant's name) of the matcher a sweep runs.
fn sweep_job(
    matcher: &str,
    config: Option<PathBuf>,
    variant: &str,
) -> PyResult<qicp_runner::sweep::Job> {
    let config = sweep_config(matcher, config)?;
    qicp_runner::sweep::Job::named(&config, variant).map_err(|e| anyhow_refusal(&e))
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
pub(crate) fn sweep_variants(matcher: &str, config: Option<PathBuf>) -> PyResult<Vec<String>> {
    let config = sweep_config(matcher, config)?;
    Ok(qicp_runner::sweep::all_variants(&config)
        .into_iter()
        .map(|v| v.name)
        .collect())
}

/// The figures of a run as a dict (the keys of a variant in `qicp sweep --json`).
fn figures_dict<'py>(
    py: Python<'py>,
    figures: &qicp_runner::sweep::RunFigures,
) -> PyResult<Bound<'py, PyDict>> {
    let value = serde_json::to_value(figures).map_err(refusal)?;
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
    // Each relation's error (None where the run has none): `sweep_report` compares a variant
    // that scored fewer relations with the default on the same ones.
    d.set_item("relation_errors", figures.relation_errors.clone())?;
    Ok(d)
}

/// Writes to `out` the relations `draw` makes from the log (read with `lenient`), renamed into
/// place when complete: the file is checked (and its temporary made) before the log is read.
/// Returns what `draw` returns beside them.
fn write_drawn_relations<T>(
    out: &std::path::Path,
    lenient: bool,
    draw: impl FnOnce(
        qicp_io::carmen::CarmenOptions,
    ) -> anyhow::Result<(T, Vec<qicp_io::relations::Relation>)>,
) -> anyhow::Result<T> {
    let mut file = qicp_runner::output::OutputFile::create(out)?;
    let carmen = qicp_io::carmen::CarmenOptions {
        lenient,
        ..Default::default()
    };
    let (value, relations) = draw(carmen)?;
    qicp_io::relations::write_relations(&mut file, &relations)
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", out.display()))?;
    file.commit()?;
    Ok(value)
}

/// The default run of a sweep on a log without relations, as `qicp sweep LOG` (no
/// `--relations`) makes it: the matcher as configured on the log's first `scans` records, and
/// the relations drawn along its trajectory (a segment per metre driven or 30° turned, on the
/// records every variant keeps, and its revisits of a place), written to `out` in the
/// Freiburg format, renamed into place when complete. Returns the default's figures (scored
/// against them: no error). The variants are then `sweep_run(log, out, name)` and the report
/// `sweep_report(log, out, results, against_default=True)`.
#[pyfunction]
#[pyo3(signature = (log, out, *, matcher = "q-wsm", config = None, scans = None,
                    lenient = false))]
pub(crate) fn sweep_relations<'py>(
    py: Python<'py>,
    log: PathBuf,
    out: PathBuf,
    matcher: &str,
    config: Option<PathBuf>,
    scans: Option<usize>,
    lenient: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let job = sweep_job(matcher, config, "default")?;
    let figures = py.detach(|| {
        write_drawn_relations(&out, lenient, |carmen| {
            let input = qicp_runner::sweep::SweepInput::against_default(
                &log,
                scans.and_then(std::num::NonZeroUsize::new),
                carmen,
            )?;
            let (default, relations) = qicp_runner::sweep::default_relations(&input, &job)?;
            let default = default.map_err(|e| anyhow::anyhow!("the default run failed: {e}"))?;
            Ok((default, relations))
        })
    });
    figures_dict(py, &figures.map_err(|e| anyhow_refusal(&e))?)
}

/// The relations of a sweep scored against a reference trajectory of the log (TUM), as
/// `qicp sweep LOG --reference TUM` draws them: a segment per metre driven or 30° turned, and
/// its revisits of a place, along the reference's poses nearest the records every variant
/// keeps among the log's first `scans`.
/// Writes them to `out` in the Freiburg format, renamed into place when complete, and returns
/// how many there are. Every run, the default's too, is then `sweep_run(log, out, name)` and
/// the report `sweep_report(log, out, results, reference=reference)`.
#[pyfunction]
#[pyo3(signature = (log, reference, out, *, scans = None, lenient = false))]
pub(crate) fn reference_relations(
    py: Python<'_>,
    log: PathBuf,
    reference: PathBuf,
    out: PathBuf,
    scans: Option<usize>,
    lenient: bool,
) -> PyResult<usize> {
    py.detach(|| {
        write_drawn_relations(&out, lenient, |carmen| {
            let input = qicp_runner::sweep::SweepInput::against_trajectory(
                &log,
                &reference,
                scans.and_then(std::num::NonZeroUsize::new),
                carmen,
            )?;
            Ok((input.relations.len(), input.relations))
        })
    })
    .map_err(|e| anyhow_refusal(&e))
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
pub(crate) fn sweep_run<'py>(
    py: Python<'py>,
    log: PathBuf,
    relations: PathBuf,
    variant: &str,
    matcher: &str,
    config: Option<PathBuf>,
    scans: Option<usize>,
    lenient: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let job = sweep_job(matcher, config, variant)?;
    let figures = py.detach(|| -> anyhow::Result<_> {
        let input = qicp_runner::sweep::SweepInput::load(
            &log,
            &relations,
            scans.and_then(std::num::NonZeroUsize::new),
            lenient,
        )?;
        job.run(&input)
    });
    figures_dict(py, &figures.map_err(|e| anyhow_refusal(&e))?)
}

/// The report of `qicp sweep --json` from the runs' results: `results` maps each run's name
/// (`"default"` and the variants, in report order) to its figures (a dict of `sweep_run`) or
/// to the message of its failure. Returns the report's JSON text, as `qicp sweep --json`
/// prints it. With `against_default`, `relations` are those `sweep_relations` drew along the
/// default run, and the report is that of `qicp sweep` without `--relations` (no ratios).
/// With `reference` (the TUM trajectory `reference_relations` drew `relations` along), it is
/// that of `qicp sweep --reference`.
#[pyfunction]
#[pyo3(signature = (log, relations, results, *, matcher = "q-wsm", config = None, scans = None,
                    lenient = false, against_default = false, reference = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sweep_report(
    py: Python<'_>,
    log: PathBuf,
    relations: PathBuf,
    results: Vec<(String, Bound<'_, PyAny>)>,
    matcher: &str,
    config: Option<PathBuf>,
    scans: Option<usize>,
    lenient: bool,
    against_default: bool,
    reference: Option<PathBuf>,
) -> PyResult<String> {
    use qicp_runner::sweep::{RunFigures, report, variant_report};
    if against_default && reference.is_some() {
        return Err(QicpError::new_err(
            "a sweep is scored against the default run or against a reference, not both",
        ));
    }
    let config = sweep_config(matcher, config)?;
    let mut input = py.detach(|| sweep_input(&log, &relations, scans, lenient))?;
    input.against_default = against_default;
    input.reference = reference.map(|r| r.display().to_string());
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
            // Optional: figures from before it was passed on compare with the whole default.
            relation_errors: match d.get_item("relation_errors")? {
                Some(v) => v.extract()?,
                None => Vec::new(),
            },
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
