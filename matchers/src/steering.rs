//! The parameters a robustness sweep perturbs (`qicp sweep`): which numbers of a
//! [`MatcherConfig`] steer matching and map building, read and scaled by dotted key.

use crate::config::{ConfigError, LASER_PARAMETERS, MatcherConfig};
use crate::params::Acts;

/// The numeric parameters of the shared sections that steer matching and map building: the
/// ones a robustness sweep perturbs (`qicp sweep`), with each algorithm's own steering
/// parameters ([`Param::steering`](crate::Param::steering)) and, for an algorithm that weighs by
/// it, the laser's range noise. Keys are dotted paths below `[matcher]`. Those that act only
/// on a map ([`Acts::Map`]: what enters it, how dense it grows, what is withheld from it) are
/// not swept for a scan-to-scan reference, which every relevant scan replaces whatever they
/// say, so that each variant would repeat the default run.
const STEERING_COMMON: &[(&str, Acts)] = &[
    ("icp.max_dist_start", Acts::Any),
    ("icp.max_dist_end", Acts::Any),
    ("relevance.tau_max", Acts::Any),
    ("relevance.rho_max_deg", Acts::Any),
    ("relevance.map_resolution", Acts::Map),
    ("relevance.surface_band_sigmas", Acts::Map),
    ("relevance.max_cell_points", Acts::Map),
    ("relevance.cell_size", Acts::Map),
    ("relevance.window_scans", Acts::Map),
    ("relevance.min_novelty", Acts::Map),
    ("relevance.novelty_distance", Acts::Map),
    ("relevance.free_space_margin", Acts::Map),
    ("motion.sigma_xy_per_m", Acts::Any),
    ("motion.sigma_theta_per_m_deg", Acts::Any),
    ("motion.calibration_m", Acts::Map),
    ("motion.stall_prior_sigmas", Acts::Map),
    ("validation.inlier_distance", Acts::Any),
    ("validation.max_share_drop", Acts::Any),
    ("validation.max_pair_drop", Acts::Any),
    ("validation.max_residual_ratio", Acts::Any),
    ("validation.max_odometry_chi2", Acts::Any),
    ("validation.point_evidence", Acts::Map),
    ("correlative.window_xy", Acts::Any),
    ("correlative.window_deg", Acts::Any),
    ("revisit.age_scans", Acts::Map),
    ("revisit.every", Acts::Map),
    ("revisit.max_miss", Acts::Map),
    ("revisit.min_gain", Acts::Map),
    ("revisit.window_xy", Acts::Map),
    ("revisit.window_deg", Acts::Map),
    ("revisit.confirmations", Acts::Map),
    ("revisit.confirm_gap", Acts::Map),
];

/// Steering parameters that act only while switches are on: each is left out of the sweep
/// while one of its switches is false, as scaling it would change nothing (and a variant that
/// repeats the default would pull the sweep's median ratio towards 1).
const SWITCHED: &[(&str, &[&str])] = &[
    ("validation.", &["validation.enabled"]),
    // A residual or a pair count below the level only sends a match to the search.
    ("validation.max_residual_ratio", &["validation.search"]),
    ("validation.max_pair_drop", &["validation.search"]),
    // Odometry's veto needs the motion prior; its weighing, the fall-back.
    ("validation.max_odometry_chi2", &["motion.enabled"]),
    (
        "validation.point_evidence",
        &["motion.enabled", "validation.veto_falls_back"],
    ),
    ("correlative.", &["validation.enabled", "validation.search"]),
    ("revisit.", &["validation.enabled", "revisit.enabled"]),
    ("motion.sigma_", &["motion.enabled"]),
    (
        "motion.stall_prior_sigmas",
        &["motion.enabled", "motion.stall_velocity"],
    ),
];

/// Steering parameters that act only through another one: each is left out of the sweep
/// while the parameter it serves is 0 (off), as scaling it would change nothing.
const SERVES: &[(&str, &str)] = &[
    ("relevance.novelty_distance", "relevance.min_novelty"),
    ("relevance.cell_size", "relevance.max_cell_points"),
    ("validation.point_evidence", "validation.max_odometry_chi2"),
];

impl MatcherConfig {
    /// The numeric parameters that steer this matcher (correspondence distances, relevance
    /// thresholds, the map's density bound, the noise and motion models, and the algorithm's
    /// own steering parameters), as dotted keys such as `"matcher.icp.max_dist_start"`.
    /// Parameters whose value is 0 are left out: scaling them changes nothing; so are those
    /// that serve a parameter which is 0 (the novelty distance without the novelty gate), and,
    /// those that act only on another kind of reference ([`Param::acting_on`](crate::Param::acting_on)).
    #[must_use]
    pub fn steering_parameters(&self) -> Vec<String> {
        let Ok(value) = self.to_table() else {
            return Vec::new();
        };
        let map = self.reference.is_map();
        let own = self
            .algorithm
            .parameters()
            .iter()
            .filter(|p| p.steering && p.acts.on(map))
            .map(|p| format!("{}.{}", self.algorithm.name(), p.key));
        let laser = LASER_PARAMETERS
            .iter()
            .filter(|p| p.steering && self.algorithm.weighs_by_laser_noise())
            .map(|p| format!("laser.{}", p.key));
        STEERING_COMMON
            .iter()
            .filter(|(_, acts)| acts.on(map))
            .map(|(k, _)| k.to_string())
            .chain(own)
            .chain(laser)
            .map(|k| format!("matcher.{k}"))
            .filter(|k| lookup(&value, k).is_some_and(|v| v != 0.0))
            .filter(|k| {
                SERVES.iter().all(|(key, served)| {
                    k.strip_prefix("matcher.") != Some(key)
                        || lookup(&value, &format!("matcher.{served}")).is_some_and(|v| v != 0.0)
                })
            })
            .filter(|k| {
                SWITCHED.iter().all(|(prefix, switches)| {
                    !k.strip_prefix("matcher.")
                        .is_some_and(|k| k.starts_with(prefix))
                        || switches
                            .iter()
                            .all(|s| switch(&value, &format!("matcher.{s}")) != Some(false))
                })
            })
            .collect()
    }

    /// The value of a numeric parameter given as a dotted key (`"matcher.wsm.sigma_slide"`),
    /// defaults filled in; `None` if the key names no number.
    #[must_use]
    pub fn parameter(&self, key: &str) -> Option<f64> {
        lookup(&self.to_table().ok()?, key)
    }

    /// This config with the numeric parameter `key` (a dotted key, as
    /// [`steering_parameters`](Self::steering_parameters) gives) multiplied by `factor`,
    /// validated. Integers are rounded to the nearest whole number.
    pub fn scaled(&self, key: &str, factor: f64) -> Result<Self, ConfigError> {
        let unknown = || ConfigError::invalid(key, "is not a numeric matcher parameter");
        let mut table = self.to_table()?;
        let mut parts = key.strip_prefix("matcher.").ok_or_else(unknown)?.split('.');
        let first = parts.next().ok_or_else(unknown)?;
        let mut at = table.get_mut(first).ok_or_else(unknown)?;
        for part in parts {
            at = at.get_mut(part).ok_or_else(unknown)?;
        }
        *at = match *at {
            toml::Value::Float(v) => toml::Value::Float(v * factor),
            toml::Value::Integer(v) => toml::Value::Integer((v as f64 * factor).round() as i64),
            _ => return Err(unknown()),
        };
        for axis in ["algorithm", "reference", "index"] {
            table.remove(axis);
        }
        // Leftover keys cannot appear: the table is this config's own.
        Self::assemble(
            self.algorithm.clone(),
            self.reference.clone(),
            self.index.clone(),
            table,
            &|_| false,
        )
    }
}

/// The boolean at a dotted key (`"matcher.revisit.enabled"`) of an effective config's table.
fn switch(table: &toml::Table, key: &str) -> Option<bool> {
    let mut parts = key.strip_prefix("matcher.")?.split('.');
    let mut at = table.get(parts.next()?)?;
    for part in parts {
        at = at.get(part)?;
    }
    at.as_bool()
}

/// The number at a dotted key (`"matcher.wsm.sigma_slide"`) of an effective config's table.
fn lookup(table: &toml::Table, key: &str) -> Option<f64> {
    let mut parts = key.strip_prefix("matcher.")?.split('.');
    let mut at = table.get(parts.next()?)?;
    for part in parts {
        at = at.get(part)?;
    }
    match at {
        toml::Value::Float(v) => Some(*v),
        toml::Value::Integer(v) => Some(*v as f64),
        _ => None,
    }
}
