//! Matcher choice and parameters from TOML, and the registry that builds them.
//!
//! ```toml
//! [matcher]
//! kind = "q-wsm"          # idc | wsm | q-idc | q-wsm | kd-idc | kd-wsm
//! [matcher.icp]           # iteration (all kinds)
//! max_iterations = 40
//! [matcher.wsm]           # wsm kinds only
//! sigma_range = 0.01
//! [matcher.relevance]     # which scans enter the reference (paper Alg. 1 thresholds)
//! tau_max = 0.25
//! ```
//! Unknown keys, values out of range and sections the chosen kind does not use are refused
//! with a message naming the key.

use crate::correlative::CorrelativeParams;
use crate::icp::IcpParams;
use crate::idc::{Idc, IdcParams};
use crate::pipeline::{MotionModel, Odometry, Pipeline, Policy, Relevance};
use crate::validation::ValidationParams;
use crate::wsm::{Wsm, WsmParams};
use qicp_core::{KdTree, MutualNearest, QuadTree};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A configuration that cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ConfigError {
    /// The TOML does not parse or does not fit the schema (unknown key, wrong type…).
    #[error("{0}")]
    Parse(String),
    /// A value is out of range.
    #[error("`{key}`: {why}")]
    Invalid {
        /// Dotted path of the key.
        key: String,
        /// What is wrong.
        why: String,
    },
    /// A section the chosen kind does not use.
    #[error("`{key}` is not used by matcher kind `{kind}`")]
    Unused {
        /// Dotted path of the section.
        key: String,
        /// The chosen kind.
        kind: String,
    },
}

impl ConfigError {
    pub(crate) fn invalid(key: &str, why: impl Into<String>) -> Self {
        Self::Invalid {
            key: key.into(),
            why: why.into(),
        }
    }
}

/// The registered matcher kinds.
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

    /// True for the IDC family.
    #[must_use]
    pub fn is_idc(self) -> bool {
        matches!(
            self,
            MatcherKind::Idc | MatcherKind::QIdc | MatcherKind::KdIdc
        )
    }

    /// True for the kinds that match against a map.
    #[must_use]
    pub fn is_boosted(self) -> bool {
        !matches!(self, MatcherKind::Idc | MatcherKind::Wsm)
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

/// The `[matcher]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MatcherConfig {
    /// Which matcher.
    pub kind: MatcherKind,
    /// Iteration parameters.
    #[serde(default)]
    pub icp: IcpParams,
    /// IDC parameters (IDC kinds only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub idc: Option<IdcParams>,
    /// WSM parameters (WSM kinds only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wsm: Option<WsmParams>,
    /// Which scans enter the reference.
    #[serde(default)]
    pub relevance: Relevance,
    /// How far odometry is trusted (the prior of weighted matchers).
    #[serde(default)]
    pub motion: MotionModel,
    /// How a match is checked before it enters the reference.
    #[serde(default)]
    pub validation: ValidationParams,
    /// The correlative search that re-matches a suspect scan.
    #[serde(default)]
    pub correlative: CorrelativeParams,
}

impl MatcherConfig {
    /// The defaults of `kind`, every section it uses filled in.
    #[must_use]
    pub fn defaults(kind: MatcherKind) -> Self {
        let mut c = Self {
            kind,
            icp: IcpParams::default(),
            idc: None,
            wsm: None,
            relevance: Relevance::default(),
            motion: MotionModel::default(),
            validation: ValidationParams::default(),
            correlative: CorrelativeParams::default(),
        };
        c.fill_defaults();
        c
    }

    /// Parses the `[matcher]` table of a TOML document and validates it.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct File {
            matcher: MatcherConfig,
        }
        let file: File = toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        let mut c = file.matcher;
        c.validate()?;
        c.fill_defaults();
        Ok(c)
    }

    /// Fills every section the kind uses with defaults where absent: the effective config.
    pub fn fill_defaults(&mut self) {
        // WSM: the laser's range noise, below which a new point adds no geometry.
        let resolution = if self.kind.is_idc() {
            0.02
        } else {
            self.wsm
                .map_or(WsmParams::default().sigma_range, |w| w.sigma_range)
        };
        self.relevance.map_resolution.get_or_insert(resolution);
        if self.kind.is_idc() {
            self.idc.get_or_insert_with(IdcParams::default);
        } else {
            self.wsm.get_or_insert_with(WsmParams::default);
        }
    }

    /// Checks values and refuses sections the kind does not use.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let unused = |key: &str| ConfigError::Unused {
            key: key.into(),
            kind: self.kind.name().into(),
        };
        self.icp.validate()?;
        match (self.kind.is_idc(), &self.idc, &self.wsm) {
            (true, _, Some(_)) => return Err(unused("matcher.wsm")),
            (false, Some(_), _) => return Err(unused("matcher.idc")),
            _ => {}
        }
        if let Some(p) = &self.idc {
            p.validate()?;
        }
        if let Some(p) = &self.wsm {
            p.validate()?;
        }
        self.relevance.validate()?;
        self.motion.validate()?;
        self.validation.validate()?;
        self.correlative.validate()?;
        Ok(())
    }

    /// The effective config as TOML (every used section, defaults filled in).
    #[must_use]
    pub fn to_toml(&self) -> String {
        #[derive(Serialize)]
        struct File<'a> {
            matcher: &'a MatcherConfig,
        }
        let mut c = self.clone();
        c.fill_defaults();
        toml::to_string_pretty(&File { matcher: &c }).unwrap_or_default()
    }

    /// Builds the pipeline this config describes.
    pub fn build(&self) -> Result<Box<dyn Odometry>, ConfigError> {
        self.validate()?;
        let mut c = self.clone();
        c.fill_defaults();
        let icp = c.icp;
        let idc = c.idc.unwrap_or_default();
        let wsm = c.wsm.unwrap_or_default();
        let boosted = Policy::Boosted(c.relevance);
        let incremental = Policy::Incremental(c.relevance);
        let noise = wsm.noise();
        let name = c.kind.name();
        // What goes around the matcher: the odometry prior and the checks before insertion.
        let around = (c.motion, c.validation, c.correlative);
        // One line per kind: the matcher, its reference index and its policy.
        fn boxed<M, I>(
            p: Pipeline<M, I>,
            (motion, validation, correlative): (MotionModel, ValidationParams, CorrelativeParams),
        ) -> Box<dyn Odometry>
        where
            Pipeline<M, I>: Odometry + 'static,
            M: qicp_core::ScanMatcher,
            I: qicp_core::SpatialIndex,
        {
            Box::new(
                p.with_motion_model(motion)
                    .with_validation(validation, correlative),
            )
        }
        Ok(match c.kind {
            MatcherKind::Idc => {
                let m = Idc::<MutualNearest<QuadTree>>::new(icp, idc);
                boxed(
                    Pipeline::new(name, m, QuadTree::default(), incremental, noise),
                    around,
                )
            }
            MatcherKind::Wsm => {
                let m = Wsm::<MutualNearest<QuadTree>>::new(icp, wsm);
                boxed(
                    Pipeline::new(name, m, QuadTree::default(), incremental, noise),
                    around,
                )
            }
            MatcherKind::QIdc => boxed(
                QIdc::new(
                    name,
                    Idc::new(icp, idc),
                    QuadTree::default(),
                    boosted,
                    noise,
                ),
                around,
            ),
            MatcherKind::QWsm => boxed(
                QWsm::new(
                    name,
                    Wsm::new(icp, wsm),
                    QuadTree::default(),
                    boosted,
                    noise,
                ),
                around,
            ),
            MatcherKind::KdIdc => boxed(
                KdIdc::new(name, Idc::new(icp, idc), KdTree::default(), boosted, noise),
                around,
            ),
            MatcherKind::KdWsm => boxed(
                KdWsm::new(name, Wsm::new(icp, wsm), KdTree::default(), boosted, noise),
                around,
            ),
        })
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

/// The numeric parameters that steer matching and map building, by kind family: the ones a
/// robustness sweep perturbs (`qicp sweep`). Keys are dotted paths below `[matcher]`.
const STEERING_COMMON: &[&str] = &[
    "icp.max_dist_start",
    "icp.max_dist_end",
    "relevance.tau_max",
    "relevance.rho_max_deg",
    "relevance.map_resolution",
    "relevance.min_novelty",
    "relevance.novelty_distance",
    "motion.sigma_xy_per_m",
    "motion.sigma_theta_per_m_deg",
    "validation.inlier_distance",
    "validation.max_share_drop",
    "validation.max_residual_ratio",
    "correlative.window_xy",
    "correlative.window_deg",
];
const STEERING_WSM: &[&str] = &["wsm.sigma_range", "wsm.sigma_slide"];
const STEERING_IDC: &[&str] = &[
    "idc.window_start_deg",
    "idc.window_sigmas",
    "idc.gate_sigmas",
];

impl MatcherConfig {
    /// The numeric parameters that steer this kind's matching and map building (correspondence
    /// distances, relevance thresholds, the map's density bound, the noise and motion models),
    /// as dotted keys such as `"matcher.icp.max_dist_start"`. Parameters whose value is 0 are
    /// left out: scaling them changes nothing.
    #[must_use]
    pub fn steering_parameters(&self) -> Vec<String> {
        let family = if self.kind.is_idc() {
            STEERING_IDC
        } else {
            STEERING_WSM
        };
        let Ok(value) = self.effective_value() else {
            return Vec::new();
        };
        STEERING_COMMON
            .iter()
            .chain(family)
            .map(|k| format!("matcher.{k}"))
            .filter(|k| lookup(&value, k).is_some_and(|v| v != 0.0))
            .collect()
    }

    fn effective_value(&self) -> Result<toml::Value, ConfigError> {
        let mut c = self.clone();
        c.fill_defaults();
        toml::Value::try_from(&c).map_err(|e| ConfigError::Parse(e.to_string()))
    }

    /// The value of a numeric parameter given as a dotted key (`"matcher.wsm.sigma_slide"`),
    /// defaults filled in; `None` if the key names no number.
    #[must_use]
    pub fn parameter(&self, key: &str) -> Option<f64> {
        lookup(&self.effective_value().ok()?, key)
    }

    /// This config with the numeric parameter `key` (a dotted key, as
    /// [`steering_parameters`](Self::steering_parameters) gives) multiplied by `factor`,
    /// validated. Integers are rounded to the nearest whole number.
    pub fn scaled(&self, key: &str, factor: f64) -> Result<Self, ConfigError> {
        let unknown = || ConfigError::invalid(key, "is not a numeric matcher parameter");
        let mut value = self.effective_value()?;
        let mut at = &mut value;
        for part in key.strip_prefix("matcher.").ok_or_else(unknown)?.split('.') {
            at = at.get_mut(part).ok_or_else(unknown)?;
        }
        *at = match *at {
            toml::Value::Float(v) => toml::Value::Float(v * factor),
            toml::Value::Integer(v) => toml::Value::Integer((v as f64 * factor).round() as i64),
            _ => return Err(unknown()),
        };
        let c: MatcherConfig = value
            .try_into()
            .map_err(|e: toml::de::Error| ConfigError::Parse(e.to_string()))?;
        c.validate()?;
        Ok(c)
    }
}

/// The number at a dotted key (`"matcher.wsm.sigma_slide"`) of an effective config's TOML.
fn lookup(value: &toml::Value, key: &str) -> Option<f64> {
    let mut at = value;
    for part in key.strip_prefix("matcher.")?.split('.') {
        at = at.get(part)?;
    }
    match at {
        toml::Value::Float(v) => Some(*v),
        toml::Value::Integer(v) => Some(*v as f64),
        _ => None,
    }
}
