//! Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009): every
//! pose of a grid around a prediction is scored by looking the scan's points up in a
//! likelihood raster of the reference, and the best one wins. It is exhaustive, so it finds the
//! right basin where ICP's local search cannot (a start wrong by 20°), and it hands ICP a start
//! inside that basin. It is slower than one ICP match, so the pipeline runs it only when a
//! match looks wrong (see [`crate::validation`]).

use crate::ConfigError;
use crate::icp::positive;
use qicp_core::{Neighbour, Point2, Pose2, Reference, SpatialIndex};
use serde::{Deserialize, Serialize};

/// The search window and raster (TOML section `[matcher.correlative]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CorrelativeParams {
    /// Half-width of the translation window around the prediction (m). Default 0.5.
    pub window_xy: f64,
    /// Half-width of the rotation window (deg). Default 25.
    pub window_deg: f64,
    /// Raster cell, and the translation step of the search (m). Default 0.05.
    pub resolution: f64,
    /// Rotation step of the search (deg). Default 0.5: a point 6 m away moves one cell.
    pub angle_step_deg: f64,
    /// Standard deviation of the likelihood around each reference point (m). Default 0.1.
    pub sigma: f64,
}

impl Default for CorrelativeParams {
    fn default() -> Self {
        Self {
            window_xy: 0.5,
            window_deg: 25.0,
            resolution: 0.05,
            angle_step_deg: 0.5,
            sigma: 0.1,
        }
    }
}

/// The raster grows to at most this many cells a side; points beyond it are not scored.
const MAX_CELLS: usize = 4096;

impl CorrelativeParams {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("matcher.correlative.window_xy", self.window_xy)?;
        positive("matcher.correlative.window_deg", self.window_deg)?;
        positive("matcher.correlative.resolution", self.resolution)?;
        positive("matcher.correlative.angle_step_deg", self.angle_step_deg)?;
        positive("matcher.correlative.sigma", self.sigma)?;
        if self.window_deg > 180.0 {
            return Err(ConfigError::invalid(
                "matcher.correlative.window_deg",
                format!("{} must be at most 180", self.window_deg),
            ));
        }
        let steps = self.window_xy / self.resolution;
        if steps > 200.0 {
            return Err(ConfigError::invalid(
                "matcher.correlative.window_xy",
                format!(
                    "{} m is {steps:.0} cells of {} m either way; at most 200",
                    self.window_xy, self.resolution
                ),
            ));
        }
        if self.window_deg / self.angle_step_deg > 1000.0 {
            return Err(ConfigError::invalid(
                "matcher.correlative.angle_step_deg",
                "gives more than 1000 rotations either way",
            ));
        }
        Ok(())
    }
}

/// The best pose of a search and how well it explains the scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Pose of the scan in the reference frame.
    pub pose: Pose2,
    /// Mean likelihood of the scan points at `pose`, from 0 (none near the reference) to 1
    /// (every point on a reference point).
    pub score: f64,
}

/// A correlative matcher with its buffers (reused between searches).
#[derive(Debug, Clone, Default)]
pub struct CorrelativeSearch {
    /// The window and raster.
    pub params: CorrelativeParams,
    raster: Vec<u8>,
    side: usize,
    origin: Point2<f64>,
    kernel: Vec<u8>,
    radius: usize,
    neighbours: Vec<Neighbour>,
    cells: Vec<(usize, usize)>,
    sums: Vec<u32>,
}

impl CorrelativeSearch {
    /// A search with the given window.
    #[must_use]
    pub fn new(params: CorrelativeParams) -> Self {
        Self {
            params,
            ..Self::default()
        }
    }

    /// Olson Sec. III-A: the likelihood of a point is a Gaussian of its distance to the
    /// nearest reference point, here the largest of the Gaussians of the reference points
    /// near it, quantized to a byte.
    fn build_raster<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        centre: Point2<f64>,
        reach: f64,
    ) {
        let res = self.params.resolution;
        self.radius = (2.0 * self.params.sigma / res).ceil() as usize;
        let r = self.radius as isize;
        let width = 2 * self.radius + 1;
        self.kernel.clear();
        for dy in -r..=r {
            for dx in -r..=r {
                let d2 = ((dx * dx + dy * dy) as f64) * res * res;
                let s2 = self.params.sigma * self.params.sigma;
                self.kernel
                    .push((255.0 * (-0.5 * d2 / s2).exp()).round() as u8);
            }
        }
        self.side = ((2.0 * reach / res).ceil() as usize + 1).min(MAX_CELLS);
        let half = (self.side / 2) as f64 * res;
        self.origin = Point2::new(centre.x - half, centre.y - half);
        self.raster.clear();
        self.raster.resize(self.side * self.side, 0);
        reference.index().within_radius(
            &centre,
            half * std::f64::consts::SQRT_2,
            &mut self.neighbours,
        );
        for n in &self.neighbours {
            let Some((cx, cy)) = self.cell(&n.point) else {
                continue;
            };
            if self.raster[cy * self.side + cx] == 255 {
                continue; // a point in this cell has been drawn already
            }
            for ky in 0..width {
                let Some(y) = (cy + ky).checked_sub(self.radius) else {
                    continue;
                };
                if y >= self.side {
                    break;
                }
                for kx in 0..width {
                    let Some(x) = (cx + kx).checked_sub(self.radius) else {
                        continue;
                    };
                    if x >= self.side {
                        break;
                    }
                    let cell = &mut self.raster[y * self.side + x];
                    *cell = (*cell).max(self.kernel[ky * width + kx]);
                }
            }
        }
    }

    /// The raster cell of a point, if it lies on the raster.
    fn cell(&self, p: &Point2<f64>) -> Option<(usize, usize)> {
        let res = self.params.resolution;
        let x = ((p.x - self.origin.x) / res).round();
        let y = ((p.y - self.origin.y) / res).round();
        let side = self.side as f64;
        (x >= 0.0 && y >= 0.0 && x < side && y < side).then_some((x as usize, y as usize))
    }

    /// Searches the window around `guess` for the pose of `local` (scan points in the laser
    /// frame) that best explains the reference. `None` when the scan has no point or the
    /// reference none near it.
    pub fn search<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        guess: &Pose2,
    ) -> Option<Candidate> {
        if local.is_empty() || reference.is_empty() || !guess.is_finite() {
            return None;
        }
        let p = self.params;
        let steps = (p.window_xy / p.resolution).round() as usize;
        let reach_points = local
            .iter()
            .map(|q| q.coords.norm())
            .fold(0.0, f64::max)
            .min(0.5 * MAX_CELLS as f64 * p.resolution);
        let reach = reach_points + p.window_xy + 2.0 * p.sigma + p.resolution;
        let centre = Point2::new(guess.x, guess.y);
        self.build_raster(reference, centre, reach);
        let span = 2 * steps + 1;
        let turns = (p.window_deg / p.angle_step_deg).floor() as i64;
        let mut best: Option<(u32, Pose2)> = None;
        // From the prediction outwards, so that of equal scores the nearest rotation wins.
        let order = std::iter::once(0).chain((1..=turns).flat_map(|k| [-k, k]));
        for k in order {
            let theta = guess.theta + (k as f64 * p.angle_step_deg).to_radians();
            let at = Pose2::new(guess.x, guess.y, theta);
            self.cells.clear();
            for q in local {
                // Cells of the window's corner translation (-steps, -steps).
                if let Some((x, y)) = self.cell(&at.transform_point(q))
                    && x >= steps
                    && y >= steps
                    && x + steps < self.side
                    && y + steps < self.side
                {
                    self.cells.push((x - steps, y - steps));
                }
            }
            self.sums.clear();
            self.sums.resize(span * span, 0);
            for &(x, y) in &self.cells {
                for dy in 0..span {
                    let row = &self.raster[(y + dy) * self.side + x..][..span];
                    for (sum, &v) in self.sums[dy * span..][..span].iter_mut().zip(row) {
                        *sum += u32::from(v);
                    }
                }
            }
            // Of equal scores the translation nearest the prediction wins.
            let centre = steps as isize;
            let mut here: Option<(u32, isize, usize)> = None;
            for (i, &s) in self.sums.iter().enumerate() {
                let (dx, dy) = ((i % span) as isize - centre, (i / span) as isize - centre);
                let d = dx * dx + dy * dy;
                if here.is_none_or(|(bs, bd, _)| s > bs || (s == bs && d < bd)) {
                    here = Some((s, d, i));
                }
            }
            let Some((score, _, i)) = here else { continue };
            if best.is_none_or(|(b, _)| score > b) {
                let dx = (i % span) as f64 - steps as f64;
                let dy = (i / span) as f64 - steps as f64;
                let pose = Pose2::new(
                    guess.x + dx * p.resolution,
                    guess.y + dy * p.resolution,
                    theta,
                );
                best = Some((score, pose));
            }
        }
        let (score, pose) = best?;
        (score > 0).then(|| Candidate {
            pose,
            score: f64::from(score) / (255.0 * local.len() as f64),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qicp_core::QuadTree;
    use qicp_core::testdata::SyntheticWorld;

    #[test]
    fn finds_a_pose_twenty_degrees_and_forty_centimetres_off() {
        let scan = SyntheticWorld::room().scan(&Pose2::IDENTITY, 0.005, 1);
        let mut reference = Reference::new(QuadTree::default());
        reference
            .insert_scan(&scan, &Pose2::IDENTITY, None)
            .unwrap();
        let mut search = CorrelativeSearch::new(CorrelativeParams::default());
        let guess = Pose2::new(0.3, -0.25, 20f64.to_radians());
        let found = search.search(&reference, scan.points(), &guess).unwrap();
        assert!(found.pose.distance(&Pose2::IDENTITY) < 0.06, "{found:?}");
        assert!(found.pose.theta.abs() < 0.6f64.to_radians(), "{found:?}");
        assert!(found.score > 0.8, "{found:?}");
    }
}
