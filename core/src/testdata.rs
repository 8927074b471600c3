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
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let (ox, oy, heading) = (r.range(-17.0, 17.0), r.range(-5.5, 5.5), r.range(-3.2, 3.2));
        for b in 0..181 {
            if out.len() == n {
                break;
            }
            let a = heading - std::f64::consts::FRAC_PI_2 + b as f64 * std::f64::consts::PI / 180.0;
            let (dx, dy) = (a.cos(), a.sin());
            let mut best = 30.0f64;
            for w in &walls {
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
            for &(px, py, pr) in &posts {
                let (fx, fy) = (ox - px, oy - py);
                let bq = fx * dx + fy * dy;
                let c = fx * fx + fy * fy - pr * pr;
                let disc = bq * bq - c;
                if disc >= 0.0 {
                    let t = -bq - disc.sqrt();
                    if t > 0.0 {
                        best = best.min(t);
                    }
                }
            }
            if best < 30.0 {
                let range = best + 0.01 * r.normal();
                out.push(Point2::new(ox + range * dx, oy + range * dy));
            }
        }
    }
    out
}
