//! The drive: a rapier2d world of static obstacles, a differential-drive robot body pushed by
//! two slipping tyres, wheel-encoder odometry, a waypoint controller and a ray-cast laser.
//!
//! Each physics step:
//! 1. the controller (on the true pose) picks a linear and angular speed, rate-limited;
//! 2. the motors drive the wheel rims toward the matching wheel speeds (acceleration-limited);
//! 3. the encoders integrate the rim speeds into odometry (with bias and noise) — they cannot
//!    see slip;
//! 4. each tyre transmits a force that grows with its slip and saturates at µ·N
//!    (a tanh tyre curve, friction circle over the longitudinal and lateral parts), against
//!    rolling resistance; rapier integrates the body, including collisions with the world.
//!
//! At laser times the scanner casts its beams against the static colliders.

use crate::ConfigError;
use crate::config::SimConfig;
use crate::noise::Noise;
use crate::world::{Obstacle, World, WorldError};
use qicp_core::{BeamGeometry, Pose2, Record, Scan, ScanError, normalize_angle};
use rapier2d::prelude::*;
use thiserror::Error;

/// Gravity (m/s²), for the normal load on the tyres (the world itself is seen from above).
const G: f64 = 9.81;

/// Why a simulation could not run.
#[derive(Debug, Error)]
pub enum SimError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The world could not be built.
    #[error(transparent)]
    World(#[from] WorldError),
    /// A scan could not be built (a bug: the geometry is validated beforehand).
    #[error("building a scan")]
    Scan(#[from] ScanError),
}

/// Figures of a finished (or running) drive, from every physics step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveStats {
    /// Simulated time so far (s).
    pub sim_seconds: f64,
    /// Physics steps so far.
    pub steps: u64,
    /// Distance the robot's true position travelled, summed over physics steps (m).
    pub path_length_m: f64,
    /// Whether the robot reached the route's last waypoint.
    pub route_completed: bool,
    /// Physics steps during which the robot touched an obstacle.
    pub contact_steps: u64,
    /// Smallest distance from the robot's centre to an obstacle surface over all steps (m).
    pub min_clearance_m: f64,
    /// Scans produced.
    pub scans: usize,
    /// Beams cast.
    pub beams: u64,
    /// Beams that hit something within range.
    pub returns: u64,
}

/// A running simulation; an iterator of records, one per laser sweep.
pub struct Simulation {
    cfg: SimConfig,
    world: World,
    physics: PhysicsWorld,
    robot: RigidBodyHandle,
    robot_collider: ColliderHandle,
    geometry: BeamGeometry,
    dt: f64,
    steps_per_scan: u64,
    /// Effective mass seen by one tyre along the heading, and sideways.
    wheel_mass: (f64, f64),
    /// Controller's rate-limited command (m/s, rad/s).
    command: (f64, f64),
    /// Left and right wheel rim speeds (m/s): what the encoders measure.
    wheels: [f64; 2],
    odometry: Pose2,
    target: usize,
    laser_noise: Noise,
    /// Where a beam returns inside foliage (drawn only for beams that enter a stand).
    foliage_noise: Noise,
    encoder_noise: Noise,
    stats: DriveStats,
    done: bool,
}

impl std::fmt::Debug for Simulation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulation")
            .field("world", &self.world.kind)
            .field("stats", &self.stats)
            .field("odometry", &self.odometry)
            .finish_non_exhaustive()
    }
}

fn vec2(x: f64, y: f64) -> Vector {
    Vector::new(x as Real, y as Real)
}

impl Simulation {
    /// Validates the configuration, builds the world and places the robot on the route's start.
    pub fn new(cfg: SimConfig) -> Result<Self, SimError> {
        cfg.validate()?;
        let world = World::build(&cfg)?;
        let l = &cfg.laser;
        let mut geometry = BeamGeometry::centered(l.beams, l.fov_deg.to_radians(), l.max_range);
        geometry.min_range = l.min_range;
        geometry.validate()?;

        let mut physics = PhysicsWorld::new();
        physics.gravity = Vector::ZERO;
        physics.integration_parameters.dt = (1.0 / cfg.drive.physics_hz) as Real;
        for o in &world.obstacles {
            let c = match *o {
                Obstacle::Circle { center, radius } => {
                    ColliderBuilder::ball(radius as Real).translation(vec2(center.x, center.y))
                }
                Obstacle::Rect {
                    center,
                    half,
                    angle,
                } => ColliderBuilder::cuboid(half.x as Real, half.y as Real)
                    .translation(vec2(center.x, center.y))
                    .rotation(angle as Real),
            };
            physics.insert_collider(c, None);
        }
        let start = start_pose(&world);
        let r = &cfg.robot;
        let body = RigidBodyBuilder::dynamic()
            .translation(vec2(start.x, start.y))
            .rotation(start.theta as Real)
            .can_sleep(false);
        let collider =
            ColliderBuilder::cuboid((r.size[0] / 2.0) as Real, (r.size[1] / 2.0) as Real)
                .mass(r.mass as Real)
                .friction(0.5);
        let (robot, robot_collider) = physics.insert(body, collider);
        // Put the static colliders into the broad phase so the first scan sees them.
        physics.detect_collisions(&(), &());

        let inertia = r.mass * (r.size[0].powi(2) + r.size[1].powi(2)) / 12.0;
        let half_base = r.wheel_base / 2.0;
        let wheel_mass = (
            1.0 / (1.0 / r.mass + half_base * half_base / inertia),
            r.mass / 2.0,
        );
        let dt = 1.0 / cfg.drive.physics_hz;
        let steps_per_scan = (cfg.drive.physics_hz / cfg.laser.rate_hz).round().max(1.0) as u64;
        let seed = cfg.drive.seed;
        Ok(Self {
            world,
            physics,
            robot,
            robot_collider,
            geometry,
            dt,
            steps_per_scan,
            wheel_mass,
            command: (0.0, 0.0),
            wheels: [0.0, 0.0],
            odometry: start,
            target: 1,
            laser_noise: Noise::new(seed, 0x6c61736572),
            foliage_noise: Noise::new(seed, 0x666f6c69616765),
            encoder_noise: Noise::new(seed, 0x656e636f646572),
            stats: DriveStats {
                min_clearance_m: f64::INFINITY,
                ..DriveStats::default()
            },
            done: false,
            cfg,
        })
    }

    /// Builds the simulation from a configuration and runs the whole drive.
    pub fn run(cfg: SimConfig) -> Result<(Vec<Record>, DriveStats, World), SimError> {
        let mut sim = Simulation::new(cfg)?;
        let records = sim.by_ref().collect::<Result<Vec<_>, _>>()?;
        Ok((records, sim.stats, sim.world))
    }

    /// The world being driven through.
    #[must_use]
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The effective configuration.
    #[must_use]
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Figures of the drive so far.
    #[must_use]
    pub fn stats(&self) -> DriveStats {
        self.stats
    }

    /// The laser's beam layout.
    #[must_use]
    pub fn beam_geometry(&self) -> BeamGeometry {
        self.geometry
    }

    /// The robot's true pose now.
    #[must_use]
    pub fn true_pose(&self) -> Pose2 {
        let b = &self.physics.bodies[self.robot];
        let t = b.translation();
        Pose2::new(t.x as f64, t.y as f64, b.rotation().angle() as f64)
    }

    /// The robot's pose by odometry now.
    #[must_use]
    pub fn odometry(&self) -> Pose2 {
        self.odometry
    }

    /// The noise-free range along one ray from `origin` at world bearing `angle`: the distance
    /// to the first static obstacle, or `None` when nothing lies within `max_range`. Foliage,
    /// which returns a beam at a random depth, is not seen here ([`Self::scan_now`] sees it).
    #[must_use]
    pub fn cast_ray(&self, origin: (f64, f64), angle: f64, max_range: f64) -> Option<f64> {
        let q = self
            .physics
            .query_pipeline_with_filter(QueryFilter::only_fixed());
        let (s, c) = angle.sin_cos();
        let ray = Ray::new(vec2(origin.0, origin.1), vec2(c, s));
        q.cast_ray(&ray, max_range as Real, true)
            .map(|(_, toi)| toi as f64)
    }

    /// One sweep of the laser from the robot's current true pose (noise included): each beam
    /// returns from the first solid surface or from a leaf inside foliage in front of it
    /// ([`crate::Foliage`]).
    pub fn scan_now(&mut self) -> Result<Scan, SimError> {
        let laser = self.true_pose() * Pose2::new(self.cfg.laser.offset_x, 0.0, 0.0);
        let g = self.geometry;
        let sigma = self.cfg.laser.range_sigma;
        let q = self
            .physics
            .query_pipeline_with_filter(QueryFilter::only_fixed());
        let origin = vec2(laser.x, laser.y);
        let at = nalgebra::Point2::new(laser.x, laser.y);
        let mut ranges = Vec::with_capacity(self.cfg.laser.beams);
        for i in 0..self.cfg.laser.beams {
            let (s, c) = (laser.theta + g.angle(i)).sin_cos();
            let ray = Ray::new(origin, vec2(c, s));
            let solid = q
                .cast_ray(&ray, g.max_range as Real, true)
                .map(|(_, toi)| toi as f64);
            // Foliage in front of the first solid surface may return the beam first: each
            // stand crossed draws its leaf's distance from its own stream, so a world without
            // foliage draws nothing and scans as it did.
            let mut hit = solid;
            for f in &self.world.foliage {
                let reach = hit.unwrap_or(g.max_range);
                let Some((t_in, t_out)) = f.crossing(&at, &nalgebra::Vector2::new(c, s)) else {
                    continue;
                };
                if t_in >= reach {
                    continue;
                }
                let depth = self.foliage_noise.exponential(f.mean_free_path);
                let t = t_in + depth;
                if t < t_out && t < reach {
                    hit = Some(t);
                }
            }
            let r = match hit {
                Some(toi) => {
                    let noisy = toi + sigma * self.laser_noise.gaussian();
                    noisy.clamp(0.0, g.max_range)
                }
                // No return: report max_range itself, which readers mark as invalid.
                None => g.max_range,
            };
            if r < g.max_range {
                self.stats.returns += 1;
            }
            ranges.push(r);
        }
        self.stats.beams += ranges.len() as u64;
        self.stats.scans += 1;
        Ok(Scan::new(self.stats.sim_seconds, g, ranges)?)
    }

    fn record(&mut self) -> Result<Record, SimError> {
        let scan = self.scan_now()?;
        Ok(Record {
            scan,
            odometry: self.odometry,
            truth: Some(self.true_pose()),
            laser_offset: Pose2::new(self.cfg.laser.offset_x, 0.0, 0.0),
        })
    }

    /// The waypoint controller on the true pose: desired (v, ω).
    fn control(&mut self, pose: &Pose2) -> (f64, f64) {
        let d = &self.cfg.drive;
        let route = &self.world.route;
        while self.target < route.len() {
            let last = self.target + 1 == route.len();
            let t = route[self.target];
            let dist = (t.x - pose.x).hypot(t.y - pose.y);
            let tol = if last {
                d.waypoint_tolerance.min(0.15)
            } else {
                d.waypoint_tolerance
            };
            if dist >= tol {
                break;
            }
            self.target += 1;
        }
        if self.target >= route.len() {
            self.stats.route_completed = true;
            return (0.0, 0.0);
        }
        let t = route[self.target];
        let (dx, dy) = (t.x - pose.x, t.y - pose.y);
        let alpha = normalize_angle(dy.atan2(dx) - pose.theta);
        let w_max = d.turn_rate_deg.to_radians();
        let w = (2.0 * alpha).clamp(-w_max, w_max);
        // Drive while roughly facing the waypoint, turn on the spot otherwise.
        let mut v = if alpha.abs() < 60f64.to_radians() {
            d.speed * alpha.cos()
        } else {
            0.0
        };
        if self.target + 1 == route.len() {
            // Come to rest on the last waypoint.
            v = v.min((d.accel * dx.hypot(dy)).sqrt()).min(dx.hypot(dy));
        }
        (v, w)
    }

    /// One physics step.
    fn step(&mut self) {
        let dt = self.dt;
        let pose = self.true_pose();
        let (v_des, w_des) = self.control(&pose);
        let d = &self.cfg.drive;
        let r = &self.cfg.robot;
        let a_max = d.accel * dt;
        let aw_max = d.angular_accel_deg.to_radians() * dt;
        self.command.0 += (v_des - self.command.0).clamp(-a_max, a_max);
        self.command.1 += (w_des - self.command.1).clamp(-aw_max, aw_max);

        // Motors: wheel rims follow the command, limited in speed and acceleration.
        let half_base = r.wheel_base / 2.0;
        let (v, w) = self.command;
        let mut want = [v - w * half_base, v + w * half_base];
        let peak = want[0].abs().max(want[1].abs());
        if peak > r.max_wheel_speed {
            let k = r.max_wheel_speed / peak;
            want = [want[0] * k, want[1] * k];
        }
        let acc = r.max_wheel_accel * dt;
        for (rim, want) in self.wheels.iter_mut().zip(want) {
            *rim += (want - *rim).clamp(-acc, acc);
        }

        // Encoders: rim travel, scaled by the systematic error, plus random walk noise.
        let mut travel = [0.0; 2];
        for (j, t) in travel.iter_mut().enumerate() {
            let s = self.wheels[j] * dt;
            *t = s * (1.0 + r.encoder_bias[j]);
            if r.encoder_noise > 0.0 {
                *t += r.encoder_noise * s.abs().sqrt() * self.encoder_noise.gaussian();
            }
        }
        let ds = (travel[0] + travel[1]) / 2.0;
        let dth = (travel[1] - travel[0]) / r.wheel_base;
        let (hs, hc) = (dth / 2.0).sin_cos();
        self.odometry = self.odometry * Pose2::new(ds * hc, ds * hs, dth);

        // Tyres.
        let mu_n = r.ground_friction * r.mass * G / 2.0;
        let rr_n = r.rolling_resistance * r.mass * G / 2.0;
        let body = &mut self.physics.bodies[self.robot];
        let lin = body.linvel();
        let (lin_x, lin_y, omega) = (lin.x as f64, lin.y as f64, body.angvel() as f64);
        let (s, c) = pose.theta.sin_cos();
        let v_fwd = lin_x * c + lin_y * s;
        let v_lat = -lin_x * s + lin_y * c;
        body.reset_forces(false);
        body.reset_torques(false);
        for (j, side) in [(0usize, 1.0f64), (1, -1.0)] {
            // Left wheel at +half_base along the body's y axis, right at −half_base.
            let ground = v_fwd - side * omega * half_base;
            let rim = self.wheels[j];
            let scale = r.tyre_slip * rim.abs().max(ground.abs()).max(0.1);
            let mut f_long = tyre_force(rim - ground, mu_n, scale, dt / self.wheel_mass.0);
            let mut f_lat = tyre_force(-v_lat, mu_n, scale, dt / self.wheel_mass.1);
            let total = f_long.hypot(f_lat);
            if total > mu_n {
                f_long *= mu_n / total;
                f_lat *= mu_n / total;
            }
            let f_long = f_long - rr_n * (ground / 0.02).tanh();
            let force = vec2(f_long * c - f_lat * s, f_long * s + f_lat * c);
            let at = vec2(pose.x - side * s * half_base, pose.y + side * c * half_base);
            body.add_force_at_point(force, at, true);
        }
        self.physics.step();
        self.stats.steps += 1;
        self.stats.sim_seconds = self.stats.steps as f64 * dt;

        let now = self.true_pose();
        self.stats.path_length_m += now.distance(&pose);
        let clearance = self
            .world
            .signed_distance(&nalgebra::Point2::new(now.x, now.y));
        self.stats.min_clearance_m = self.stats.min_clearance_m.min(clearance);
        if self
            .physics
            .narrow_phase
            .contact_pairs_with(self.robot_collider)
            .any(|p| p.has_any_active_contact())
        {
            self.stats.contact_steps += 1;
        }
    }

    fn at_rest(&self) -> bool {
        let b = &self.physics.bodies[self.robot];
        self.wheels.iter().all(|w| w.abs() < 1e-3) && b.linvel().length() < 0.01
    }
}

/// The force one tyre transmits, solved implicitly so that stiff tyres stay stable:
/// `F = µN · tanh(slip_after / scale)` with `slip_after = slip − F · compliance`, where
/// `compliance` is dt over the effective mass the tyre pushes. Newton on a monotone function.
fn tyre_force(slip: f64, mu_n: f64, scale: f64, compliance: f64) -> f64 {
    // g(F) = F − µN·tanh((slip − F·compliance)/scale) increases with F and changes sign on
    // [−µN, µN]: Newton steps, falling back to bisection whenever a step leaves the bracket.
    let g = |f: f64| {
        let th = ((slip - f * compliance) / scale).tanh();
        (
            f - mu_n * th,
            1.0 + mu_n * (1.0 - th * th) * compliance / scale,
        )
    };
    let (mut lo, mut hi) = (-mu_n, mu_n);
    let mut f = 0.0;
    for _ in 0..60 {
        let (gf, dg) = g(f);
        if gf.abs() <= 1e-9 * mu_n {
            break;
        }
        if gf > 0.0 {
            hi = f;
        } else {
            lo = f;
        }
        let newton = f - gf / dg;
        f = if newton > lo && newton < hi {
            newton
        } else {
            (lo + hi) / 2.0
        };
        if hi - lo <= 1e-9 * mu_n {
            break;
        }
    }
    f
}

/// The first waypoint, facing the second.
fn start_pose(world: &World) -> Pose2 {
    match world.route.as_slice() {
        [a, b, ..] => Pose2::new(a.x, a.y, (b.y - a.y).atan2(b.x - a.x)),
        [a] => Pose2::new(a.x, a.y, 0.0),
        [] => Pose2::IDENTITY,
    }
}

impl Iterator for Simulation {
    type Item = Result<Record, SimError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if self.stats.scans > 0 {
            // Advance to the next laser time.
            for _ in 0..self.steps_per_scan {
                self.step();
            }
        }
        let record = self.record();
        let limit = self
            .cfg
            .drive
            .max_scans
            .is_some_and(|m| self.stats.scans >= m);
        let finished = self.stats.route_completed && self.at_rest();
        let timeout = self.stats.sim_seconds >= self.cfg.drive.timeout_s;
        if record.is_err() || limit || finished || timeout {
            self.done = true;
        }
        Some(record)
    }
}
