//! Matcher configurations from Python: `[matcher]` sections given as dicts turned into TOML,
//! the `[matcher]` of a TOML file, each checked and completed as the command line does.

use crate::{QicpError, REGISTRY, refusal, refusal_in};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use qicp_matchers::MatcherConfig;

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

pub(crate) fn section(prefix: &str, dict: &Bound<'_, PyDict>) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    for (k, v) in dict.iter() {
        let k: String = k.extract()?;
        let path = format!("{prefix}.{k}");
        table.insert(k, toml_value(&path, &v)?);
    }
    Ok(table)
}

/// A configuration checked and completed, as the command line's `load_config` leaves it.
pub(crate) fn checked(mut config: MatcherConfig) -> PyResult<MatcherConfig> {
    config.validate().map_err(refusal)?;
    config.fill_defaults();
    Ok(config)
}

/// The `[matcher]` of a TOML file, resolved by the registry, with the command line's messages.
pub(crate) fn config_file(path: &std::path::Path) -> PyResult<MatcherConfig> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| refusal_in(format!("reading {}", path.display()), e))?;
    let config = REGISTRY
        .parse(&text)
        .map_err(|e| refusal_in(format!("in {}", path.display()), e))?;
    checked(config)
}
