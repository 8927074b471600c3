//! The bounds of a map picture, gathered scan by scan.

use super::*;

/// The bounds of a map gathered scan by scan, for scans that are not held in memory: the
/// returns' coordinates are counted in 1 cm bins (memory grows with the area seen, not with
/// the number of scans), so [`MapExtent::bounds`] gives [`map_bounds`]' trimmed quantiles to
/// within a bin, widened outwards.
#[derive(Debug, Clone, Default)]
pub struct MapExtent {
    xs: std::collections::BTreeMap<i64, u64>,
    ys: std::collections::BTreeMap<i64, u64>,
    n: u64,
    lo: (f64, f64),
    hi: (f64, f64),
    poses: bool,
}

/// Bin width of [`MapExtent`] (m).
const EXTENT_BIN_M: f64 = 0.01;

impl MapExtent {
    /// An empty extent.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the returns of `scan` taken from `laser` and the laser pose itself.
    pub fn add_scan(&mut self, laser: &Pose2, scan: &Scan) {
        for p in scan.points() {
            let q = *laser * *p;
            if q.x.is_finite() && q.y.is_finite() {
                *self
                    .xs
                    .entry((q.x / EXTENT_BIN_M).floor() as i64)
                    .or_insert(0) += 1;
                *self
                    .ys
                    .entry((q.y / EXTENT_BIN_M).floor() as i64)
                    .or_insert(0) += 1;
                self.n += 1;
            }
        }
        self.add_pose(laser);
    }

    /// Adds a pose that must lie inside the map (a laser or a true pose).
    pub fn add_pose(&mut self, p: &Pose2) {
        if !self.poses {
            self.lo = (f64::INFINITY, f64::INFINITY);
            self.hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
            self.poses = true;
        }
        self.lo = (self.lo.0.min(p.x), self.lo.1.min(p.y));
        self.hi = (self.hi.0.max(p.x), self.hi.1.max(p.y));
    }

    /// `[lo, hi]` as [`map_bounds`] gives them: the 0.1 % and 99.9 % quantiles of the returns
    /// (here the outer edge of their bin) and every pose, with a 2 m margin.
    #[must_use]
    pub fn bounds(&self) -> ((f64, f64), (f64, f64)) {
        // The value of rank `rank` (1-based) of the counted bins: its bin's lower edge, or
        // upper edge for `upper`.
        let at = |bins: &std::collections::BTreeMap<i64, u64>, rank: u64, upper: bool| {
            let mut seen = 0;
            for (&bin, &count) in bins {
                seen += count;
                if seen >= rank {
                    return (bin + i64::from(upper)) as f64 * EXTENT_BIN_M;
                }
            }
            f64::NAN
        };
        let (mut lo, mut hi) = if self.n == 0 {
            (
                (f64::INFINITY, f64::INFINITY),
                (f64::NEG_INFINITY, f64::NEG_INFINITY),
            )
        } else {
            let rank = |q: f64| ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
            let (r_lo, r_hi) = (rank(0.001), rank(0.999));
            (
                (at(&self.xs, r_lo, false), at(&self.ys, r_lo, false)),
                (at(&self.xs, r_hi, true), at(&self.ys, r_hi, true)),
            )
        };
        if self.poses {
            lo = (lo.0.min(self.lo.0), lo.1.min(self.lo.1));
            hi = (hi.0.max(self.hi.0), hi.1.max(self.hi.1));
        }
        ((lo.0 - 2.0, lo.1 - 2.0), (hi.0 + 2.0, hi.1 + 2.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::map_bounds;
    use qicp_core::BeamGeometry;

    /// Scans of varied ranges at poses along a loop.
    fn drive() -> (Vec<Pose2>, Vec<Scan>) {
        let geometry = BeamGeometry::centered(181, std::f64::consts::PI, 30.0);
        (0..60)
            .map(|k| {
                let a = f64::from(k) * 0.1;
                let pose = Pose2::new(5.0 * a.cos(), 3.0 * a.sin(), a + 1.0);
                let ranges = (0..181)
                    .map(|i| 2.0 + f64::from((i * 7 + k * 13) % 97) * 0.11)
                    .collect();
                (
                    pose,
                    Scan::new(f64::from(k), geometry, ranges).expect("scan"),
                )
            })
            .unzip()
    }

    #[test]
    fn streamed_bounds_are_the_held_ones_to_within_a_bin_outwards() {
        let (poses, scans) = drive();
        let refs: Vec<&Scan> = scans.iter().collect();
        let extra = [Pose2::new(-40.0, 1.0, 0.0)];
        let (lo, hi) = map_bounds(&poses, &refs, &extra);
        let mut extent = MapExtent::new();
        for (p, s) in poses.iter().zip(&scans) {
            extent.add_scan(p, s);
        }
        extent.add_pose(&extra[0]);
        let (slo, shi) = extent.bounds();
        for (held, streamed) in [(lo.0, slo.0), (lo.1, slo.1)] {
            assert!(
                streamed <= held && held - streamed <= EXTENT_BIN_M,
                "{held} {streamed}"
            );
        }
        for (held, streamed) in [(hi.0, shi.0), (hi.1, shi.1)] {
            assert!(
                streamed >= held && streamed - held <= EXTENT_BIN_M,
                "{held} {streamed}"
            );
        }
        assert_eq!(slo.0, -42.0, "a pose outside the returns widens the bounds");
    }
}
