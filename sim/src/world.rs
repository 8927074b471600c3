//! World geometry: obstacles (circles and rotated rectangles; walls are thin rectangles),
//! foliage the laser sees into, and the route through them, built from a [`SimConfig`] —
//! procedurally for `park` and `corridor`.
//!
//! The same geometry feeds rapier (static colliders), the drawing of `world.png` and the exact
//! signed distance used by the tests.

use crate::config::{CorridorConfig, ObstacleConfig, ParkConfig, SimConfig, WorldKind};
use crate::noise::Noise;
use nalgebra::{Point2, Vector2};
use thiserror::Error;

/// Why a world could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum WorldError {
    /// Procedural placement gave up: the area is too crowded for the requested obstacles.
    #[error(
        "`world.park.{what}`: could only place {placed} of {wanted} {what} clear of the route; lower their number or world.park.route_clearance"
    )]
    Crowded {
        /// Which obstacles.
        what: &'static str,
        /// How many fit.
        placed: usize,
        /// How many were asked for.
        wanted: usize,
    },
}

/// One static obstacle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Obstacle {
    /// A round post, trunk or rock.
    Circle {
        /// Centre (m).
        center: Point2<f64>,
        /// Radius (m).
        radius: f64,
    },
    /// A rectangle (bench, wall), rotated by `angle` about its centre.
    Rect {
        /// Centre (m).
        center: Point2<f64>,
        /// Half extents along the rectangle's own axes (m).
        half: Vector2<f64>,
        /// Rotation (rad, counter-clockwise).
        angle: f64,
    },
}

impl Obstacle {
    /// A wall along the centre line `a`–`b`, extended by half its thickness at both ends so
    /// that walls meeting at a corner close it.
    #[must_use]
    pub fn wall(a: Point2<f64>, b: Point2<f64>, thickness: f64) -> Self {
        let d = b - a;
        Obstacle::Rect {
            center: a + d / 2.0,
            half: Vector2::new(d.norm() / 2.0 + thickness / 2.0, thickness / 2.0),
            angle: d.y.atan2(d.x),
        }
    }

    /// Signed distance from `p` to the obstacle's surface: negative inside.
    #[must_use]
    pub fn signed_distance(&self, p: &Point2<f64>) -> f64 {
        match *self {
            Obstacle::Circle { center, radius } => (p - center).norm() - radius,
            Obstacle::Rect {
                center,
                half,
                angle,
            } => {
                let (s, c) = angle.sin_cos();
                let d = p - center;
                let q = Vector2::new(c * d.x + s * d.y, -s * d.x + c * d.y);
                let e = Vector2::new(q.x.abs() - half.x, q.y.abs() - half.y);
                let outside = Vector2::new(e.x.max(0.0), e.y.max(0.0)).norm();
                outside + e.x.max(e.y).min(0.0)
            }
        }
    }

    /// Radius of the smallest circle about the centre that holds the obstacle.
    #[must_use]
    pub fn bounding_radius(&self) -> f64 {
        match *self {
            Obstacle::Circle { radius, .. } => radius,
            Obstacle::Rect { half, .. } => half.norm(),
        }
    }

    /// The centre.
    #[must_use]
    pub fn center(&self) -> Point2<f64> {
        match *self {
            Obstacle::Circle { center, .. } | Obstacle::Rect { center, .. } => center,
        }
    }

    /// Corners of a rectangle, counter-clockwise; empty for a circle.
    #[must_use]
    pub fn corners(&self) -> Vec<Point2<f64>> {
        match *self {
            Obstacle::Circle { .. } => Vec::new(),
            Obstacle::Rect {
                center,
                half,
                angle,
            } => {
                let (s, c) = angle.sin_cos();
                [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
                    .iter()
                    .map(|&(sx, sy)| {
                        let (x, y) = (sx * half.x, sy * half.y);
                        center + Vector2::new(c * x - s * y, s * x + c * y)
                    })
                    .collect()
            }
        }
    }

    /// The solid obstacle `o` describes; `None` for foliage ([`Foliage::from_config`]).
    fn from_config(o: &ObstacleConfig) -> Option<Self> {
        Some(match *o {
            ObstacleConfig::Circle { center, radius } => Obstacle::Circle {
                center: Point2::new(center[0], center[1]),
                radius,
            },
            ObstacleConfig::Box {
                center,
                half_size,
                angle_deg,
            } => Obstacle::Rect {
                center: Point2::new(center[0], center[1]),
                half: Vector2::new(half_size[0], half_size[1]),
                angle: angle_deg.to_radians(),
            },
            ObstacleConfig::Wall { a, b, thickness } => {
                Obstacle::wall(Point2::new(a[0], a[1]), Point2::new(b[0], b[1]), thickness)
            }
            ObstacleConfig::Foliage { .. } => return None,
        })
    }
}

/// A stand of foliage (`kind = "foliage"` in `[[world.obstacles]]`): a rotated rectangle the
/// laser sees into, one leaf at a time. A beam that enters it returns after a distance drawn
/// from an exponential distribution of mean `mean_free_path`, or passes on where it leaves the
/// stand first (a Poisson process of leaves along the beam). It is no collider: the robot
/// drives through it, and the route should not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Foliage {
    /// Centre (m).
    pub center: Point2<f64>,
    /// Half extents along the stand's own axes (m).
    pub half: Vector2<f64>,
    /// Rotation (rad, counter-clockwise).
    pub angle: f64,
    /// Mean distance a beam travels inside before it returns (m).
    pub mean_free_path: f64,
}

impl Foliage {
    /// Where the ray from `origin` along the unit vector `dir` runs inside the stand: the
    /// distances at which it enters (0 when it starts inside) and leaves, or `None` when it
    /// misses it or has it behind.
    #[must_use]
    pub fn crossing(&self, origin: &Point2<f64>, dir: &Vector2<f64>) -> Option<(f64, f64)> {
        let (s, c) = self.angle.sin_cos();
        // Origin and direction in the stand's own frame (slab test per axis).
        let d = origin - self.center;
        let o = [c * d.x + s * d.y, -s * d.x + c * d.y];
        let v = [c * dir.x + s * dir.y, -s * dir.x + c * dir.y];
        let half = [self.half.x, self.half.y];
        let (mut t_in, mut t_out) = (0.0_f64, f64::INFINITY);
        for k in 0..2 {
            if v[k] == 0.0 {
                if o[k].abs() > half[k] {
                    return None;
                }
                continue;
            }
            let (a, b) = ((-half[k] - o[k]) / v[k], (half[k] - o[k]) / v[k]);
            t_in = t_in.max(a.min(b));
            t_out = t_out.min(a.max(b));
        }
        (t_in < t_out).then_some((t_in, t_out))
    }

    /// The stand `o` describes; `None` for a solid obstacle.
    fn from_config(o: &ObstacleConfig) -> Option<Self> {
        match *o {
            ObstacleConfig::Foliage {
                center,
                half_size,
                angle_deg,
                mean_free_path,
            } => Some(Foliage {
                center: Point2::new(center[0], center[1]),
                half: Vector2::new(half_size[0], half_size[1]),
                angle: angle_deg.to_radians(),
                mean_free_path,
            }),
            _ => None,
        }
    }

    /// The stand's outline as a rectangle, for drawing and bounds.
    #[must_use]
    pub fn outline(&self) -> Obstacle {
        Obstacle::Rect {
            center: self.center,
            half: self.half,
            angle: self.angle,
        }
    }
}

/// The static world and the route to drive through it.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    /// Which kind of world.
    pub kind: WorldKind,
    /// Every static obstacle.
    pub obstacles: Vec<Obstacle>,
    /// Foliage the laser sees into ([`Foliage`]); no obstacle to the robot.
    pub foliage: Vec<Foliage>,
    /// Waypoints of the route; the robot starts on the first, facing the second.
    pub route: Vec<Point2<f64>>,
    /// Lower-left and upper-right corners of the area of interest (for drawing).
    pub bounds: (Point2<f64>, Point2<f64>),
}

impl World {
    /// Builds the world described by the configuration (which must be valid).
    pub fn build(cfg: &SimConfig) -> Result<World, WorldError> {
        let robot_radius = Vector2::new(cfg.robot.size[0], cfg.robot.size[1]).norm() / 2.0;
        let mut world = match cfg.world.kind {
            WorldKind::Park => park(&cfg.park(), cfg.world.seed, robot_radius)?,
            WorldKind::Corridor => corridor(&cfg.corridor(), cfg.world.seed),
            WorldKind::Custom => World {
                kind: WorldKind::Custom,
                obstacles: Vec::new(),
                foliage: Vec::new(),
                route: Vec::new(),
                bounds: (Point2::origin(), Point2::origin()),
            },
        };
        world
            .obstacles
            .extend(cfg.world.obstacles.iter().filter_map(Obstacle::from_config));
        world
            .foliage
            .extend(cfg.world.obstacles.iter().filter_map(Foliage::from_config));
        if let Some(w) = &cfg.drive.waypoints {
            world.route = w.iter().map(|p| Point2::new(p[0], p[1])).collect();
        }
        if world.kind == WorldKind::Custom {
            let outlines: Vec<Obstacle> = (world.obstacles.iter().copied())
                .chain(world.foliage.iter().map(Foliage::outline))
                .collect();
            world.bounds = bounding_box(&outlines, &world.route, 2.0);
        }
        Ok(world)
    }

    /// Signed distance from `p` to the nearest obstacle surface (negative inside one);
    /// infinite in an empty world.
    #[must_use]
    pub fn signed_distance(&self, p: &Point2<f64>) -> f64 {
        self.obstacles
            .iter()
            .map(|o| o.signed_distance(p))
            .fold(f64::INFINITY, f64::min)
    }

    /// Length of the route's polyline (m).
    #[must_use]
    pub fn route_length(&self) -> f64 {
        self.route.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }
}

fn bounding_box(
    obstacles: &[Obstacle],
    route: &[Point2<f64>],
    margin: f64,
) -> (Point2<f64>, Point2<f64>) {
    let mut lo = Point2::new(f64::INFINITY, f64::INFINITY);
    let mut hi = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
    let mut grow = |p: Point2<f64>, r: f64| {
        lo = Point2::new(lo.x.min(p.x - r), lo.y.min(p.y - r));
        hi = Point2::new(hi.x.max(p.x + r), hi.y.max(p.y + r));
    };
    for o in obstacles {
        grow(o.center(), o.bounding_radius());
    }
    for p in route {
        grow(*p, 0.0);
    }
    if !lo.x.is_finite() {
        return (Point2::new(-1.0, -1.0), Point2::new(1.0, 1.0));
    }
    (
        lo - Vector2::new(margin, margin),
        hi + Vector2::new(margin, margin),
    )
}

/// Distance from `p` to the segment `a`–`b`.
#[must_use]
pub fn distance_to_segment(p: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

fn distance_to_polyline(p: &Point2<f64>, line: &[Point2<f64>]) -> f64 {
    line.windows(2)
        .map(|w| distance_to_segment(p, &w[0], &w[1]))
        .fold(f64::INFINITY, f64::min)
}

/// The park: a clockwise loop from the bottom-right corner, wiggling sideways, with trees,
/// rocks and benches placed at random but clear of the route.
fn park(p: &ParkConfig, seed: u64, robot_radius: f64) -> Result<World, WorldError> {
    let mut rng = Noise::new(seed, 0x7061726b);
    let [w, h] = p.size;
    let m = p.route_margin;
    // Clockwise (seen from above, y up): bottom-right → bottom-left → top-left → top-right.
    let corners = [
        Point2::new(w - m, m),
        Point2::new(m, m),
        Point2::new(m, h - m),
        Point2::new(w - m, h - m),
        Point2::new(w - m, m),
    ];
    let mut route = vec![corners[0]];
    for side in corners.windows(2) {
        let (a, b) = (side[0], side[1]);
        let len = (b - a).norm();
        let n = (len / 8.0).round().max(1.0) as usize;
        let dir = (b - a) / len;
        let normal = Vector2::new(-dir.y, dir.x);
        for k in 1..n {
            let along = a + (b - a) * (k as f64 / n as f64);
            let off = rng.uniform(-p.route_wiggle, p.route_wiggle);
            route.push(along + normal * off);
        }
        route.push(b);
    }

    let mut obstacles: Vec<Obstacle> = Vec::new();
    let keep_clear = p.route_clearance + robot_radius;
    let mut place = |obstacles: &mut Vec<Obstacle>,
                     what: &'static str,
                     wanted: usize,
                     make: &mut dyn FnMut(&mut Noise, Point2<f64>) -> Obstacle|
     -> Result<(), WorldError> {
        let mut placed = 0;
        let mut tries = 0;
        while placed < wanted {
            tries += 1;
            if tries > 20_000 {
                return Err(WorldError::Crowded {
                    what,
                    placed,
                    wanted,
                });
            }
            let c = Point2::new(rng.uniform(0.0, w), rng.uniform(0.0, h));
            let o = make(&mut rng, c);
            let r = o.bounding_radius();
            if distance_to_polyline(&c, &route) < keep_clear + r {
                continue;
            }
            // Keep obstacles apart so the laser sees them as separate objects.
            if obstacles
                .iter()
                .any(|q| (q.center() - c).norm() < q.bounding_radius() + r + 2.0)
            {
                continue;
            }
            obstacles.push(o);
            placed += 1;
        }
        Ok(())
    };
    let [r0, r1] = p.tree_radius;
    place(&mut obstacles, "trees", p.trees, &mut |rng, c| {
        Obstacle::Circle {
            center: c,
            radius: rng.uniform(r0, r1),
        }
    })?;
    place(&mut obstacles, "rocks", p.rocks, &mut |rng, c| {
        Obstacle::Circle {
            center: c,
            radius: rng.uniform(0.3, 0.8),
        }
    })?;
    place(&mut obstacles, "benches", p.benches, &mut |rng, c| {
        Obstacle::Rect {
            center: c,
            half: Vector2::new(0.8, 0.25),
            angle: rng.uniform(0.0, std::f64::consts::PI),
        }
    })?;
    // Hedges last, so that a park without them is laid out as before. They are placed as
    // their outlines, clear of the route and of everything else, then become foliage.
    let solids = obstacles.len();
    place(&mut obstacles, "hedges", p.hedges, &mut |rng, c| {
        Obstacle::Rect {
            center: c,
            half: Vector2::new(rng.uniform(1.5, 5.0), rng.uniform(0.5, 1.0)),
            angle: rng.uniform(0.0, std::f64::consts::PI),
        }
    })?;
    let foliage = obstacles
        .drain(solids..)
        .filter_map(|o| match o {
            Obstacle::Rect {
                center,
                half,
                angle,
            } => Some(Foliage {
                center,
                half,
                angle,
                mean_free_path: p.hedge_mean_free_path,
            }),
            Obstacle::Circle { .. } => None,
        })
        .collect();
    Ok(World {
        kind: WorldKind::Park,
        obstacles,
        foliage,
        route,
        bounds: (Point2::origin(), Point2::new(w, h)),
    })
}

/// Maps (along, depth, floor width, floor height) of one side of the floor to a point.
type SideMap = fn(f64, f64, f64, f64) -> Point2<f64>;

/// The office floor. Seen from the outside in, each side of the floor has: the outer wall, a
/// row of outer rooms, the corridor (between its outer and inner wall, both with one doorway
/// per room), a row of inner rooms and the wall of a closed core. The route runs
/// counter-clockwise along the corridor, zigzagging between its walls.
fn corridor(c: &CorridorConfig, seed: u64) -> World {
    let [w, h] = c.size;
    let (o, cw, i, t) = (
        c.outer_room_depth,
        c.corridor_width,
        c.inner_room_depth,
        c.wall_thickness,
    );
    // The layout's draws (doorways, furniture); none where the config asks for no variation,
    // so the default floor is one layout whatever the seed.
    let mut rng = Noise::new(seed, 0x6f6666696365);
    // Side frames: `u` runs along the side (counter-clockwise), `d` is the depth from the
    // floor's edge inwards.
    let sides: [(f64, SideMap); 4] = [
        (w, |u, d, _w, _h| Point2::new(u, d)),
        (h, |u, d, w, _h| Point2::new(w - d, u)),
        (w, |u, d, w, h| Point2::new(w - u, h - d)),
        (h, |u, d, _w, h| Point2::new(d, h - u)),
    ];
    let mut obstacles = Vec::new();
    let mut route = Vec::new();
    let centre = o + cw / 2.0;
    for (len, map) in sides {
        let at = |u: f64, d: f64| map(u, d, w, h);
        let mut walls = Vec::new();
        let mut wall = |u0: f64, u1: f64, d: f64, doors: &[f64]| {
            // Split the wall at each doorway.
            let mut start = u0;
            for &door in doors {
                let (g0, g1) = (door - c.door_width / 2.0, door + c.door_width / 2.0);
                if g0 - start > 1e-3 {
                    walls.push(Obstacle::wall(at(start, d), at(g0, d), t));
                }
                start = g1;
            }
            if u1 - start > 1e-3 {
                walls.push(Obstacle::wall(at(start, d), at(u1, d), t));
            }
        };
        // Outer wall of the floor.
        wall(0.0, len, 0.0, &[]);
        // Outer rooms: between the floor's edge and the corridor, one doorway each.
        let outer = Rooms::along(o, len - o, c.room_width, (0.0, o));
        wall(o, len - o, o, &outer.doors(c, &mut rng));
        // Inner rooms: between the corridor and the core.
        let inner = Rooms::along(
            o + cw + i,
            len - o - cw - i,
            c.room_width,
            (o + cw, o + cw + i),
        );
        wall(o + cw, len - o - cw, o + cw, &inner.doors(c, &mut rng));
        wall(inner.start, inner.end, o + cw + i, &[]);
        for rooms in [&outer, &inner] {
            for k in 0..=rooms.count {
                let u = rooms.start + rooms.step * k as f64;
                walls.push(Obstacle::wall(
                    at(u, rooms.depth.0),
                    at(u, rooms.depth.1),
                    t,
                ));
            }
            walls.extend(rooms.furniture(c, &mut rng, &at));
        }
        obstacles.append(&mut walls);
        // Zigzag along this side of the corridor, from corner to corner.
        let (a, b) = (centre, len - centre);
        let n = ((b - a) / (c.zigzag_period / 2.0)).round().max(2.0) as usize;
        for k in 0..n {
            let u = a + (b - a) * k as f64 / n as f64;
            let off = if k == 0 {
                0.0
            } else if k % 2 == 1 {
                c.zigzag_amplitude
            } else {
                -c.zigzag_amplitude
            };
            route.push(at(u, centre + off));
        }
    }
    route.push(route[0]);
    World {
        kind: WorldKind::Corridor,
        obstacles,
        foliage: Vec::new(),
        route,
        bounds: (Point2::origin(), Point2::new(w, h)),
    }
}

/// One row of rooms along a side of the corridor, in the side's frame: `count` rooms of
/// `step` along it from `start` to `end`, each from depth `depth.0` to `depth.1`.
struct Rooms {
    start: f64,
    end: f64,
    step: f64,
    count: usize,
    depth: (f64, f64),
}

impl Rooms {
    /// Rooms from `a` to `b` about `width` wide each.
    fn along(a: f64, b: f64, width: f64, depth: (f64, f64)) -> Self {
        let count = ((b - a) / width).round().max(1.0) as usize;
        Self {
            start: a,
            end: b,
            step: (b - a) / count as f64,
            count,
            depth,
        }
    }

    /// Where each open doorway's middle lies along the corridor wall: the room's middle,
    /// shifted by up to `door_offset` within the room, and none where the door is closed.
    fn doors(&self, c: &CorridorConfig, rng: &mut Noise) -> Vec<f64> {
        // A doorway keeps clear of its room's partitions.
        let room = (self.step - c.door_width) / 2.0 - c.wall_thickness;
        let reach = c.door_offset.min(room.max(0.0));
        (0..self.count)
            .filter_map(|k| {
                let middle = self.start + self.step * (k as f64 + 0.5);
                let shift = if reach > 0.0 {
                    rng.uniform(-reach, reach)
                } else {
                    0.0
                };
                let closed = c.closed_doors > 0.0 && rng.uniform(0.0, 1.0) < c.closed_doors;
                (!closed).then_some(middle + shift)
            })
            .collect()
    }

    /// Furniture: 0 to `c.furniture` boxes in each room, square to its walls, clear of them.
    fn furniture(
        &self,
        c: &CorridorConfig,
        rng: &mut Noise,
        at: &dyn Fn(f64, f64) -> Point2<f64>,
    ) -> Vec<Obstacle> {
        let mut boxes = Vec::new();
        if c.furniture == 0 {
            return boxes;
        }
        // The direction along the side, in the world.
        let along = at(1.0, 0.0) - at(0.0, 0.0);
        let angle = along.y.atan2(along.x);
        let clear = c.wall_thickness / 2.0 + 0.05;
        for k in 0..self.count {
            let u0 = self.start + self.step * k as f64 + clear;
            let u1 = u0 + self.step - 2.0 * clear;
            let (d0, d1) = (self.depth.0 + clear, self.depth.1 - clear);
            let n = (rng.uniform(0.0, (c.furniture + 1) as f64) as usize).min(c.furniture);
            for _ in 0..n {
                let half = Vector2::new(rng.uniform(0.2, 0.8), rng.uniform(0.2, 0.4));
                let (u, d) = (rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0));
                if u1 - u0 <= 2.0 * half.x || d1 - d0 <= 2.0 * half.y {
                    continue;
                }
                boxes.push(Obstacle::Rect {
                    center: at(
                        u0 + half.x + u * (u1 - u0 - 2.0 * half.x),
                        d0 + half.y + d * (d1 - d0 - 2.0 * half.y),
                    ),
                    half,
                    angle,
                });
            }
        }
        boxes
    }
}
