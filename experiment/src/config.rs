//! The experiment file: its source, the matchers to run and their overrides.

use super::*;
use qicp_io::carmen::RecordOrder;
use qicp_matchers::Registry;

/// An experiment configuration that cannot be used: the one configuration error of every
/// qicp file, a per-kind matcher table's error nested under `matchers.<kind>`.
pub type ExperimentError = qicp_core::ConfigError;

pub(super) fn invalid(key: &str, why: impl Into<String>) -> ExperimentError {
    ExperimentError::invalid(key, why)
}

fn is_file_order(order: &RecordOrder) -> bool {
    *order == RecordOrder::File
}

/// A [`RecordOrder`] in TOML by its name ([`RecordOrder::name`]: `"file"`, `"time"`).
mod order_name {
    use qicp_io::carmen::RecordOrder;
    use serde::{Deserialize, Deserializer, Serializer};

    pub(super) fn serialize<S: Serializer>(order: &RecordOrder, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(order.name())
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<RecordOrder, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// `[source]`: where the records come from. Exactly one of `sim` and `log`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// A drive configuration for the simulator (`configs/worlds/*.toml`). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim: Option<PathBuf>,
    /// A CARMEN log (plain or `.bz2`) or a ROS 2 bag (MCAP, told by its first bytes; see
    /// `scan_topic`). Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log: Option<PathBuf>,
    /// The `sensor_msgs/msg/LaserScan` topic of a bag. Default `/scan`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_topic: Option<String>,
    /// The `nav_msgs/msg/Odometry` topic of a bag. Default `/odom`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom_topic: Option<String>,
    /// Take a bag's odometry from /tf instead: the transform from this frame to `base_frame`.
    /// Default: none (the odometry topic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom_frame: Option<String>,
    /// The robot's frame, with `odom_frame`. Default `base_link`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_frame: Option<String>,
    /// Freiburg benchmark relations of the log. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relations: Option<PathBuf>,
    /// Ground truth of the log: TUM file or CARMEN log with `TRUEPOS`. Default: the log's own
    /// `TRUEPOS` records, if every laser record has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub groundtruth: Option<PathBuf>,
    /// Only the first `max_scans` scans. Default: all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_scans: Option<usize>,
    /// Override the drive's `[drive] seed` (sim only). Default: the drive's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Override the world's `[world] seed`, its procedural layout (sim only). Default: the
    /// world's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_seed: Option<u64>,
    /// Skip and count malformed log lines instead of failing (log only). Default false.
    #[serde(default)]
    pub lenient: bool,
    /// The order of a CARMEN log's records: `"file"` (the order the laser took them) or
    /// `"time"` (sorted by timestamp, as `qicp convert` writes a bag). Default `"file"`.
    #[serde(default, with = "order_name", skip_serializing_if = "is_file_order")]
    pub order: RecordOrder,
    /// Field of view of a CARMEN log's `FLASER` scans (degrees, in (0, 360]), as `qicp match
    /// --fov-deg`. Default: the log's `PARAM laser_front_laser_fov`, else 180.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
    /// Readings of a CARMEN log at or beyond this are no-returns (m), as `qicp match
    /// --max-range`. Default: the log's (`PARAM robot_front_laser_max`, else 81, for `FLASER`;
    /// a `ROBOTLASER1` line's own field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_range: Option<f64>,
    /// Readings of a CARMEN log below this are discarded (m). Default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_range: Option<f64>,
}

impl SourceConfig {
    /// The ground truth file of a log, read; `None` when not given.
    pub fn truth(&self) -> Result<Option<Vec<Stamped>>> {
        self.groundtruth
            .as_ref()
            .map(|p| {
                qicp_eval::load_trajectory(p, qicp_eval::LogPoses::Truth)
                    .with_context(|| format!("reading ground truth {}", p.display()))
            })
            .transpose()
    }

    /// How to read the log: CARMEN with `lenient`, a bag with the topics and frames given.
    #[must_use]
    pub fn log_options(&self) -> qicp_io::LogOptions {
        use qicp_io::rosbag::{BagOptions, OdometrySource};
        let odometry = OdometrySource::from_names(
            self.odom_topic.as_deref().unwrap_or("/odom"),
            self.odom_frame.as_deref(),
            self.base_frame.as_deref().unwrap_or("base_link"),
        );
        qicp_io::LogOptions {
            carmen: CarmenOptions {
                lenient: self.lenient,
                order: self.order,
                flaser_fov_deg: self.fov_deg,
                max_range: self.max_range,
                min_range: self.min_range.unwrap_or(0.0),
                ..CarmenOptions::default()
            },
            bag: BagOptions::new(
                self.scan_topic.clone().unwrap_or_else(|| "/scan".into()),
                odometry,
            ),
        }
    }

    /// The drive of a `sim` source at `sim`, with the source's seeds and length applied.
    pub fn drive(&self, sim: &Path) -> Result<qicp_sim::SimConfig> {
        let mut cfg = qicp_sim::SimConfig::load(sim)
            .with_context(|| format!("loading drive {}", sim.display()))?;
        if let Some(seed) = self.seed {
            cfg.drive.seed = seed;
        }
        if let Some(seed) = self.world_seed {
            cfg.world.seed = seed;
        }
        if self.max_scans.is_some() {
            cfg.drive.max_scans = self.max_scans;
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

/// `[run]`: what runs over the records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// Matcher kinds, in report order. Default [`DEFAULT_MATCHERS`].
    #[serde(default = "default_matchers")]
    pub matchers: Vec<String>,
}

pub(super) fn default_matchers() -> Vec<String> {
    DEFAULT_MATCHERS.map(String::from).to_vec()
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            matchers: default_matchers(),
        }
    }
}

/// An experiment: a source, the matchers, per-kind parameter overrides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// Where the records come from.
    pub source: SourceConfig,
    /// What runs.
    #[serde(default)]
    pub run: RunConfig,
    /// Per-kind overrides: each a `[matcher]` table without `kind`. Default: none (every
    /// matcher with its registry defaults).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub matchers: BTreeMap<String, toml::Table>,
}

impl ExperimentConfig {
    /// Parses a TOML document and validates it against the matchers of `registry`. Relative
    /// paths stay as written; see [`ExperimentConfig::resolve`].
    pub fn from_toml(text: &str, registry: &Registry) -> Result<Self, ExperimentError> {
        let c: Self = toml::from_str(text).map_err(|e| ExperimentError::Parse(e.to_string()))?;
        c.validate(registry)?;
        Ok(c)
    }

    /// Reads, validates and resolves a file: relative paths become relative to its directory.
    pub fn load(path: &Path, registry: &Registry) -> Result<Self, ExperimentError> {
        let text = std::fs::read_to_string(path).map_err(|e| ExperimentError::Io {
            path: path.display().to_string(),
            cause: e,
        })?;
        let mut c = Self::from_toml(&text, registry).map_err(|e| match e {
            ExperimentError::Parse(m) => ExperimentError::Parse(format!("{}: {m}", path.display())),
            other => other,
        })?;
        c.resolve(path.parent().unwrap_or(Path::new(".")));
        Ok(c)
    }

    /// Makes every relative source path relative to `base` instead, and absolute (so the
    /// effective config written elsewhere still finds them).
    pub fn resolve(&mut self, base: &Path) {
        let s = &mut self.source;
        for p in [&mut s.sim, &mut s.log, &mut s.relations, &mut s.groundtruth]
            .into_iter()
            .flatten()
        {
            let joined = base.join(&*p);
            *p = std::fs::canonicalize(&joined)
                .or_else(|_| std::path::absolute(&joined))
                .unwrap_or(joined);
        }
    }

    /// Checks the source, the matcher list and every per-kind table against the matchers of
    /// `registry`; names the bad key.
    pub fn validate(&self, registry: &Registry) -> Result<(), ExperimentError> {
        let s = &self.source;
        match (&s.sim, &s.log) {
            (None, None) => {
                return Err(invalid(
                    "source",
                    "give `sim` (a drive) or `log` (a CARMEN log)",
                ));
            }
            (Some(_), Some(_)) => return Err(invalid("source", "give `sim` or `log`, not both")),
            (Some(_), None) => {
                for (key, set) in [
                    ("source.relations", s.relations.is_some()),
                    ("source.groundtruth", s.groundtruth.is_some()),
                    ("source.lenient", s.lenient),
                    ("source.scan_topic", s.scan_topic.is_some()),
                    ("source.odom_topic", s.odom_topic.is_some()),
                    ("source.odom_frame", s.odom_frame.is_some()),
                    ("source.base_frame", s.base_frame.is_some()),
                    // A drive's records are made in time order; only a log's can be sorted.
                    ("source.order", s.order != RecordOrder::File),
                    // A drive's laser is its world's.
                    ("source.fov_deg", s.fov_deg.is_some()),
                    ("source.max_range", s.max_range.is_some()),
                    ("source.min_range", s.min_range.is_some()),
                ] {
                    if set {
                        return Err(invalid(
                            key,
                            "only for a `log` source (a simulated drive has its own ground \
                             truth, topics and frames, and makes its records in time order)",
                        ));
                    }
                }
            }
            (None, Some(_)) => {
                if s.odom_topic.is_some() && s.odom_frame.is_some() {
                    return Err(invalid(
                        "source.odom_frame",
                        "odometry from /tf (odom_frame) or from a topic (odom_topic), not both",
                    ));
                }
                if s.base_frame.is_some() && s.odom_frame.is_none() {
                    return Err(invalid("source.base_frame", "only with `odom_frame`"));
                }
                for (key, set) in [
                    ("source.seed", s.seed.is_some()),
                    ("source.world_seed", s.world_seed.is_some()),
                ] {
                    if set {
                        return Err(invalid(key, "only for a `sim` source"));
                    }
                }
                use qicp_io::carmen::{fov_deg_problem, max_range_problem, min_range_problem};
                for (key, value, problem) in [
                    ("source.fov_deg", s.fov_deg, fov_deg_problem as fn(f64) -> _),
                    ("source.max_range", s.max_range, max_range_problem),
                    ("source.min_range", s.min_range, min_range_problem),
                ] {
                    if let Some(v) = value
                        && let Some(why) = problem(v)
                    {
                        return Err(invalid(key, format!("{v} {why}")));
                    }
                }
            }
        }
        if s.max_scans == Some(0) {
            return Err(invalid(
                "source.max_scans",
                "is 0: nothing would be matched",
            ));
        }
        if self.run.matchers.is_empty() {
            return Err(invalid(
                "run.matchers",
                "is empty: name at least one matcher kind",
            ));
        }
        let mut seen = std::collections::BTreeSet::new();
        for k in &self.run.matchers {
            if !seen.insert(k) {
                return Err(invalid("run.matchers", format!("`{k}` is listed twice")));
            }
            registry.resolve(k).map_err(|_| {
                invalid(
                    "run.matchers",
                    format!(
                        "unknown matcher kind `{k}`; known: {}",
                        registry.names().join(", ")
                    ),
                )
            })?;
        }
        for kind in self.matchers.keys() {
            let name = kind;
            registry.resolve(kind).map_err(|_| {
                invalid(
                    &format!("matchers.{name}"),
                    format!(
                        "unknown matcher kind; known: {}",
                        registry.names().join(", ")
                    ),
                )
            })?;
            if !self.run.matchers.contains(kind) {
                return Err(invalid(
                    &format!("matchers.{name}"),
                    "parameters for a kind that `run.matchers` does not list",
                ));
            }
            self.matcher(kind, registry)?;
        }
        Ok(())
    }

    /// The effective configuration of `kind`: its registry defaults, overridden by its
    /// `[matchers.<kind>]` table.
    pub fn matcher(
        &self,
        kind: &str,
        registry: &Registry,
    ) -> Result<MatcherConfig, ExperimentError> {
        let err = |e: ExperimentError| e.inside(format!("matchers.{kind}"));
        let Some(table) = self.matchers.get(kind) else {
            return registry.config(kind).map_err(err);
        };
        if table.contains_key("kind") {
            return Err(err(ExperimentError::invalid(
                "kind",
                "the table's name is the kind; drop `kind`",
            )));
        }
        let mut matcher = table.clone();
        matcher.insert("kind".into(), toml::Value::String(kind.into()));
        let mut doc = toml::Table::new();
        doc.insert("matcher".into(), toml::Value::Table(matcher));
        let text = toml::to_string(&doc).map_err(|e| ExperimentError::Parse(e.to_string()))?;
        registry.parse(&text).map_err(err)
    }

    /// The effective configuration as TOML: the source and run as loaded (paths resolved) and
    /// every matcher's parameters spelled out under `[matchers.<kind>]`. It loads back as an
    /// experiment that runs the same.
    pub fn effective_toml(&self, registry: &Registry) -> Result<String, ExperimentError> {
        let mut c = self.clone();
        for kind in &self.run.matchers {
            let m = self.matcher(kind, registry)?;
            let mut value = m
                .to_table()
                .map_err(|e| e.inside(format!("matchers.{kind}")))?;
            for axis in ["algorithm", "reference", "index"] {
                value.remove(axis);
            }
            c.matchers.insert(kind.clone(), value);
        }
        toml::to_string_pretty(&c).map_err(|e| ExperimentError::Parse(e.to_string()))
    }
}
