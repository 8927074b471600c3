//! `[robot]`, `[laser]` and `[drive]`: the robot's body and encoders, its laser scanner, and
//! how it is driven and the simulation stepped.

use serde::{Deserialize, Serialize};

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
    /// travel (m/√m), at most [`MAX_ENCODER_NOISE`](super::MAX_ENCODER_NOISE). Default 0.
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
    /// Number of beams, at most [`MAX_BEAMS`](super::MAX_BEAMS). Default 181.
    pub beams: usize,
    /// Field of view, centred on the heading (degrees). Default 180.
    pub fov_deg: f64,
    /// Maximum range (m); beams that hit nothing report exactly this. Default 20.
    pub max_range: f64,
    /// Minimum range (m). Default 0.
    pub min_range: f64,
    /// Standard deviation of the Gaussian range noise (m). Default 0.01.
    pub range_sigma: f64,
    /// Scans per second, at least [`MIN_LASER_RATE_HZ`](super::MIN_LASER_RATE_HZ). Default 1.
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
    /// Distance at which an intermediate waypoint counts as reached (m), at most
    /// [`MAX_WAYPOINT_TOLERANCE`](super::MAX_WAYPOINT_TOLERANCE). Default 0.5.
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
