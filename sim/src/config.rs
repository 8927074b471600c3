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
use thiserror::Error;

/// Why a configuration was refused.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The text is not valid TOML for this schema (unknown key, unknown world kind, wrong type).
    /// The message names the key and shows the offending line.
    #[error("invalid simulation config: {0}")]
    Parse(String),
    /// A value parses but cannot work.
    #[error("invalid simulation config: `{key}` {why}")]
    Invalid {
        /// Dotted path of the key, e.g. `laser.beams`.
        key: &'static str,
        /// What is wrong with it.
        why: String,
    },
}

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

/// Which world to build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WorldKind {
    /// An open park with sparse trees, rocks and benches (procedural, seeded).
    #[default]
    Park,
    /// An office floor: a rectangular corridor loop with rooms on both sides (procedural).
    Corridor,
    /// Only the explicit `world.obstacles`; the route must be given as `drive.waypoints`.
    Custom,
}

impl WorldKind {
    /// The lowercase name used in configs.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            WorldKind::Park => "park",
            WorldKind::Corridor => "corridor",
            WorldKind::Custom => "custom",
        }
    }
}

/// `[world]`. Defaults: a park, seed 7, no extra obstacles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldConfig {
    /// `park`, `corridor` or `custom`.
    pub kind: WorldKind,
    /// Seed of the procedural layout (tree positions, route wiggles).
    pub seed: u64,
    /// Park parameters (`[world.park]`); only allowed with `kind = "park"`.
    pub park: Option<ParkConfig>,
    /// Corridor parameters (`[world.corridor]`); only allowed with `kind = "corridor"`.
    pub corridor: Option<CorridorConfig>,
    /// Explicit obstacles, added to any world kind (`[[world.obstacles]]`).
    pub obstacles: Vec<ObstacleConfig>,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            kind: WorldKind::Park,
            seed: 7,
            park: None,
            corridor: None,
            obstacles: Vec::new(),
        }
    }
}

/// `[world.park]`: an open area, the route a clockwise loop from the bottom-right corner.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParkConfig {
    /// Width and height of the park (m). Default 80 × 40.
    pub size: [f64; 2],
    /// Number of trees. Default 12.
    pub trees: usize,
    /// Smallest and largest trunk radius (m). Default 0.15–0.5.
    pub tree_radius: [f64; 2],
    /// Number of rocks (round, 0.3–0.8 m). Default 3.
    pub rocks: usize,
    /// Number of benches (1.6 × 0.5 m boxes). Default 2.
    pub benches: usize,
    /// Smallest free distance between the route and any obstacle surface (m). Default 2.5.
    pub route_clearance: f64,
    /// Distance of the loop from the park's edge (m). Default 6.
    pub route_margin: f64,
    /// Largest sideways wiggle of the loop's intermediate waypoints (m). Default 3.
    pub route_wiggle: f64,
}

impl Default for ParkConfig {
    fn default() -> Self {
        Self {
            size: [80.0, 40.0],
            trees: 12,
            tree_radius: [0.15, 0.5],
            rocks: 3,
            benches: 2,
            route_clearance: 2.5,
            route_margin: 6.0,
            route_wiggle: 3.0,
        }
    }
}

/// `[world.corridor]`: a rectangular corridor loop, rooms with doorways on both sides, the
/// route zigzagging between the corridor walls.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CorridorConfig {
    /// Outer size of the floor (m). Default 30 × 30.
    pub size: [f64; 2],
    /// Free width of the corridor (m). Default 2.4.
    pub corridor_width: f64,
    /// Depth of the rooms on the outer side of the corridor (m). Default 5.
    pub outer_room_depth: f64,
    /// Depth of the rooms on the inner side of the corridor (m). Default 4.
    pub inner_room_depth: f64,
    /// Target width of a room along the corridor (m). Default 4.5.
    pub room_width: f64,
    /// Width of a doorway (m). Default 1.0.
    pub door_width: f64,
    /// Wall thickness (m). Default 0.1.
    pub wall_thickness: f64,
    /// Distance along the corridor between zigzag turning points (m). Default 3.
    pub zigzag_period: f64,
    /// Sideways offset of the zigzag turning points from the corridor centre (m). Default 0.5.
    pub zigzag_amplitude: f64,
}

impl Default for CorridorConfig {
    fn default() -> Self {
        Self {
            size: [30.0, 30.0],
            corridor_width: 2.4,
            outer_room_depth: 5.0,
            inner_room_depth: 4.0,
            room_width: 4.5,
            door_width: 1.0,
            wall_thickness: 0.1,
            zigzag_period: 3.0,
            zigzag_amplitude: 0.5,
        }
    }
}

/// One explicit obstacle (`[[world.obstacles]]`), tagged by `kind`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum ObstacleConfig {
    /// A round post or trunk.
    Circle {
        /// Centre (m).
        center: [f64; 2],
        /// Radius (m).
        radius: f64,
    },
    /// A rectangle, rotated by `angle_deg` about its centre.
    Box {
        /// Centre (m).
        center: [f64; 2],
        /// Half width and half height (m).
        half_size: [f64; 2],
        /// Rotation (degrees, counter-clockwise).
        #[serde(default)]
        angle_deg: f64,
    },
    /// A straight wall from `a` to `b` (its centre line) of the given thickness.
    Wall {
        /// One end (m).
        a: [f64; 2],
        /// The other end (m).
        b: [f64; 2],
        /// Thickness (m); default 0.1.
        #[serde(default = "default_wall_thickness")]
        thickness: f64,
    },
}

fn default_wall_thickness() -> f64 {
    0.1
}

/// `[robot]`: a differential-drive robot on tyres that slip. Defaults: a 30 kg, 0.5 × 0.4 m
/// robot on an office floor (µ = 0.8).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    /// Mass (kg). Default 30.
    pub mass: f64,
    /// Length and width of the body's collision box (m). Default 0.5 × 0.4.
    pub size: [f64; 2],
    /// Distance between the two drive wheels (m). Default 0.4.
    pub wheel_base: f64,
    /// Largest wheel rim speed (m/s). Default 1.0.
    pub max_wheel_speed: f64,
    /// Largest wheel rim acceleration the motors deliver (m/s²). Default 2.0.
    pub max_wheel_accel: f64,
    /// Tyre–ground friction coefficient µ: each wheel transmits at most µ·m·g/2 (traction
    /// saturation). Grass ~0.2–0.35, indoor floor ~0.8. Default 0.8.
    pub ground_friction: f64,
    /// Rolling resistance coefficient (force / normal load). Grass ~0.05, floor ~0.01.
    /// Default 0.01.
    pub rolling_resistance: f64,
    /// Tyre slip scale: the slip ratio at which a tyre transmits tanh(1) ≈ 76 % of µ·N.
    /// Larger means softer tyres and more creep. Default 0.1.
    pub tyre_slip: f64,
    /// Random encoder error: standard deviation of each wheel's travel error per √metre of
    /// travel (m/√m). Default 0.
    pub encoder_noise: f64,
    /// Systematic encoder error of the left and right wheel, as a relative scale error
    /// (0.01: the wheel reports 1 % more travel than it turned). Default [0, 0].
    pub encoder_bias: [f64; 2],
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            mass: 30.0,
            size: [0.5, 0.4],
            wheel_base: 0.4,
            max_wheel_speed: 1.0,
            max_wheel_accel: 2.0,
            ground_friction: 0.8,
            rolling_resistance: 0.01,
            tyre_slip: 0.1,
            encoder_noise: 0.0,
            encoder_bias: [0.0, 0.0],
        }
    }
}

/// `[laser]`. Defaults: 181 beams over 180°, 20 m range, σ = 1 cm, 1 Hz, at the robot origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LaserConfig {
    /// Number of beams. Default 181.
    pub beams: usize,
    /// Field of view, centred on the heading (degrees). Default 180.
    pub fov_deg: f64,
    /// Maximum range (m); beams that hit nothing report exactly this. Default 20.
    pub max_range: f64,
    /// Minimum range (m). Default 0.
    pub min_range: f64,
    /// Standard deviation of the Gaussian range noise (m). Default 0.01.
    pub range_sigma: f64,
    /// Scans per second. Default 1.
    pub rate_hz: f64,
    /// Forward offset of the laser from the robot origin (m). Default 0.
    pub offset_x: f64,
}

impl Default for LaserConfig {
    fn default() -> Self {
        Self {
            beams: 181,
            fov_deg: 180.0,
            max_range: 20.0,
            min_range: 0.0,
            range_sigma: 0.01,
            rate_hz: 1.0,
            offset_x: 0.0,
        }
    }
}

/// `[drive]`: how the waypoint controller drives and how the simulation is stepped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriveConfig {
    /// Waypoints (m). Default: none, the world kind generates the route (required for `custom`).
    /// The robot starts at the first, facing the second.
    pub waypoints: Option<Vec<[f64; 2]>>,
    /// Cruise speed (m/s). Default 0.5.
    pub speed: f64,
    /// Largest commanded turn rate (deg/s). Default 60.
    pub turn_rate_deg: f64,
    /// Commanded linear acceleration (m/s²); above µ·g the wheels spin. Default 1.0.
    pub accel: f64,
    /// Commanded angular acceleration (deg/s²). Default 180.
    pub angular_accel_deg: f64,
    /// Distance at which an intermediate waypoint counts as reached (m). Default 0.5.
    pub waypoint_tolerance: f64,
    /// Seed of the laser and encoder noise. Default 1.
    pub seed: u64,
    /// Physics steps per second. Default 100.
    pub physics_hz: f64,
    /// Stop after this many scans even if the route is not finished. Default: no limit.
    pub max_scans: Option<usize>,
    /// Give up after this much simulated time (s). Default 3600.
    pub timeout_s: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            waypoints: None,
            speed: 0.5,
            turn_rate_deg: 60.0,
            accel: 1.0,
            angular_accel_deg: 180.0,
            waypoint_tolerance: 0.5,
            seed: 1,
            physics_hz: 100.0,
            max_scans: None,
            timeout_s: 3600.0,
        }
    }
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
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
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

    /// Refuses values that cannot work, naming the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let w = &self.world;
        if w.park.is_some() && w.kind != WorldKind::Park {
            return invalid(
                "world.park",
                format!("is given but world.kind is \"{}\"", w.kind.name()),
            );
        }
        if w.corridor.is_some() && w.kind != WorldKind::Corridor {
            return invalid(
                "world.corridor",
                format!("is given but world.kind is \"{}\"", w.kind.name()),
            );
        }
        match w.kind {
            WorldKind::Park => self.validate_park()?,
            WorldKind::Corridor => self.validate_corridor()?,
            WorldKind::Custom => {
                if self.drive.waypoints.is_none() {
                    return invalid(
                        "drive.waypoints",
                        "is required with world.kind = \"custom\"".into(),
                    );
                }
            }
        }
        for o in &w.obstacles {
            validate_obstacle(o)?;
        }
        self.validate_robot()?;
        self.validate_laser()?;
        self.validate_drive()
    }

    fn validate_park(&self) -> Result<(), ConfigError> {
        let p = self.park();
        positive("world.park.size", p.size[0].min(p.size[1]))?;
        let [r0, r1] = p.tree_radius;
        if !(r0.is_finite() && r1.is_finite() && r0 > 0.0 && r0 <= r1) {
            return invalid(
                "world.park.tree_radius",
                format!("is [{r0}, {r1}]: needs 0 < min <= max"),
            );
        }
        non_negative("world.park.route_clearance", p.route_clearance)?;
        non_negative("world.park.route_wiggle", p.route_wiggle)?;
        positive("world.park.route_margin", p.route_margin)?;
        if 2.0 * p.route_margin >= p.size[0].min(p.size[1]) {
            return invalid(
                "world.park.route_margin",
                format!("is {}: the loop does not fit in the park", p.route_margin),
            );
        }
        Ok(())
    }

    fn validate_corridor(&self) -> Result<(), ConfigError> {
        let c = self.corridor();
        positive("world.corridor.size", c.size[0].min(c.size[1]))?;
        positive("world.corridor.corridor_width", c.corridor_width)?;
        positive("world.corridor.outer_room_depth", c.outer_room_depth)?;
        positive("world.corridor.inner_room_depth", c.inner_room_depth)?;
        positive("world.corridor.room_width", c.room_width)?;
        positive("world.corridor.door_width", c.door_width)?;
        positive("world.corridor.wall_thickness", c.wall_thickness)?;
        positive("world.corridor.zigzag_period", c.zigzag_period)?;
        non_negative("world.corridor.zigzag_amplitude", c.zigzag_amplitude)?;
        let core = c.size[0].min(c.size[1])
            - 2.0 * (c.outer_room_depth + c.corridor_width + c.inner_room_depth);
        if core <= 0.0 {
            return invalid(
                "world.corridor.size",
                "is too small for the corridor and its rooms".into(),
            );
        }
        if c.door_width >= c.room_width {
            return invalid(
                "world.corridor.door_width",
                "must be smaller than room_width".into(),
            );
        }
        let half_free = c.corridor_width / 2.0 - self.robot.size[1].max(self.robot.size[0]) / 2.0;
        if c.zigzag_amplitude >= half_free {
            return invalid(
                "world.corridor.zigzag_amplitude",
                format!(
                    "is {}: the robot would touch the corridor walls (at most {half_free:.2})",
                    c.zigzag_amplitude
                ),
            );
        }
        Ok(())
    }

    fn validate_robot(&self) -> Result<(), ConfigError> {
        let r = &self.robot;
        positive("robot.mass", r.mass)?;
        positive("robot.size", r.size[0].min(r.size[1]))?;
        positive("robot.wheel_base", r.wheel_base)?;
        positive("robot.max_wheel_speed", r.max_wheel_speed)?;
        positive("robot.max_wheel_accel", r.max_wheel_accel)?;
        positive("robot.ground_friction", r.ground_friction)?;
        non_negative("robot.rolling_resistance", r.rolling_resistance)?;
        if r.rolling_resistance >= r.ground_friction {
            return invalid(
                "robot.rolling_resistance",
                "must be below robot.ground_friction (the robot could not move)".into(),
            );
        }
        positive("robot.tyre_slip", r.tyre_slip)?;
        non_negative("robot.encoder_noise", r.encoder_noise)?;
        for b in r.encoder_bias {
            if !(b.is_finite() && b.abs() < 0.5) {
                return invalid("robot.encoder_bias", format!("has {b}: needs |bias| < 0.5"));
            }
        }
        Ok(())
    }

    fn validate_laser(&self) -> Result<(), ConfigError> {
        let l = &self.laser;
        if l.beams == 0 {
            return invalid(
                "laser.beams",
                "is 0: a laser needs at least one beam".into(),
            );
        }
        if !(l.fov_deg.is_finite() && l.fov_deg > 0.0 && l.fov_deg <= 360.0) {
            return invalid(
                "laser.fov_deg",
                format!("is {}: needs 0 < fov <= 360", l.fov_deg),
            );
        }
        positive("laser.max_range", l.max_range)?;
        non_negative("laser.min_range", l.min_range)?;
        if l.min_range >= l.max_range {
            return invalid("laser.min_range", "must be below laser.max_range".into());
        }
        non_negative("laser.range_sigma", l.range_sigma)?;
        positive("laser.rate_hz", l.rate_hz)?;
        if !l.offset_x.is_finite() {
            return invalid("laser.offset_x", "must be finite".into());
        }
        Ok(())
    }

    fn validate_drive(&self) -> Result<(), ConfigError> {
        let d = &self.drive;
        if let Some(w) = &d.waypoints {
            if w.len() < 2 {
                return invalid(
                    "drive.waypoints",
                    format!("has {} point(s): needs at least 2", w.len()),
                );
            }
            if w.iter().flatten().any(|v| !v.is_finite()) {
                return invalid("drive.waypoints", "must be finite".into());
            }
            if w[0] == w[1] {
                return invalid(
                    "drive.waypoints",
                    "starts with two equal points (no start heading)".into(),
                );
            }
        }
        positive("drive.speed", d.speed)?;
        if d.speed > self.robot.max_wheel_speed {
            return invalid(
                "drive.speed",
                format!(
                    "is {} m/s, above robot.max_wheel_speed ({})",
                    d.speed, self.robot.max_wheel_speed
                ),
            );
        }
        positive("drive.turn_rate_deg", d.turn_rate_deg)?;
        positive("drive.accel", d.accel)?;
        positive("drive.angular_accel_deg", d.angular_accel_deg)?;
        positive("drive.waypoint_tolerance", d.waypoint_tolerance)?;
        positive("drive.physics_hz", d.physics_hz)?;
        if d.physics_hz < self.laser.rate_hz {
            return invalid(
                "drive.physics_hz",
                "must be at least laser.rate_hz (one physics step per scan)".into(),
            );
        }
        if d.physics_hz > 10_000.0 {
            return invalid("drive.physics_hz", "is above 10000".into());
        }
        if d.max_scans == Some(0) {
            return invalid("drive.max_scans", "is 0: nothing would be simulated".into());
        }
        positive("drive.timeout_s", d.timeout_s)
    }
}

fn validate_obstacle(o: &ObstacleConfig) -> Result<(), ConfigError> {
    let key = "world.obstacles";
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    match o {
        ObstacleConfig::Circle { center, radius } => {
            if !(finite(center) && radius.is_finite() && *radius > 0.0) {
                return invalid(
                    key,
                    format!("has a circle with bad centre or radius {radius}"),
                );
            }
        }
        ObstacleConfig::Box {
            center,
            half_size,
            angle_deg,
        } => {
            if !finite(center)
                || !finite(&[*angle_deg])
                || !half_size.iter().all(|h| h.is_finite() && *h > 0.0)
            {
                return invalid(key, "has a box with bad centre, half_size or angle".into());
            }
        }
        ObstacleConfig::Wall { a, b, thickness } => {
            if !(finite(a) && finite(b) && a != b && thickness.is_finite() && *thickness > 0.0) {
                return invalid(key, "has a wall with bad ends or thickness".into());
            }
        }
    }
    Ok(())
}

fn invalid(key: &'static str, why: String) -> Result<(), ConfigError> {
    Err(ConfigError::Invalid { key, why })
}

fn positive(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        invalid(key, format!("is {v}: must be finite and positive"))
    }
}

fn non_negative(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        invalid(key, format!("is {v}: must be finite and non-negative"))
    }
}
