//! Matcher choice and parameters from TOML.
//!
//! ```toml
//! [matcher]
//! kind = "q-wsm"          # a composed name: idc | wsm | q-idc | q-wsm | kd-idc | kd-wsm | …
//! # or the three axes:  algorithm = "wsm", reference = "map" | "scan", index = "quadtree" | "kdtree" | …
//! [matcher.icp]           # iteration (every algorithm)
//! max_iterations = 40
//! [matcher.wsm]           # the chosen algorithm's own section
//! sigma_slide = 0.1
//! [matcher.laser]         # the laser's noise (every algorithm; the reference holds it)
//! sigma_range = 0.01
//! [matcher.relevance]     # which scans enter the reference (paper Alg. 1 thresholds)
//! tau_max = 0.25
//! ```
//! Unknown keys, values out of range and sections of another algorithm are refused with a
//! message naming the key. The names resolve through a [`Registry`].

use crate::correlative::CorrelativeParams;
use crate::icp::IcpParams;
use crate::idc::Idc;
use crate::params::{Param, Range, check_section, parse_section, to_table, typed_section};
use crate::pipeline::{MotionModel, Odometry, Pipeline, Relevance};
use crate::registry::{Assembly, ErasedAlgorithm, IndexEntry, ReferenceEntry, Registry};
use crate::revisit::RevisitParams;
use crate::validation::ValidationParams;
use crate::wsm::Wsm;
use qicp_core::{KdTree, LaserNoise, MutualNearest, QuadTree};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

pub use qicp_core::ConfigError;

/// The six built-in presets: shorthands for an algorithm, a reference and an index (any
/// algorithm registered later composes the same way; see [`Registry::resolve`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "kebab-case")]
pub enum MatcherKind {
    /// IDC, scan-to-scan (against the latest relevant scan, mutual-nearest pairs).
    Idc,
    /// WSM, scan-to-scan (against the latest relevant scan, mutual-nearest pairs).
    Wsm,
    /// IDC against a quad-tree map with mutual-nearest pairs (paper Alg. 1 + 2).
    QIdc,
    /// WSM against a quad-tree map with mutual-nearest pairs (paper Alg. 1 + 2).
    QWsm,
    /// IDC against a kd-tree map.
    KdIdc,
    /// WSM against a kd-tree map.
    KdWsm,
}

impl MatcherKind {
    /// Every kind, in report order.
    pub const ALL: [MatcherKind; 6] = [
        MatcherKind::Idc,
        MatcherKind::QIdc,
        MatcherKind::KdIdc,
        MatcherKind::Wsm,
        MatcherKind::QWsm,
        MatcherKind::KdWsm,
    ];

    /// The registry name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            MatcherKind::Idc => "idc",
            MatcherKind::Wsm => "wsm",
            MatcherKind::QIdc => "q-idc",
            MatcherKind::QWsm => "q-wsm",
            MatcherKind::KdIdc => "kd-idc",
            MatcherKind::KdWsm => "kd-wsm",
        }
    }
}

impl std::fmt::Display for MatcherKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for MatcherKind {
    type Err = ConfigError;
    fn from_str(s: &str) -> Result<Self, ConfigError> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                ConfigError::invalid(
                    "matcher.kind",
                    format!(
                        "unknown kind `{s}`; known: {}",
                        Self::ALL.map(|k| k.name()).join(", ")
                    ),
                )
            })
    }
}

/// The `[matcher]` table, resolved against a [`Registry`]: the algorithm and index it names
/// are held here, so a config builds, prints and scales without the registry.
#[derive(Clone)]
pub struct MatcherConfig {
    pub(crate) algorithm: Arc<dyn ErasedAlgorithm>,
    /// Which scans the matcher is matched against.
    pub reference: ReferenceEntry,
    pub(crate) index: IndexEntry,
    /// Iteration parameters.
    pub icp: IcpParams,
    /// The algorithm's own section `[matcher.<algorithm>]`, effective (defaults filled in).
    section: toml::Table,
    /// Which scans enter the reference.
    pub relevance: Relevance,
    /// How far odometry is trusted (the prior of weighted matchers).
    pub motion: MotionModel,
    /// How a match is checked before it enters the reference.
    pub validation: ValidationParams,
    /// The correlative search that re-matches a suspect scan.
    pub correlative: CorrelativeParams,
    /// The look-ups in the old map that re-anchor a match on a revisit.
    pub revisit: RevisitParams,
    /// The laser's noise (`[matcher.laser]`): one sensor parameter for every algorithm, held
    /// by the reference ([`qicp_core::Reference::noise`]).
    pub laser: LaserNoise,
}

impl std::fmt::Debug for MatcherConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MatcherConfig")
            .field("kind", &self.kind())
            .field("icp", &self.icp)
            .field(self.algorithm.name(), &self.section)
            .field("relevance", &self.relevance)
            .field("motion", &self.motion)
            .field("validation", &self.validation)
            .field("correlative", &self.correlative)
            .field("revisit", &self.revisit)
            .field("laser", &self.laser)
            .finish()
    }
}

impl PartialEq for MatcherConfig {
    fn eq(&self, other: &Self) -> bool {
        self.algorithm.name() == other.algorithm.name()
            && self.reference == other.reference
            && self.index.name() == other.index.name()
            && self.icp == other.icp
            && self.section == other.section
            && self.relevance == other.relevance
            && self.motion == other.motion
            && self.validation == other.validation
            && self.correlative == other.correlative
            && self.revisit == other.revisit
            && self.laser == other.laser
    }
}

/// The sections every algorithm shares, with their keys below `[matcher]`.
const COMMON_SECTIONS: [&str; 7] = [
    "icp",
    "relevance",
    "motion",
    "validation",
    "correlative",
    "revisit",
    "laser",
];

/// The parameters of `[matcher.laser]`, declared once like an algorithm's.
pub const LASER_PARAMETERS: &[Param] = &[
    Param::steering(
        "sigma_range",
        Range::Positive,
        "range noise σr along the beam (m)",
    ),
    Param::new(
        "sigma_bearing",
        Range::Positive,
        "bearing noise σφ across the beam (rad)",
    ),
];

/// Keys of `[matcher.laser]` that configs written before it gave in `[matcher.wsm]`: read
/// there still, with the same meaning.
const LEGACY_LASER_KEYS: [&str; 2] = ["sigma_range", "sigma_bearing"];

/// The `[matcher.laser]` table, with the laser keys an old config gives in the WSM section
/// (`own`, taken out of it) moved in; a key given in both places is refused.
fn laser_section(
    table: &mut toml::Table,
    algorithm: &str,
    own: &mut toml::Table,
) -> Result<LaserNoise, ConfigError> {
    let mut laser = match table.remove("laser") {
        None => toml::Table::new(),
        Some(toml::Value::Table(t)) => t,
        Some(v) => {
            return Err(ConfigError::invalid(
                "matcher.laser",
                format!("must be a table, not {v}"),
            ));
        }
    };
    if algorithm == "wsm" {
        for key in LEGACY_LASER_KEYS {
            if let Some(v) = own.remove(key) {
                // Refused under the name the config gave.
                let number = v.as_float().or(v.as_integer().map(|i| i as f64));
                let param = LASER_PARAMETERS.iter().find(|p| p.key == key);
                if let Some(why) = number.zip(param).and_then(|(x, p)| p.range.refuse(x)) {
                    return Err(ConfigError::invalid(&format!("matcher.wsm.{key}"), why));
                }
                if laser.contains_key(key) {
                    return Err(ConfigError::invalid(
                        &format!("matcher.wsm.{key}"),
                        format!("is the laser's noise: give it once, as matcher.laser.{key}"),
                    ));
                }
                laser.insert(key.into(), v);
            }
        }
    }
    let noise: LaserNoise = parse_section("matcher.laser", &laser, LASER_PARAMETERS)?;
    check_section("matcher.laser", &noise, LASER_PARAMETERS)?;
    Ok(noise)
}

fn section<T: serde::de::DeserializeOwned + Default>(
    table: &mut toml::Table,
    key: &str,
) -> Result<T, ConfigError> {
    match table.remove(key) {
        None => Ok(T::default()),
        Some(toml::Value::Table(t)) => typed_section(&format!("matcher.{key}"), &t),
        Some(v) => Err(ConfigError::invalid(
            &format!("matcher.{key}"),
            format!("must be a table, not {v}"),
        )),
    }
}

fn string_key(table: &mut toml::Table, key: &str) -> Result<Option<String>, ConfigError> {
    match table.remove(key) {
        None => Ok(None),
        Some(toml::Value::String(s)) => Ok(Some(s)),
        Some(v) => Err(ConfigError::invalid(
            &format!("matcher.{key}"),
            format!("must be a string, not {v}"),
        )),
    }
}

impl MatcherConfig {
    /// The defaults of a built-in preset, every section filled in. Presets from other crates:
    /// [`Registry::config`].
    #[must_use]
    pub fn defaults(kind: MatcherKind) -> Self {
        Registry::builtin()
            .config(kind.name())
            .expect("every built-in preset resolves with valid defaults")
    }

    /// Parses the `[matcher]` table of a TOML document against the built-in registry
    /// ([`Registry::parse`] for others) and validates it.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        Registry::builtin().parse(text)
    }

    pub(crate) fn from_axes(
        registry: &Registry,
        algorithm: &str,
        reference: ReferenceEntry,
        index: &str,
    ) -> Result<Self, ConfigError> {
        Self::assemble(
            registry.algorithm(algorithm)?,
            reference,
            registry.index(index)?,
            toml::Table::new(),
            &|name| registry.is_algorithm(name),
        )
    }

    pub(crate) fn parse_with(registry: &Registry, text: &str) -> Result<Self, ConfigError> {
        let mut file: toml::Table =
            toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        let Some(matcher) = file.remove("matcher") else {
            return Err(ConfigError::Parse(match file.keys().next() {
                Some(k) => format!("unknown table `{k}`: the matcher is configured in `[matcher]`"),
                None => "no `[matcher]` table".into(),
            }));
        };
        if let Some(k) = file.keys().next() {
            return Err(ConfigError::Parse(format!(
                "unknown table `{k}`: the matcher is configured in `[matcher]`"
            )));
        }
        let toml::Value::Table(mut table) = matcher else {
            return Err(ConfigError::Parse("`matcher` must be a table".into()));
        };
        let kind = string_key(&mut table, "kind")?;
        let algorithm = string_key(&mut table, "algorithm")?;
        let reference = string_key(&mut table, "reference")?;
        let index = string_key(&mut table, "index")?;
        let (algorithm, reference, index) = match (kind, algorithm) {
            (Some(_), Some(_)) => {
                return Err(ConfigError::invalid(
                    "matcher.kind",
                    "give `kind` (a composed name such as \"q-wsm\") or `algorithm` with \
                     `reference` and `index`, not both",
                ));
            }
            (Some(kind), None) => {
                if reference.is_some() || index.is_some() {
                    return Err(ConfigError::invalid(
                        "matcher.kind",
                        "`kind` names the reference and index already; leave out `reference` and `index`",
                    ));
                }
                let (a, r, i) = registry.resolve(&kind)?;
                (a.to_string(), r, i.to_string())
            }
            (None, Some(a)) => (
                a,
                registry.reference(reference.as_deref().unwrap_or(crate::registry::MAP))?,
                index.unwrap_or_else(|| "quadtree".into()),
            ),
            (None, None) => {
                return Err(ConfigError::invalid(
                    "matcher.kind",
                    format!(
                        "missing: give `kind` (one of {}) or `algorithm`",
                        registry.names().join(", ")
                    ),
                ));
            }
        };
        let algorithm = registry.algorithm(&algorithm)?;
        let index = registry.index(&index)?;
        Self::assemble(algorithm, reference, index, table, &|name| {
            registry.is_algorithm(name)
        })
    }

    /// Builds a config from the keys of `[matcher]` left after the axes; refuses leftovers.
    pub(crate) fn assemble(
        algorithm: Arc<dyn ErasedAlgorithm>,
        reference: ReferenceEntry,
        index: IndexEntry,
        mut table: toml::Table,
        is_algorithm: &dyn Fn(&str) -> bool,
    ) -> Result<Self, ConfigError> {
        let mut own = match table.remove(algorithm.name()) {
            None => toml::Table::new(),
            Some(toml::Value::Table(t)) => t,
            Some(v) => {
                return Err(ConfigError::invalid(
                    &format!("matcher.{}", algorithm.name()),
                    format!("must be a table, not {v}"),
                ));
            }
        };
        let icp = match table.remove("icp") {
            None => algorithm.icp_defaults(),
            Some(toml::Value::Table(given)) => {
                // The algorithm's defaults, overridden key by key.
                let mut merged = to_table(&algorithm.icp_defaults())?;
                merged.extend(given);
                typed_section("matcher.icp", &merged)?
            }
            Some(v) => {
                return Err(ConfigError::invalid(
                    "matcher.icp",
                    format!("must be a table, not {v}"),
                ));
            }
        };
        let laser = laser_section(&mut table, algorithm.name(), &mut own)?;
        let mut c = Self {
            reference,
            icp,
            laser,
            relevance: section(&mut table, "relevance")?,
            motion: section(&mut table, "motion")?,
            validation: section(&mut table, "validation")?,
            correlative: section(&mut table, "correlative")?,
            revisit: section(&mut table, "revisit")?,
            section: algorithm.effective(&own)?,
            algorithm,
            index,
        };
        if let Some(key) = table.keys().next() {
            return Err(if is_algorithm(key) {
                ConfigError::Unused {
                    key: format!("matcher.{key}"),
                    kind: c.kind(),
                }
            } else {
                ConfigError::Parse(format!(
                    "unknown field `{key}` in `[matcher]`; expected kind, algorithm, reference, \
                     index, {}, {}",
                    COMMON_SECTIONS.join(", "),
                    c.algorithm.name()
                ))
            });
        }
        c.validate()?;
        c.fill_defaults();
        Ok(c)
    }

    /// The composed name, e.g. `"q-wsm"` (see [`Registry::compose`]).
    #[must_use]
    pub fn kind(&self) -> String {
        Registry::compose(self.algorithm.name(), &self.reference, &self.index)
    }

    /// The algorithm's registry name, e.g. `"wsm"`.
    #[must_use]
    pub fn algorithm(&self) -> &'static str {
        self.algorithm.name()
    }

    /// The index's registry name, e.g. `"quadtree"`.
    #[must_use]
    pub fn index(&self) -> &'static str {
        self.index.name()
    }

    /// This config with its reference policy set to `reference` (all else kept): the
    /// scan-to-scan twin of a boosted matcher and back.
    #[must_use]
    pub fn with_reference(&self, reference: ReferenceEntry) -> Self {
        let mut c = self.clone();
        c.reference = reference;
        c
    }

    /// The algorithm's parameters as their type, e.g. `config.params::<WsmParams>()`.
    pub fn params<P: serde::de::DeserializeOwned>(&self) -> Result<P, ConfigError> {
        toml::Value::Table(self.section.clone())
            .try_into()
            .map_err(|e: toml::de::Error| ConfigError::Parse(e.to_string()))
    }

    /// Fills every section with defaults where absent: the effective config.
    pub fn fill_defaults(&mut self) {
        if self.relevance.map_resolution.is_none() {
            let resolution = self
                .algorithm
                .map_resolution(&self.section, &self.laser)
                .unwrap_or(0.02);
            self.relevance.map_resolution = Some(resolution);
        }
        if self.relevance.surface_band_sigmas.is_none() {
            let sigmas = self
                .algorithm
                .surface_band_sigmas(&self.section)
                .unwrap_or(1.0);
            self.relevance.surface_band_sigmas = Some(sigmas);
        }
        let resolution = self.relevance.map_resolution.unwrap_or(0.0);
        self.relevance.max_cell_points = Some(self.relevance.cell_cap(resolution));
        if self.relevance.min_novelty.is_none() {
            let share = self.algorithm.min_novelty(&self.section).unwrap_or(0.0);
            self.relevance.min_novelty = Some(share);
        }
    }

    /// Checks every value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.icp.validate()?;
        self.algorithm.effective(&self.section)?;
        self.relevance.validate()?;
        self.motion.validate()?;
        self.validation.validate()?;
        self.correlative.validate()?;
        self.revisit.validate()?;
        check_section("matcher.laser", &self.laser, LASER_PARAMETERS)?;
        Ok(())
    }

    /// The effective `[matcher]` table: the axes (`algorithm`, `reference`, `index`) and every
    /// section, defaults filled in.
    pub fn to_table(&self) -> Result<toml::Table, ConfigError> {
        let mut c = self.clone();
        c.fill_defaults();
        let mut m = toml::Table::new();
        let mut put =
            |key: &str, value: Result<toml::Table, ConfigError>| -> Result<(), ConfigError> {
                m.insert(key.into(), toml::Value::Table(value?));
                Ok(())
            };
        put("icp", to_table(&c.icp))?;
        put(c.algorithm.name(), Ok(c.section.clone()))?;
        put("relevance", to_table(&c.relevance))?;
        put("motion", to_table(&c.motion))?;
        put("validation", to_table(&c.validation))?;
        put("correlative", to_table(&c.correlative))?;
        put("revisit", to_table(&c.revisit))?;
        put("laser", to_table(&c.laser))?;
        m.insert("algorithm".into(), c.algorithm.name().into());
        m.insert("reference".into(), c.reference.name().into());
        m.insert("index".into(), c.index.name().into());
        Ok(m)
    }

    /// The effective config as TOML (every section, defaults filled in), with the composed
    /// name in a comment.
    #[must_use]
    pub fn to_toml(&self) -> String {
        let Ok(m) = self.to_table() else {
            return String::new();
        };
        let mut file = toml::Table::new();
        file.insert("matcher".into(), toml::Value::Table(m));
        format!(
            "# kind = \"{}\"\n{}",
            self.kind(),
            toml::to_string_pretty(&file).unwrap_or_default()
        )
    }

    /// Builds the pipeline this config describes.
    pub fn build(&self) -> Result<Box<dyn Odometry>, ConfigError> {
        self.validate()?;
        let mut c = self.clone();
        c.fill_defaults();
        let kind = c.kind();
        let policy = c.reference.policy(&c.relevance);
        c.algorithm.build(
            &c.section,
            Assembly {
                kind,
                icp: c.icp,
                policy,
                motion: c.motion,
                validation: c.validation,
                correlative: c.correlative,
                revisit: c.revisit,
                laser: c.laser,
                index: &c.index,
            },
        )
    }
}

/// Q-IDC: IDC against a quad-tree map, mutual-nearest pairs (paper Alg. 1 + 2).
pub type QIdc = Pipeline<Idc<MutualNearest<QuadTree>>, QuadTree>;
/// Q-WSM: WSM against a quad-tree map, mutual-nearest pairs (paper Alg. 1 + 2).
pub type QWsm = Pipeline<Wsm<MutualNearest<QuadTree>>, QuadTree>;
/// KD-IDC: IDC against a kd-tree map.
pub type KdIdc = Pipeline<Idc<MutualNearest<KdTree>>, KdTree>;
/// KD-WSM: WSM against a kd-tree map.
pub type KdWsm = Pipeline<Wsm<MutualNearest<KdTree>>, KdTree>;
