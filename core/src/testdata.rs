//! Seeded point sets shared by the tests and the benchmarks.

use nalgebra::Point2;

/// A small deterministic generator (SplitMix64), so tests and benchmarks need no extra crate
/// and their data never changes between versions of a dependency.
#[derive(Debug, Clone)]
pub struct SplitMix(u64);

impl SplitMix {
    /// Seeded generator.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u = self.unit().max(1e-300);
        let v = self.unit();
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// `n` points uniform in a square of side `size` centred on the origin.
#[must_use]
pub fn uniform(n: usize, size: f64, seed: u64) -> Vec<Point2<f64>> {
    let mut r = SplitMix::new(seed);
    (0..n)
        .map(|_| {
            Point2::new(
                r.range(-size / 2.0, size / 2.0),
                r.range(-size / 2.0, size / 2.0),
            )
        })
        .collect()
}

/// Points as a laser sees them: a building of walls and posts scanned by 181-beam sweeps from
/// poses along a path, with 1 cm range noise. Clustered along lines, the realistic case.
#[must_use]
pub fn laser_scans(n: usize, seed: u64) -> Vec<Point2<f64>> {
    let mut r = SplitMix::new(seed);
    // Walls as segments (x0, y0, x1, y1) of a 40 m × 30 m floor with rooms, and round posts.
    let mut walls: Vec<[f64; 4]> = vec![
        [-20.0, -15.0, 20.0, -15.0],
        [20.0, -15.0, 20.0, 15.0],
        [20.0, 15.0, -20.0, 15.0],
        [-20.0, 15.0, -20.0, -15.0],
    ];
    for k in 0..8 {
        let x = -16.0 + 4.5 * k as f64;
        walls.push([x, 15.0, x + r.range(-0.3, 0.3), 7.0]);
        walls.push([x, -15.0, x + r.range(-0.3, 0.3), -7.0]);
    }
    let posts: Vec<(f64, f64, f64)> = (0..12)
        .map(|_| (r.range(-18.0, 18.0), r.range(-5.0, 5.0), r.range(0.1, 0.4)))
        .collect();
    let world = SyntheticWorld { walls, posts };
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let (ox, oy, heading) = (r.range(-17.0, 17.0), r.range(-5.5, 5.5), r.range(-3.2, 3.2));
        for b in 0..181 {
            if out.len() == n {
                break;
            }
            let a = heading - std::f64::consts::FRAC_PI_2 + b as f64 * std::f64::consts::PI / 180.0;
            let (dx, dy) = (a.cos(), a.sin());
            let best = world.cast(ox, oy, dx, dy, 30.0);
            if best < 30.0 {
                let range = best + 0.01 * r.normal();
                out.push(Point2::new(ox + range * dx, oy + range * dy));
            }
        }
    }
    out
}

/// A world of wall segments and round posts for synthetic scans with known geometry.
#[derive(Debug, Clone, Default)]
pub struct SyntheticWorld {
    /// Walls as `[x0, y0, x1, y1]`.
    pub walls: Vec<[f64; 4]>,
    /// Posts as `(x, y, radius)`.
    pub posts: Vec<(f64, f64, f64)>,
}

impl SyntheticWorld {
    /// A 10 m × 8 m room with a pillar, a cupboard and a doorway.
    #[must_use]
    pub fn room() -> Self {
        Self {
            walls: vec![
                [-5.0, -4.0, 5.0, -4.0],
                [5.0, -4.0, 5.0, 4.0],
                [5.0, 4.0, 1.0, 4.0],
                [0.0, 4.0, -5.0, 4.0],
                [-5.0, 4.0, -5.0, -4.0],
                [2.0, -4.0, 2.0, -3.0],
                [2.0, -3.0, 3.5, -3.0],
                [3.5, -3.0, 3.5, -4.0],
            ],
            posts: vec![(-2.0, 1.5, 0.3)],
        }
    }

    /// A corridor 2.4 m wide ending in a wall 13 m ahead, with a door recess on the right and
    /// a doorway into a room on the left: long walls, few features along its axis.
    #[must_use]
    pub fn corridor() -> Self {
        Self {
            walls: vec![
                // right wall with a door recess
                [-20.0, -1.2, -3.0, -1.2],
                [-3.0, -1.2, -3.0, -1.6],
                [-3.0, -1.6, -2.0, -1.6],
                [-2.0, -1.6, -2.0, -1.2],
                [-2.0, -1.2, 12.0, -1.2],
                // end wall
                [12.0, -1.2, 12.0, 1.2],
                // left wall with a doorway into a 3 m × 3 m room
                [-20.0, 1.2, 4.0, 1.2],
                [5.0, 1.2, 12.0, 1.2],
                [4.0, 1.2, 4.0, 4.2],
                [4.0, 4.2, 7.0, 4.2],
                [7.0, 4.2, 7.0, 1.2],
            ],
            posts: vec![],
        }
    }

    /// A long corridor with no feature at all along its axis.
    #[must_use]
    pub fn featureless_corridor() -> Self {
        Self {
            walls: vec![[-50.0, -1.2, 50.0, -1.2], [-50.0, 1.2, 50.0, 1.2]],
            posts: vec![],
        }
    }

    /// Sparse posts outdoors (the paper's park in miniature).
    #[must_use]
    pub fn posts() -> Self {
        Self {
            walls: vec![],
            posts: vec![
                (4.0, 1.0, 0.3),
                (6.0, -3.0, 0.45),
                (2.5, 4.0, 0.2),
                (9.0, 2.0, 0.35),
                (-1.0, -5.0, 0.25),
                (7.5, 6.0, 0.4),
            ],
        }
    }

    /// Range along a ray from `(ox, oy)` in direction `(dx, dy)` (unit), or `max_range`.
    #[must_use]
    pub fn cast(&self, ox: f64, oy: f64, dx: f64, dy: f64, max_range: f64) -> f64 {
        let mut best = max_range;
        for w in &self.walls {
            let (ex, ey) = (w[2] - w[0], w[3] - w[1]);
            let den = dx * ey - dy * ex;
            if den.abs() < 1e-12 {
                continue;
            }
            let t = ((w[0] - ox) * ey - (w[1] - oy) * ex) / den;
            let u = ((w[0] - ox) * dy - (w[1] - oy) * dx) / den;
            if t > 0.0 && (0.0..=1.0).contains(&u) {
                best = best.min(t);
            }
        }
        for &(px, py, pr) in &self.posts {
            let (fx, fy) = (ox - px, oy - py);
            let b = fx * dx + fy * dy;
            let disc = b * b - (fx * fx + fy * fy - pr * pr);
            if disc >= 0.0 {
                let t = -b - disc.sqrt();
                if t > 0.0 {
                    best = best.min(t);
                }
            }
        }
        best
    }

    /// A 181-beam, 180° scan (max range 30 m) from the laser pose `pose`, with Gaussian range
    /// noise `sigma` (seeded).
    #[must_use]
    pub fn scan(&self, pose: &crate::Pose2, sigma: f64, seed: u64) -> crate::Scan {
        self.scan_with_beams(pose, 181, sigma, seed)
    }

    /// A 180° scan of `beams` beams (at least 2; max range 30 m) from the laser pose `pose`,
    /// with Gaussian range noise `sigma` (seeded): a sparser or denser laser than
    /// [`SyntheticWorld::scan`]'s.
    #[must_use]
    pub fn scan_with_beams(
        &self,
        pose: &crate::Pose2,
        beams: usize,
        sigma: f64,
        seed: u64,
    ) -> crate::Scan {
        let beams = beams.max(2);
        let geometry = crate::BeamGeometry::centered(beams, std::f64::consts::PI, 30.0);
        let mut r = SplitMix::new(seed);
        let ranges = (0..beams)
            .map(|i| {
                let a = pose.theta + geometry.angle(i);
                let range = self.cast(pose.x, pose.y, a.cos(), a.sin(), geometry.max_range);
                if range < geometry.max_range {
                    range + sigma * r.normal()
                } else {
                    range
                }
            })
            .collect();
        // The geometry is valid and there are as many ranges as beams: this cannot fail.
        crate::Scan::new(0.0, geometry, ranges).unwrap_or_else(|_| unreachable!())
    }
}
