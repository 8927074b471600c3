//! The TOML description of one simulated drive: `[world]`, `[robot]`, `[laser]`, `[drive]`.
//!
//! Every section has documented defaults (a missing section or key takes them), unknown keys
//! are refused, and [`SimConfig::validate`] names the key of any value that cannot work.
//!
//! ```toml
//! [world]
//! kind = "park"          # "park" | "corridor" | "custom"
//! seed = 7               # procedural layout seed
//! [world.park]           # only with kind = "park" (all keys optional)
//! trees = 12
//! [robot]
//! ground_friction = 0.3
//! [laser]
//! beams = 181
//! fov_deg = 180
//! max_range = 20
//! [drive]
//! speed = 0.45
//! seed = 1
//! ```

use serde::{Deserialize, Serialize};
use std::path::Path;

mod robot;
mod validate;
mod world;

pub use robot::{DriveConfig, LaserConfig, RobotConfig};
pub use validate::{
    MAX_BEAMS, MAX_ENCODER_NOISE, MAX_FURNITURE, MAX_WAYPOINT_TOLERANCE, MAX_WORLD_SIZE,
    MIN_LASER_RATE_HZ, MIN_ZIGZAG_PERIOD,
};
pub use world::{CorridorConfig, ObstacleConfig, ParkConfig, WorldConfig, WorldKind};

pub use qicp_core::ConfigError;

/// The whole drive: world, robot, laser, route and timing.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// The world the robot drives in.
    pub world: WorldConfig,
    /// The robot's body, wheels, tyres and encoders.
    pub robot: RobotConfig,
    /// The laser scanner.
    pub laser: LaserConfig,
    /// Route, speed, timing and noise seed.
    pub drive: DriveConfig,
}

impl SimConfig {
    /// Parses TOML text and validates it.
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        let cfg: SimConfig = toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads, parses and validates a TOML file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|cause| ConfigError::Io {
            path: path.display().to_string(),
            cause,
        })?;
        Self::from_toml_str(&text)
    }

    /// The effective configuration as TOML (written beside every run's outputs).
    pub fn to_toml_string(&self) -> Result<String, ConfigError> {
        toml::to_string_pretty(self).map_err(|e| ConfigError::Parse(e.to_string()))
    }

    /// The park parameters in effect (given or default).
    #[must_use]
    pub fn park(&self) -> ParkConfig {
        self.world.park.clone().unwrap_or_default()
    }

    /// The corridor parameters in effect (given or default).
    #[must_use]
    pub fn corridor(&self) -> CorridorConfig {
        self.world.corridor.clone().unwrap_or_default()
    }
}
