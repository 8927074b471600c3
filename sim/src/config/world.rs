//! `[world]`: the world kind, its procedural layouts (`[world.park]`, `[world.corridor]`)
//! and explicit obstacles.

use serde::{Deserialize, Serialize};

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
    /// Width and height of the park (m), each at most [`MAX_WORLD_SIZE`](super::MAX_WORLD_SIZE).
    /// Default 80 × 40.
    pub size: [f64; 2],
    /// Number of trees. Default 12.
    pub trees: usize,
    /// Smallest and largest trunk radius (m). Default 0.15–0.5.
    pub tree_radius: [f64; 2],
    /// Number of rocks (round, 0.3–0.8 m). Default 3.
    pub rocks: usize,
    /// Number of benches (1.6 × 0.5 m boxes). Default 2.
    pub benches: usize,
    /// Number of hedges: stands of foliage 3-10 m long and 1-2 m deep, turned at random,
    /// which the laser sees into ([`ObstacleConfig::Foliage`]). Default 0.
    pub hedges: usize,
    /// Mean distance a beam travels into a hedge before it returns (m). Default 0.3.
    pub hedge_mean_free_path: f64,
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
            hedges: 0,
            hedge_mean_free_path: 0.3,
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
    /// Outer size of the floor (m), each side at most
    /// [`MAX_WORLD_SIZE`](super::MAX_WORLD_SIZE). Default 30 × 30.
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
    /// Wall thickness (m), below half the corridor's width. Default 0.1.
    pub wall_thickness: f64,
    /// Distance along the corridor between zigzag turning points (m), at least
    /// [`MIN_ZIGZAG_PERIOD`](super::MIN_ZIGZAG_PERIOD). Default 3.
    pub zigzag_period: f64,
    /// Sideways offset of the zigzag turning points from the corridor centre (m). Default 0.5.
    pub zigzag_amplitude: f64,
    /// Largest shift of a doorway along its wall from the middle of its room (m), drawn for
    /// each doorway from the world's seed; the doorway stays inside its room. Default 0: every
    /// doorway in the middle, one layout whatever the seed.
    pub door_offset: f64,
    /// Chance that a doorway is closed, its wall running on unbroken, drawn for each doorway
    /// from the world's seed (0 to 1). Default 0.
    pub closed_doors: f64,
    /// Most pieces of furniture in a room: each room holds 0 to this many boxes, 0.4-1.6 m
    /// along the corridor by 0.4-0.8 m, placed in it at random from the world's seed (at most
    /// [`MAX_FURNITURE`](super::MAX_FURNITURE)). Default 0.
    pub furniture: usize,
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
            door_offset: 0.0,
            closed_doors: 0.0,
            furniture: 0,
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
    /// A stand of foliage (a hedge, a bush): a rectangle, rotated by `angle_deg` about its
    /// centre, that the laser sees into. A beam that enters it returns after a distance drawn
    /// from an exponential distribution of mean `mean_free_path` (m), or passes on when it
    /// leaves the stand first, so the leaves return another surface at every scan. It stops
    /// no robot: keep the route out of it.
    Foliage {
        /// Centre (m).
        center: [f64; 2],
        /// Half width and half height (m).
        half_size: [f64; 2],
        /// Rotation (degrees, counter-clockwise).
        #[serde(default)]
        angle_deg: f64,
        /// Mean distance a beam travels inside the stand before it returns (m).
        mean_free_path: f64,
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
