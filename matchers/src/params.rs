//! Parameters declared once: each registered algorithm lists its parameters with their range
//! and documentation ([`Param`]); the registry checks any section against that list
//! generically (unknown keys, wrong types, values out of range), so a matcher from another
//! crate gets the same checks and messages as the built-in ones. Defaults live in the
//! parameter type's `Default` implementation and nowhere else.

use crate::ConfigError;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// The values a parameter may take.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Range {
    /// Finite and > 0.
    Positive,
    /// Finite and ≥ 0.
    NonNegative,
    /// Within `[lo, hi]`.
    Closed(f64, f64),
    /// Within `(lo, hi)`.
    Open(f64, f64),
    /// An integer within `lo..=hi`.
    Count(i64, i64),
    /// `true` or `false`.
    Flag,
}

impl Range {
    /// Why `v` is out of this range, if it is.
    #[must_use]
    pub fn refuse(&self, v: f64) -> Option<String> {
        let ok = match *self {
            Range::Positive => v.is_finite() && v > 0.0,
            Range::NonNegative => v.is_finite() && v >= 0.0,
            Range::Closed(lo, hi) => v.is_finite() && (lo..=hi).contains(&v),
            Range::Open(lo, hi) => v.is_finite() && lo < v && v < hi,
            Range::Count(lo, hi) => v.fract() == 0.0 && (lo as f64..=hi as f64).contains(&v),
            Range::Flag => true,
        };
        (!ok).then(|| format!("{v} {}", self.describe()))
    }

    /// The range in words, e.g. `"must be finite and > 0"`.
    #[must_use]
    pub fn describe(&self) -> String {
        match *self {
            Range::Positive => "must be finite and > 0".into(),
            Range::NonNegative => "must be finite and ≥ 0".into(),
            Range::Closed(lo, hi) => format!("must be in [{lo}, {hi}]"),
            Range::Open(lo, hi) => format!("must be in ({lo}, {hi})"),
            Range::Count(lo, hi) => format!("must lie in {lo}..={hi}"),
            Range::Flag => "true or false".into(),
        }
    }
}

/// The references a steering parameter acts on, so that a robustness sweep perturbs it only
/// where it changes something.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acts {
    /// Every reference.
    Any,
    /// Only a map (what enters it, how dense it grows, how it is matched).
    Map,
    /// Only a scan as reference.
    Scan,
}

impl Acts {
    /// True when a parameter that acts here changes a matcher whose reference is a map
    /// (`map`) or a scan.
    #[must_use]
    pub fn on(self, map: bool) -> bool {
        match self {
            Acts::Any => true,
            Acts::Map => map,
            Acts::Scan => !map,
        }
    }
}

/// One declared parameter of an algorithm's section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Param {
    /// Key within the section, e.g. `"sigma_range"`.
    pub key: &'static str,
    /// What it does, with its unit.
    pub doc: &'static str,
    /// The values it may take.
    pub range: Range,
    /// Whether it steers matching or map building: the robustness sweep (`qicp sweep`)
    /// multiplies each steering parameter by 0.7 and 1.4.
    pub steering: bool,
    /// The references it acts on ([`Acts::Any`] unless declared with [`Param::acting_on`]).
    pub acts: Acts,
}

impl Param {
    /// A parameter that does not steer (see [`Param::steering`]).
    #[must_use]
    pub const fn new(key: &'static str, range: Range, doc: &'static str) -> Self {
        Self {
            key,
            doc,
            range,
            steering: false,
            acts: Acts::Any,
        }
    }

    /// A parameter the robustness sweep perturbs.
    #[must_use]
    pub const fn steering(key: &'static str, range: Range, doc: &'static str) -> Self {
        Self {
            key,
            doc,
            range,
            steering: true,
            acts: Acts::Any,
        }
    }

    /// This parameter, acting only on the references `acts` names.
    #[must_use]
    pub const fn acting_on(self, acts: Acts) -> Self {
        Self { acts, ..self }
    }
}

/// Parses the TOML section `[<section>]` into `P` and checks it against `declared`: a key that
/// is not declared, a value of the wrong type or out of its range is refused, naming the
/// dotted key. Keys left out take `P::default()`'s values.
pub fn parse_section<P>(
    section: &str,
    table: &toml::Table,
    declared: &[Param],
) -> Result<P, ConfigError>
where
    P: DeserializeOwned,
{
    for key in table.keys() {
        if !declared.iter().any(|p| p.key == key) {
            return Err(ConfigError::invalid(
                &format!("{section}.{key}"),
                format!(
                    "unknown parameter; `{section}` has: {}",
                    declared
                        .iter()
                        .map(|p| p.key)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
    }
    typed_section(section, table)
}

/// Deserialises `table` as `P` (a struct whose missing fields take their defaults); a value
/// of the wrong type or out of its type's range is named by its dotted key
/// `<section>.<key>`: on a failure each key is tried alone, and the first that fails alone is
/// the one named.
pub fn typed_section<P: DeserializeOwned>(
    section: &str,
    table: &toml::Table,
) -> Result<P, ConfigError> {
    let parse = |t: toml::Table| -> Result<P, String> {
        toml::Value::Table(t)
            .try_into()
            .map_err(|e: toml::de::Error| e.message().trim().to_string())
    };
    parse(table.clone()).map_err(|whole| {
        table
            .iter()
            .find_map(|(key, value)| {
                let alone = toml::Table::from_iter([(key.clone(), value.clone())]);
                parse(alone)
                    .err()
                    .map(|why| ConfigError::invalid(&format!("{section}.{key}"), why))
            })
            .unwrap_or_else(|| ConfigError::invalid(section, whole))
    })
}

/// Checks every declared parameter of `params` against its range; the error names the
/// dotted key `<section>.<key>`. Also refuses a field of `P` that is not declared, so that a
/// parameter cannot escape the checks by being left out of the list.
pub fn check_section<P: Serialize>(
    section: &str,
    params: &P,
    declared: &[Param],
) -> Result<(), ConfigError> {
    let table = to_table(params)?;
    for (key, value) in &table {
        let key_path = format!("{section}.{key}");
        let Some(param) = declared.iter().find(|p| p.key == key) else {
            return Err(ConfigError::invalid(
                &key_path,
                "is not declared by its algorithm",
            ));
        };
        let number = match value {
            toml::Value::Float(v) => *v,
            toml::Value::Integer(v) => *v as f64,
            toml::Value::Boolean(_) if param.range == Range::Flag => continue,
            _ => return Err(ConfigError::invalid(&key_path, param.range.describe())),
        };
        if let Some(why) = param.range.refuse(number) {
            return Err(ConfigError::invalid(&key_path, why));
        }
    }
    Ok(())
}

/// `params` as a TOML table.
pub fn to_table<P: Serialize>(params: &P) -> Result<toml::Table, ConfigError> {
    match toml::Value::try_from(params) {
        Ok(toml::Value::Table(t)) => Ok(t),
        Ok(_) => Err(ConfigError::Parse(
            "parameters must serialise as a table".into(),
        )),
        Err(e) => Err(ConfigError::Parse(e.to_string())),
    }
}
