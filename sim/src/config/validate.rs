//! Validation: [`SimConfig::validate`] refuses values that cannot work, naming the key.

use super::{ConfigError, ObstacleConfig, SimConfig, WorldKind};

/// Largest side of a park or a corridor floor (m): the route, the rooms and the obstacles'
/// placement scale with it, and a kilometre is far beyond any laser's reach.
pub const MAX_WORLD_SIZE: f64 = 1_000.0;
/// Most beams a simulated laser may have: the CARMEN reader's default `--max-beams`, so a
/// simulated log always reads back.
pub const MAX_BEAMS: usize = 10_000;
/// Smallest zigzag period (m): the route gets a waypoint every period.
pub const MIN_ZIGZAG_PERIOD: f64 = 0.1;
/// Largest random encoder error (m/√m): beyond it the encoders report noise, not travel.
pub const MAX_ENCODER_NOISE: f64 = 1.0;
/// Most pieces of furniture a corridor world's room may hold (`world.corridor.furniture`).
pub const MAX_FURNITURE: usize = 20;
/// Slowest laser (scans per second): one scan a minute and a half.
pub const MIN_LASER_RATE_HZ: f64 = 0.01;
/// Largest waypoint tolerance (m): beyond it every waypoint of a route counts as reached.
pub const MAX_WAYPOINT_TOLERANCE: f64 = 5.0;

impl SimConfig {
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
        size("world.park.size", p.size)?;
        let [r0, r1] = p.tree_radius;
        if !(r0.is_finite() && r1.is_finite() && r0 > 0.0 && r0 <= r1) {
            return invalid(
                "world.park.tree_radius",
                format!("is [{r0}, {r1}]: needs 0 < min <= max"),
            );
        }
        positive("world.park.hedge_mean_free_path", p.hedge_mean_free_path)?;
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
        size("world.corridor.size", c.size)?;
        positive("world.corridor.corridor_width", c.corridor_width)?;
        positive("world.corridor.outer_room_depth", c.outer_room_depth)?;
        positive("world.corridor.inner_room_depth", c.inner_room_depth)?;
        positive("world.corridor.room_width", c.room_width)?;
        positive("world.corridor.door_width", c.door_width)?;
        positive("world.corridor.wall_thickness", c.wall_thickness)?;
        at_least(
            "world.corridor.zigzag_period",
            c.zigzag_period,
            MIN_ZIGZAG_PERIOD,
        )?;
        non_negative("world.corridor.zigzag_amplitude", c.zigzag_amplitude)?;
        non_negative("world.corridor.door_offset", c.door_offset)?;
        if !(0.0..=1.0).contains(&c.closed_doors) {
            return invalid(
                "world.corridor.closed_doors",
                format!("is {}: must be a chance from 0 to 1", num(c.closed_doors)),
            );
        }
        if c.furniture > MAX_FURNITURE {
            return invalid(
                "world.corridor.furniture",
                format!("is {}: at most {MAX_FURNITURE} a room", c.furniture),
            );
        }
        let core = c.size[0].min(c.size[1])
            - 2.0 * (c.outer_room_depth + c.corridor_width + c.inner_room_depth);
        if core <= 0.0 {
            return invalid(
                "world.corridor.size",
                "is too small for the corridor and its rooms".into(),
            );
        }
        if c.wall_thickness >= c.corridor_width / 2.0 {
            return invalid(
                "world.corridor.wall_thickness",
                format!(
                    "is {}: must be below half the corridor's width",
                    num(c.wall_thickness)
                ),
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
        positive("robot.size", r.size[0])?;
        positive("robot.size", r.size[1])?;
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
        if r.encoder_noise > MAX_ENCODER_NOISE {
            return invalid(
                "robot.encoder_noise",
                format!(
                    "is {}: at most {MAX_ENCODER_NOISE} m/√m",
                    num(r.encoder_noise)
                ),
            );
        }
        for b in r.encoder_bias {
            if !(b.is_finite() && b.abs() < 0.5) {
                return invalid("robot.encoder_bias", format!("has {b}: needs |bias| < 0.5"));
            }
        }
        Ok(())
    }

    fn validate_laser(&self) -> Result<(), ConfigError> {
        let l = &self.laser;
        if l.beams == 0 || l.beams > MAX_BEAMS {
            return invalid(
                "laser.beams",
                format!("is {}: needs 1 to {MAX_BEAMS} beams", l.beams),
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
        at_least("laser.rate_hz", l.rate_hz, MIN_LASER_RATE_HZ)?;
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
        if d.waypoint_tolerance > MAX_WAYPOINT_TOLERANCE {
            return invalid(
                "drive.waypoint_tolerance",
                format!(
                    "is {} m: at most {MAX_WAYPOINT_TOLERANCE} m (every waypoint would count as reached)",
                    num(d.waypoint_tolerance)
                ),
            );
        }
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
            if !rectangle(center, half_size, *angle_deg) {
                return invalid(key, "has a box with bad centre, half_size or angle".into());
            }
        }
        ObstacleConfig::Foliage {
            center,
            half_size,
            angle_deg,
            mean_free_path,
        } => {
            if !rectangle(center, half_size, *angle_deg) {
                return invalid(
                    key,
                    "has foliage with bad centre, half_size or angle".into(),
                );
            }
            if !(mean_free_path.is_finite() && *mean_free_path > 0.0) {
                return invalid(
                    key,
                    format!(
                        "has foliage with mean_free_path {}: must be finite and positive",
                        num(*mean_free_path)
                    ),
                );
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

/// A rotated rectangle's centre and angle are finite and its half sizes finite and positive.
fn rectangle(center: &[f64; 2], half_size: &[f64; 2], angle_deg: f64) -> bool {
    center.iter().all(|x| x.is_finite())
        && angle_deg.is_finite()
        && half_size.iter().all(|h| h.is_finite() && *h > 0.0)
}

fn invalid(key: &'static str, why: String) -> Result<(), ConfigError> {
    Err(ConfigError::invalid(key, why))
}

fn positive(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        invalid(key, format!("is {}: must be finite and positive", num(v)))
    }
}

/// Both sides of a floor: finite, positive and at most [`MAX_WORLD_SIZE`].
fn size(key: &'static str, [w, h]: [f64; 2]) -> Result<(), ConfigError> {
    positive(key, w)?;
    positive(key, h)?;
    if w.max(h) > MAX_WORLD_SIZE {
        return invalid(
            key,
            format!(
                "is [{}, {}]: each side at most {MAX_WORLD_SIZE} m",
                num(w),
                num(h)
            ),
        );
    }
    Ok(())
}

fn at_least(key: &'static str, v: f64, min: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= min {
        Ok(())
    } else {
        invalid(
            key,
            format!("is {}: must be finite and at least {min}", num(v)),
        )
    }
}

fn non_negative(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        invalid(
            key,
            format!("is {}: must be finite and non-negative", num(v)),
        )
    }
}

/// A value as a message shows it: in exponent form when it is huge or tiny (1e308, not 309
/// digits).
fn num(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && a.is_finite() && !(1e-4..1e9).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}
