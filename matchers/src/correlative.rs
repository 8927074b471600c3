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
    /// In a log without odometry (no reading has moved), against a map, once a match has
    /// moved off the repeated reading: each scan's ICP starts from this search's best
    /// pose around the constant-velocity prediction (the prediction's prior centred there),
    /// and from the prediction only where that match finds too few pairs. Cartographer's
    /// real-time correlative scan matcher gives its local match a start, and the centre of its
    /// priors, the same way where odometry is poor or absent.
    /// Default false: it costs about nine times the time per scan (q-plicp on Intel without
    /// odometry: 2.8 ms against 0.31 ms). docs/robustness.md ("A correlative start without
    /// odometry") has its sweeps. Logs with odometry are matched as without it.
    pub start_without_odometry: bool,
}

impl Default for CorrelativeParams {
    fn default() -> Self {
        Self {
            window_xy: 0.5,
            window_deg: 25.0,
            resolution: 0.05,
            angle_step_deg: 0.5,
            sigma: 0.1,
            start_without_odometry: false,
        }
    }
}

/// Radius of a disc about a cell's centre that holds every point of the cell (half its
/// diagonal, 0.71, and a margin), in cells.
const CELL_DISC: f64 = 0.75;

/// The raster grows to at most this many cells a side; points beyond it are not scored.
const MAX_CELLS: usize = 4096;

/// The likelihood kernel reaches at most this many cells either way of a point (2σ over the
/// resolution; the default 2): every map point draws a square of twice that side.
const MAX_KERNEL_CELLS: f64 = 64.0;

/// A window's count of steps either way: the ratio rounded down, but within a hair of an
/// integer taken as that integer (0.3° / 0.1° is 2.9999999999999996 in floating point).
fn steps_within(window: f64, step: f64) -> f64 {
    (window / step * (1.0 + 1e-12)).floor()
}

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
        let kernel_cells = 2.0 * self.sigma / self.resolution;
        if kernel_cells > MAX_KERNEL_CELLS {
            return Err(ConfigError::invalid(
                "matcher.correlative.sigma",
                format!(
                    "{} m reaches {kernel_cells:.0} cells of {} m either way; at most \
                     {MAX_KERNEL_CELLS} (each map point draws a square of that reach)",
                    self.sigma, self.resolution
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
///
/// The raster is laid out as a square of `side` cells about the prediction (`origin` its
/// corner), large enough for the scan's reach and the window; only the rectangle of it that
/// the search reads (`rect`) is held and drawn, since a cell's value depends on the reference
/// points near it alone.
#[derive(Debug, Clone, Default)]
pub struct CorrelativeSearch {
    /// The window and raster.
    pub params: CorrelativeParams,
    raster: Vec<u8>,
    side: usize,
    origin: Point2<f64>,
    /// The cells held: first column and row, width and height.
    rect: (usize, usize, usize, usize),
    kernel: Vec<u8>,
    radius: usize,
    neighbours: Vec<Neighbour>,
    /// The corner cells of every rotation's scan points, rotation after rotation.
    cells: Vec<(usize, usize)>,
    /// Where each rotation's corner cells end in `cells`.
    ends: Vec<usize>,
    sums: Vec<u32>,
    /// The raster's block maxima ([`pool`](Self::pool)).
    pooled: Vec<u8>,
    /// The bound of every block of translations.
    bounds: Vec<u32>,
    /// The row maxima on the way to `pooled`.
    scratch: Vec<u8>,
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
    /// near it, quantized to a byte. Draws the held rectangle of the raster, from the
    /// reference points with ids below `below` (every point with `None`).
    fn draw_raster<I: SpatialIndex>(&mut self, reference: &Reference<I>, below: Option<u32>) {
        let res = self.params.resolution;
        let width = 2 * self.radius + 1;
        let (x0, y0, w, h) = self.rect;
        self.raster.clear();
        self.raster.resize(w * h, 0);
        if w == 0 || h == 0 {
            return;
        }
        // Every point whose kernel reaches the held cells lies within this disc.
        let reach = |cells: usize| (cells as f64 / 2.0 + self.radius as f64 + 1.0) * res;
        let centre = Point2::new(
            self.origin.x + (x0 as f64 + (w - 1) as f64 / 2.0) * res,
            self.origin.y + (y0 as f64 + (h - 1) as f64 / 2.0) * res,
        );
        reference
            .index()
            .within_radius(&centre, reach(w).hypot(reach(h)), &mut self.neighbours);
        let (x1, y1) = (x0 + w, y0 + h);
        // Only a point in a cell draws the kernel's peak (255) there while the entry one cell
        // right of the peak is below it (σ under about 16 cells; none for a one-cell kernel).
        let peak_alone = self
            .kernel
            .get(self.radius * width + self.radius + 1)
            .is_none_or(|&v| v < 255);
        for n in &self.neighbours {
            if below.is_some_and(|b| n.id >= b) {
                continue;
            }
            let Some((cx, cy)) = self.cell(&n.point) else {
                continue;
            };
            if cx + self.radius < x0
                || cy + self.radius < y0
                || cx >= x1 + self.radius
                || cy >= y1 + self.radius
            {
                continue; // its kernel misses the held cells
            }
            if peak_alone
                && (x0..x1).contains(&cx)
                && (y0..y1).contains(&cy)
                && self.raster[(cy - y0) * w + cx - x0] == 255
            {
                continue; // a point in this cell has been drawn already
            }
            // The kernel's cells that fall on the held ones, row by row: (x, y) takes kernel
            // entry (x + radius − cx, y + radius − cy).
            let r = self.radius;
            let (lo_x, hi_x) = (cx.saturating_sub(r).max(x0), (cx + r + 1).min(x1));
            let (lo_y, hi_y) = (cy.saturating_sub(r).max(y0), (cy + r + 1).min(y1));
            for y in lo_y..hi_y {
                let row = &mut self.raster[(y - y0) * w + lo_x - x0..(y - y0) * w + hi_x - x0];
                let k = (y + r - cy) * width;
                let kernel = &self.kernel[k + lo_x + r - cx..k + hi_x + r - cx];
                for (cell, &v) in row.iter_mut().zip(kernel) {
                    *cell = (*cell).max(v);
                }
            }
        }
    }

    /// The raster cell of a point, if it lies on the raster.
    fn cell(&self, p: &Point2<f64>) -> Option<(usize, usize)> {
        let res = self.params.resolution;
        let x = round_to_cell((p.x - self.origin.x) / res, self.side)?;
        let y = round_to_cell((p.y - self.origin.y) / res, self.side)?;
        Some((x, y))
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
        self.search_among(reference, local, guess, None)
            .map(|(best, _)| best)
    }

    /// The rotations of a window of `turns` steps of `step` degrees about `theta`, from the
    /// prediction outwards (so that of equal scores the nearest rotation wins): the step
    /// number and the heading.
    fn rotations(step: f64, theta: f64, turns: i64) -> impl Iterator<Item = (i64, f64)> {
        std::iter::once(0)
            .chain((1..=turns).flat_map(|k| [-k, k]))
            .map(move |k| (k, theta + (k as f64 * step).to_radians()))
    }

    /// The window's rotation steps either way of the prediction.
    fn turns(&self) -> i64 {
        steps_within(self.params.window_deg, self.params.angle_step_deg) as i64
    }

    /// Lays the raster out around `guess`, large enough for the window and the scan's reach,
    /// and finds the corner cells of every rotation's scan points (up to `turns` steps
    /// either way) and the kernel: the window's translation steps either way, or `None` when
    /// there is nothing to search.
    fn layout<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        guess: &Pose2,
        turns: i64,
    ) -> Option<usize> {
        if local.is_empty() || reference.is_empty() || !guess.is_finite() {
            return None;
        }
        let p = self.params;
        let res = p.resolution;
        self.radius = (2.0 * p.sigma / res).ceil() as usize;
        let r = self.radius as isize;
        self.kernel.clear();
        for dy in -r..=r {
            for dx in -r..=r {
                let d2 = ((dx * dx + dy * dy) as f64) * res * res;
                let s2 = p.sigma * p.sigma;
                self.kernel
                    .push((255.0 * (-0.5 * d2 / s2).exp()).round() as u8);
            }
        }
        let reach_points = local
            .iter()
            .map(|q| q.coords.norm())
            .fold(0.0, f64::max)
            .min(0.5 * MAX_CELLS as f64 * res);
        let reach = reach_points + p.window_xy + 2.0 * p.sigma + res;
        self.side = ((2.0 * reach / res).ceil() as usize + 1).min(MAX_CELLS);
        let half = (self.side / 2) as f64 * res;
        self.origin = Point2::new(guess.x - half, guess.y - half);
        let steps = (p.window_xy / res).round() as usize;
        self.cells.clear();
        self.ends.clear();
        for (_, theta) in Self::rotations(p.angle_step_deg, guess.theta, turns) {
            let at = Pose2::new(guess.x, guess.y, theta);
            for q in local {
                // Cells of the window's corner translation (-steps, -steps), where every
                // translation of the window keeps the point on the raster.
                if let Some((x, y)) = self.cell(&at.transform_point(q))
                    && x >= steps
                    && y >= steps
                    && x + steps < self.side
                    && y + steps < self.side
                {
                    self.cells.push((x - steps, y - steps));
                }
            }
            self.ends.push(self.cells.len());
        }
        Some(steps)
    }

    /// Lays the raster out (see [`layout`](Self::layout)) and draws the cells the search
    /// reads from the reference points with ids below `below` (every point with `None`): the
    /// window's translation steps either way, or `None` when there is nothing to search.
    fn prepare<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        guess: &Pose2,
        below: Option<u32>,
        turns: i64,
    ) -> Option<usize> {
        let steps = self.layout(reference, local, guess, turns)?;
        let span = 2 * steps + 1;
        self.rect = match self
            .cells
            .iter()
            .copied()
            .reduce(|a, b| (a.0.min(b.0), a.1.min(b.1)))
        {
            None => (0, 0, 0, 0),
            Some((x0, y0)) => {
                let (x1, y1) = self
                    .cells
                    .iter()
                    .fold((0, 0), |m, c| (m.0.max(c.0), m.1.max(c.1)));
                (x0, y0, x1 + span - x0, y1 + span - y0)
            }
        };
        self.draw_raster(reference, below);
        Some(steps)
    }

    /// [`search`](Self::search) against the reference points with ids below `below` only
    /// (every point with `None`: the points of the scans inserted before a given one), with
    /// the score of `guess` itself in the same raster.
    pub fn search_among<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        guess: &Pose2,
        below: Option<u32>,
    ) -> Option<(Candidate, f64)> {
        let p = self.params;
        let turns = self.turns();
        let steps = self.prepare(reference, local, guess, below, turns)?;
        let span = 2 * steps + 1;
        let mut at_guess = 0u32;
        let mut best: Option<(u32, Pose2)> = None;
        let mut start = 0;
        for (r, (k, theta)) in Self::rotations(p.angle_step_deg, guess.theta, turns).enumerate() {
            let end = self.ends[r];
            self.sums.clear();
            self.sums.resize(span * span, 0);
            self.add_sums(start..end, (0, 0), (span, span), span);
            start = end;
            if k == 0 {
                at_guess = self.sums[steps * span + steps];
            }
            let here = (0..span * span).fold(None, |b, i| better(b, self.sums[i], i, steps));
            if let Some((score, i)) = here
                && best.is_none_or(|(b, _)| score > b)
            {
                best = Some((score, self.pose_of(guess, theta, i, steps)));
            }
        }
        let (score, pose) = best?;
        let norm = 255.0 * local.len() as f64;
        (score > 0).then(|| {
            (
                Candidate {
                    pose,
                    score: f64::from(score) / norm,
                },
                f64::from(at_guess) / norm,
            )
        })
    }

    /// The best pose of the window with `below` as [`search_among`](Self::search_among)
    /// finds it, if its score is at least `min_score`; `None` if no pose of the window
    /// reaches that score.
    ///
    /// The same answer, found faster where few poses come near `min_score` (branch and bound
    /// in one level, as in Olson's multi-resolution search): the window's translations are
    /// cut into square blocks, and a block is bounded by the sum, over the scan points, of
    /// the largest raster value the block's translations read for that point. A block whose
    /// bound falls short of `min_score` holds no pose that reaches it and is not scored.
    pub fn search_over<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        guess: &Pose2,
        below: Option<u32>,
        min_score: f64,
    ) -> Option<Candidate> {
        let p = self.params;
        let turns = self.turns();
        let steps = self.prepare(reference, local, guess, below, turns)?;
        let span = 2 * steps + 1;
        let norm = 255.0 * local.len() as f64;
        // The sum a pose needs, rounded down a little so that float rounding never prunes a
        // block whose pose the final comparison with `min_score` would accept.
        let need = ((min_score * norm).floor() - 1.0).max(1.0) as u32;
        let block = (span as f64).sqrt().ceil() as usize;
        let blocks = span.div_ceil(block);
        self.pool(block);
        let (x0, y0, w, _) = self.rect;
        let mut best: Option<(u32, Pose2)> = None;
        let mut start = 0;
        for (r, (_, theta)) in Self::rotations(p.angle_step_deg, guess.theta, turns).enumerate() {
            let end = self.ends[r];
            self.bounds.clear();
            self.bounds.resize(blocks * blocks, 0);
            for &(x, y) in &self.cells[start..end] {
                for by in 0..blocks {
                    let row = &self.pooled[(y + by * block - y0) * w + x - x0..];
                    let bounds = &mut self.bounds[by * blocks..][..blocks];
                    for (bx, bound) in bounds.iter_mut().enumerate() {
                        *bound += u32::from(row[bx * block]);
                    }
                }
            }
            self.sums.clear();
            self.sums.resize(span * span, 0);
            let mut here = None;
            for b in 0..blocks * blocks {
                if self.bounds[b] < need {
                    continue;
                }
                let from = ((b % blocks) * block, (b / blocks) * block);
                let to = ((from.0 + block).min(span), (from.1 + block).min(span));
                self.add_sums(start..end, from, to, span);
                for dy in from.1..to.1 {
                    for dx in from.0..to.0 {
                        let i = dy * span + dx;
                        here = better(here, self.sums[i], i, steps);
                    }
                }
            }
            start = end;
            if let Some((score, i)) = here
                && best.is_none_or(|(b, _)| score > b)
            {
                best = Some((score, self.pose_of(guess, theta, i, steps)));
            }
        }
        let (score, pose) = best?;
        let score = f64::from(score) / norm;
        (score > 0.0 && score >= min_score).then_some(Candidate { pose, score })
    }

    /// Adds to `sums` (one per translation of the window, `span` a row) the raster values
    /// the corner cells `cells[points]` read at the translations from `from` up to `to`
    /// (exclusive, (x, y) in steps from the window's corner).
    fn add_sums(
        &mut self,
        points: std::ops::Range<usize>,
        from: (usize, usize),
        to: (usize, usize),
        span: usize,
    ) {
        let (x0, y0, w, _) = self.rect;
        let cols = to.0 - from.0;
        for &(x, y) in &self.cells[points] {
            for dy in from.1..to.1 {
                let row = &self.raster[(y + dy - y0) * w + x + from.0 - x0..][..cols];
                let sums = &mut self.sums[dy * span + from.0..][..cols];
                for (sum, &v) in sums.iter_mut().zip(row) {
                    *sum += u32::from(v);
                }
            }
        }
    }

    /// Fills `pooled` with, for every held cell, the largest raster value of the `block` ×
    /// `block` cells from it up and to the right (clipped to the held cells).
    fn pool(&mut self, block: usize) {
        let (_, _, w, h) = self.rect;
        let mut rows = std::mem::take(&mut self.scratch);
        rows.clone_from(&self.raster);
        for y in 0..h {
            let row = &mut rows[y * w..][..w];
            let src = &self.raster[y * w..][..w];
            for o in 1..block.min(w) {
                for (v, &s) in row[..w - o].iter_mut().zip(&src[o..]) {
                    *v = (*v).max(s);
                }
            }
        }
        self.pooled.clone_from(&rows);
        for o in 1..block.min(h) {
            let (dst, src) = (&mut self.pooled[..(h - o) * w], &rows[o * w..]);
            for (v, &s) in dst.iter_mut().zip(src) {
                *v = (*v).max(s);
            }
        }
        self.scratch = rows;
    }

    /// The pose of translation `i` (of a window `2 * steps + 1` a side) at heading `theta`.
    fn pose_of(&self, guess: &Pose2, theta: f64, i: usize, steps: usize) -> Pose2 {
        let span = 2 * steps + 1;
        let dx = (i % span) as f64 - steps as f64;
        let dy = (i / span) as f64 - steps as f64;
        let res = self.params.resolution;
        Pose2::new(guess.x + dx * res, guess.y + dy * res, theta)
    }

    /// The score of `pose` alone, as [`search_among`](Self::search_among) scores its
    /// `guess`, against the reference points with ids below `below`: the raster's value at
    /// each scan point's cell, found from the points near that cell without drawing the
    /// raster.
    pub fn score_among<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
        below: u32,
    ) -> Option<f64> {
        let steps = self.layout(reference, local, pose, 0)?;
        let res = self.params.resolution;
        let r = self.radius;
        let width = 2 * r + 1;
        // Every point whose cell lies within `r` cells of a cell lies within this distance
        // of the cell's centre.
        let near = (r as f64 + 1.0) * res * std::f64::consts::SQRT_2;
        let mut sum = 0u32;
        for k in 0..self.cells.len() {
            let (x, y) = (self.cells[k].0 + steps, self.cells[k].1 + steps);
            let centre = Point2::new(
                self.origin.x + x as f64 * res,
                self.origin.y + y as f64 * res,
            );
            // An old point in the cell itself gives the kernel's peak, the most any point
            // gives: the points of a small disc about the cell decide most cells of a scan
            // that fits the old map, before the whole neighbourhood is searched.
            reference
                .index()
                .within_radius(&centre, CELL_DISC * res, &mut self.neighbours);
            if self
                .neighbours
                .iter()
                .any(|n| n.id < below && self.cell(&n.point) == Some((x, y)))
            {
                sum += u32::from(self.kernel[r * width + r]);
                continue;
            }
            reference
                .index()
                .within_radius(&centre, near, &mut self.neighbours);
            let mut value = 0u8;
            for n in &self.neighbours {
                if n.id >= below {
                    continue;
                }
                // The kernel entry a point drawn at its cell (cx, cy) writes into (x, y).
                if let Some((cx, cy)) = self.cell(&n.point)
                    && let (Some(kx), Some(ky)) = ((x + r).checked_sub(cx), (y + r).checked_sub(cy))
                    && kx < width
                    && ky < width
                {
                    value = value.max(self.kernel[ky * width + kx]);
                }
            }
            sum += u32::from(value);
        }
        Some(f64::from(sum) / (255.0 * local.len() as f64))
    }
}

/// `v.round()` (half away from zero) as a cell index, if it lies in `0..side`. The same
/// answer as `f64::round`, without the library call that `round` is on targets without
/// SSE4.1: it sits in the raster's innermost loops.
fn round_to_cell(v: f64, side: usize) -> Option<usize> {
    // Values from −0.5 on round below 0, from `side` − 0.5 on to `side` or more; NaN fails.
    if !(v > -0.5 && v < side as f64 - 0.5) {
        return None;
    }
    // v + 0.5 is exact here but for v just below 0.5, where it rounds up to 1.
    let up = (v + 0.5) as usize;
    Some(if v < up as f64 - 0.5 { up - 1 } else { up })
}

/// Of two translations of a window (`steps` either way), the one with the larger sum; of
/// equal sums the one nearest the prediction, then the first. `best` holds a sum and the
/// translation's index.
fn better(best: Option<(u32, usize)>, sum: u32, i: usize, steps: usize) -> Option<(u32, usize)> {
    let span = 2 * steps + 1;
    let d = |i: usize| {
        let (dx, dy) = ((i % span).abs_diff(steps), (i / span).abs_diff(steps));
        dx * dx + dy * dy
    };
    match best {
        Some((s, j)) if s > sum || (s == sum && (d(j), j) <= (d(i), i)) => best,
        _ => Some((sum, i)),
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

    /// The cell rounding is `f64::round`'s, refused off the raster, on seeded values, halves
    /// and the values either side of them.
    #[test]
    fn round_to_cell_rounds_as_f64_round_does() {
        let mut rng = qicp_core::testdata::SplitMix::new(3);
        let side = 4096;
        let mut values = vec![
            f64::NAN,
            f64::INFINITY,
            -0.5,
            0.5,
            -0.0,
            4095.5,
            4096.0,
            1e300,
        ];
        for _ in 0..100_000 {
            let v = rng.range(-50.0, 4200.0);
            let half = v.floor() + 0.5;
            values.extend([v, half, half.next_up(), half.next_down()]);
        }
        for v in values {
            let r = v.round();
            let want = (r >= 0.0 && r < side as f64).then_some(r as usize);
            assert_eq!(round_to_cell(v, side), want, "{v}");
        }
    }

    /// The bounded search is a fast path of the exhaustive one: on seeded maps of the room
    /// and the corridor, with old and recent points, guesses off by up to 0.5 m and 4°, and
    /// thresholds on both sides of the best score, it finds the same pose and score whenever
    /// the best reaches the threshold, and nothing otherwise; and the score of the guess
    /// alone, found without drawing the raster, is the raster's.
    #[test]
    fn search_over_and_score_among_answer_as_the_exhaustive_search_does() {
        let mut rng = qicp_core::testdata::SplitMix::new(7);
        let mut search = CorrelativeSearch::new(CorrelativeParams {
            window_xy: 0.4,
            window_deg: 3.0,
            ..CorrelativeParams::default()
        });
        let (mut found, mut pruned, mut scored) = (0, 0, 0);
        for case in 0..24u64 {
            let world = if case % 2 == 0 {
                SyntheticWorld::room()
            } else {
                SyntheticWorld::corridor()
            };
            let mut reference = Reference::new(QuadTree::default());
            let mut sizes = Vec::new();
            for k in 0..4 {
                let at = Pose2::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-0.5, 0.5),
                    rng.range(-0.3, 0.3),
                );
                let scan = world.scan(&at, 0.01, case * 10 + k);
                reference.insert_scan(&scan, &at, None).expect("finite");
                sizes.push(reference.index().len() as u32);
            }
            let truth = Pose2::new(
                rng.range(-1.0, 1.0),
                rng.range(-0.5, 0.5),
                rng.range(-0.3, 0.3),
            );
            let scan = world.scan(&truth, 0.01, case * 10 + 9);
            let guess = Pose2::new(
                truth.x + rng.range(-0.5, 0.5),
                truth.y + rng.range(-0.5, 0.5),
                truth.theta + rng.range(-4.0, 4.0).to_radians(),
            );
            let below = (case % 3 != 0).then(|| sizes[(case % 3) as usize]);
            let exhaustive = search.search_among(&reference, scan.points(), &guess, below);
            let best = exhaustive.map_or(0.0, |(c, _)| c.score);
            // The score of the guess alone, from the points near each cell, is the drawn
            // raster's.
            if let (Some(b), Some((_, at_guess))) = (below, exhaustive) {
                let alone = search.score_among(&reference, scan.points(), &guess, b);
                assert_eq!(alone, Some(at_guess), "case {case}");
                scored += 1;
            }
            for min_score in [0.0, 0.3, best - 0.05, best, best + 1e-9, best + 0.05, 0.95] {
                let bounded =
                    search.search_over(&reference, scan.points(), &guess, below, min_score);
                match exhaustive {
                    Some((c, _)) if c.score >= min_score => {
                        assert_eq!(bounded, Some(c), "case {case}, min_score {min_score}");
                        found += 1;
                    }
                    _ => {
                        assert_eq!(bounded, None, "case {case}, min_score {min_score}");
                        pruned += 1;
                    }
                }
            }
        }
        // Both sides of the threshold were exercised.
        assert!(found > 40 && pruned > 40, "{found} found, {pruned} pruned");
        assert!(scored >= 12, "{scored} scored alone");
    }

    /// A map of `points`, inserted in that order: each one the return of a one-beam scan
    /// taken a metre west of it.
    fn map_of(points: &[Point2<f64>]) -> Reference<QuadTree> {
        let geometry = qicp_core::BeamGeometry {
            angle_min: 0.0,
            angle_increment: 0.01,
            max_range: 30.0,
            min_range: 0.1,
        };
        let mut reference = Reference::new(QuadTree::default());
        for p in points {
            let scan = qicp_core::Scan::new(0.0, geometry, vec![1.0]).expect("a scan");
            let at = Pose2::new(p.x - 1.0, p.y, 0.0);
            reference.insert_scan(&scan, &at, None).expect("finite");
        }
        reference
    }

    #[test]
    fn a_rotation_window_of_a_whole_number_of_steps_keeps_its_outer_step() {
        // 0.3° / 0.1° is 2.9999999999999996 in floating point: floored, the window lost its
        // outer step and a scan turned by 0.3° was not found.
        let points: Vec<Point2<f64>> = [0.0f64, 1.5, 3.0, 4.5]
            .iter()
            .map(|a| Point2::new(20.0 * a.cos(), 20.0 * a.sin()))
            .collect();
        let reference = map_of(&points);
        let mut search = CorrelativeSearch::new(CorrelativeParams {
            window_xy: 0.05,
            window_deg: 0.3,
            angle_step_deg: 0.1,
            ..CorrelativeParams::default()
        });
        assert_eq!(search.turns(), 3);
        let guess = Pose2::new(0.0, 0.0, (-0.3f64).to_radians());
        let found = search.search(&reference, &points, &guess).expect("a pose");
        assert!(found.pose.theta.abs() < 1e-9, "{found:?}");
        assert!((found.score - 1.0).abs() < 1e-9, "{found:?}");
    }

    #[test]
    fn a_wide_kernel_draws_every_point_whatever_their_order() {
        // At σ = 20 cells a point's neighbouring cell rounds to the kernel's peak too: the
        // raster skipped the second of two points a cell apart, so that the search depended
        // on the order of the map's points and disagreed with the score of its own guess.
        let params = CorrelativeParams {
            window_xy: 0.05,
            window_deg: 0.5,
            resolution: 0.05,
            angle_step_deg: 0.5,
            sigma: 1.0,
            ..CorrelativeParams::default()
        };
        let (a, b) = (Point2::new(0.0, 0.0), Point2::new(0.05, 0.0));
        let scan = [Point2::new(2.05, 0.0), Point2::new(-2.0, 0.0)];
        let guess = Pose2::IDENTITY;
        let mut answers = Vec::new();
        for order in [[a, b], [b, a]] {
            let reference = map_of(&order);
            let mut search = CorrelativeSearch::new(params);
            let (best, at_guess) = search
                .search_among(&reference, &scan, &guess, None)
                .expect("a pose");
            let alone = search.score_among(&reference, &scan, &guess, 2);
            assert_eq!(alone, Some(at_guess), "{order:?}");
            answers.push(best);
        }
        assert_eq!(answers[0], answers[1]);
    }

    #[test]
    fn a_kernel_reaching_too_far_is_refused_with_its_key() {
        for sigma in [1e20, 10.0] {
            let params = CorrelativeParams {
                sigma,
                ..CorrelativeParams::default()
            };
            let err = params.validate().expect_err("refused");
            assert!(
                err.to_string().contains("matcher.correlative.sigma"),
                "{err}"
            );
        }
        // The default reaches 2 cells either way, and at 1.4 times it 3.
        let wider = CorrelativeParams {
            sigma: 0.14,
            ..CorrelativeParams::default()
        };
        assert!(wider.validate().is_ok());
    }
}
