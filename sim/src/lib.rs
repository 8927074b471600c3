//! # qicp-sim
//!
//! A 2D robot simulator on rapier2d, so every matcher can be scored against ground truth:
//! a park drive (sparse trees, slippery grass, poor odometry) and an office corridor the robot
//! zigzags through, as in the experiments of Slamet, Visser & Pfingsthorn.
//!
//! ```no_run
//! use qicp_sim::{SimConfig, Simulation};
//! let cfg = SimConfig::load("configs/worlds/park.toml".as_ref())?;
//! for record in Simulation::new(cfg)? {
//!     let record = record?;
//!     println!("{} {:?} {:?}", record.timestamp(), record.odometry, record.truth);
//! }
//! # Ok::<(), qicp_sim::SimError>(())
//! ```
//!
//! - [`config`]: the TOML schema (`[world]`, `[robot]`, `[laser]`, `[drive]`), defaults and
//!   validation;
//! - [`world`]: obstacle geometry and routes, procedural for `park` and `corridor`;
//! - [`sim`]: the physics (slipping tyres, encoders, controller, laser) as an iterator of
//!   [`qicp_core::Record`]s;
//! - [`metrics`]: odometry drift against the truth; [`render`]: `world.png`.
#![warn(missing_docs)]

pub mod config;
pub mod metrics;
pub mod noise;
pub mod render;
pub mod sim;
pub mod world;

pub use config::{ConfigError, SimConfig, WorldKind};
pub use metrics::DriveScores;
pub use sim::{DriveStats, SimError, Simulation};
pub use world::{Foliage, Obstacle, World, WorldError};

/// A stable 64-bit digest (FNV-1a) of records: timestamps, poses and raw ranges, bit for bit.
/// The golden determinism test pins it.
#[must_use]
pub fn digest(records: &[qicp_core::Record]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |v: f64| {
        for b in v.to_bits().to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for r in records {
        eat(r.timestamp());
        for p in std::iter::once(r.odometry).chain(r.truth) {
            eat(p.x);
            eat(p.y);
            eat(p.theta);
        }
        for &x in r.scan.ranges() {
            eat(x);
        }
    }
    h
}
