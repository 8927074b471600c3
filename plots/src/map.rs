//! The occupancy map of a run: every scan at its estimated pose (paper Figs. 3, 5).

use super::*;

/// A grid of hit and pass-through counts, `cell` metres per side.
#[derive(Debug, Clone)]
pub struct OccupancyGrid {
    origin: (f64, f64),
    cell: f64,
    width: usize,
    height: usize,
    hits: Vec<u32>,
    passes: Vec<u32>,
}

impl OccupancyGrid {
    /// An empty grid covering `[lo, hi]` (m).
    #[must_use]
    pub fn new(lo: (f64, f64), hi: (f64, f64), cell: f64) -> Self {
        let width = (((hi.0 - lo.0) / cell).ceil() as usize).max(1);
        let height = (((hi.1 - lo.1) / cell).ceil() as usize).max(1);
        Self {
            origin: lo,
            cell,
            width,
            height,
            hits: vec![0; width * height],
            passes: vec![0; width * height],
        }
    }

    fn cell_of(&self, x: f64, y: f64) -> (i64, i64) {
        (
            ((x - self.origin.0) / self.cell).floor() as i64,
            ((y - self.origin.1) / self.cell).floor() as i64,
        )
    }

    fn index(&self, cx: i64, cy: i64) -> Option<usize> {
        (cx >= 0 && cy >= 0 && (cx as usize) < self.width && (cy as usize) < self.height)
            .then(|| cy as usize * self.width + cx as usize)
    }

    /// Adds one scan taken from `laser` (the laser's pose in the world): every return marks
    /// its cell hit and the cells on the beam before it free; no-returns mark free space up to
    /// [`FREE_SPACE_MAX_M`].
    pub fn insert_scan(&mut self, laser: &Pose2, scan: &Scan) {
        let origin = self.cell_of(laser.x, laser.y);
        let free_max = FREE_SPACE_MAX_M.min(scan.geometry.max_range);
        for (i, (&range, status)) in scan.ranges().iter().zip(scan.status()).enumerate() {
            let (hit, reach) = match status {
                BeamStatus::Valid => (true, range),
                BeamStatus::MaxRange => (false, free_max),
                BeamStatus::TooClose | BeamStatus::Invalid => continue,
            };
            let bearing = laser.theta + scan.geometry.angle(i);
            let end = self.cell_of(
                laser.x + reach * bearing.cos(),
                laser.y + reach * bearing.sin(),
            );
            self.trace_free(origin, end);
            if hit && let Some(k) = self.index(end.0, end.1) {
                self.hits[k] += 1;
            }
        }
    }

    /// Counts a pass in every cell from `a` up to, not including, `b` (Bresenham).
    fn trace_free(&mut self, a: (i64, i64), b: (i64, i64)) {
        let (dx, dy) = ((b.0 - a.0).abs(), -(b.1 - a.1).abs());
        let (sx, sy) = ((b.0 - a.0).signum(), (b.1 - a.1).signum());
        let (mut x, mut y, mut err) = (a.0, a.1, dx + dy);
        while (x, y) != b {
            if let Some(k) = self.index(x, y) {
                self.passes[k] += 1;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// Cells with at least one hit.
    #[must_use]
    pub fn occupied_cells(&self) -> usize {
        self.hits.iter().filter(|&&h| h > 0).count()
    }

    /// The shade of the block of cells `[cx0, cx1) × [cy0, cy1)`: the darkest cell decides
    /// (thin trunks survive pooling). Occupied: grey to black with the share of hits; free:
    /// white; never seen: light grey.
    fn shade(&self, cx0: usize, cx1: usize, cy0: usize, cy1: usize) -> RGBColor {
        let (mut best, mut seen) = (0.0f64, false);
        for cy in cy0..cy1.min(self.height) {
            for cx in cx0..cx1.min(self.width) {
                let k = cy * self.width + cx;
                let (h, p) = (f64::from(self.hits[k]), f64::from(self.passes[k]));
                if h + p > 0.0 {
                    seen = true;
                    best = best.max(h / (h + p));
                }
            }
        }
        if best > 0.0 {
            // 1 hit among many passes still shows; a cell hit every time is black.
            let v = (170.0 * (1.0 - best.sqrt())) as u8;
            RGBColor(v, v, v)
        } else if seen {
            WHITE
        } else {
            RGBColor(205, 205, 205)
        }
    }
}

/// Bounds `[lo, hi]` of the scans' returns at `poses` (0.1 % trimmed against stray far
/// returns) and the poses, with a 2 m margin.
pub(super) fn map_bounds(
    poses: &[Pose2],
    scans: &[&Scan],
    extra: &[Pose2],
) -> ((f64, f64), (f64, f64)) {
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for (pose, scan) in poses.iter().zip(scans) {
        for p in scan.points() {
            let q = *pose * *p;
            xs.push(q.x);
            ys.push(q.y);
        }
    }
    let q = |v: &[f64], f| qicp_runner::matching::quantile(v, f);
    let (mut lo, mut hi) = if xs.is_empty() {
        (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        )
    } else {
        (
            (q(&xs, 0.001), q(&ys, 0.001)),
            (q(&xs, 0.999), q(&ys, 0.999)),
        )
    };
    for p in poses.iter().chain(extra) {
        lo = (lo.0.min(p.x), lo.1.min(p.y));
        hi = (hi.0.max(p.x), hi.1.max(p.y));
    }
    ((lo.0 - 2.0, lo.1 - 2.0), (hi.0 + 2.0, hi.1 + 2.0))
}

/// Draws `map_<kind>.png`: the scans at the laser poses `lasers` into a [`MAP_CELL_M`] grid
/// (black: hit, white: seen free, grey: never seen), the estimated robot path `path` and, when
/// known, the true path. Returns the number of occupied cells.
pub fn occupancy_map(
    out: &Path,
    title: &str,
    lasers: &[Pose2],
    scans: &[&Scan],
    path: &[Pose2],
    truth: Option<&[Pose2]>,
) -> Result<usize, PlotError> {
    if lasers.is_empty() {
        return Err(PlotError::Empty {
            path: out.display().to_string(),
            why: "no scans",
        });
    }
    let (lo, hi) = map_bounds(lasers, scans, truth.unwrap_or(&[]));
    let mut canvas = MapCanvas::new(lo, hi);
    for (laser, scan) in lasers.iter().zip(scans) {
        canvas.insert_scan(laser, scan);
    }
    canvas.draw(out, title, path, truth)
}

/// A map being drawn: the occupancy grid over fixed bounds, filled one scan at a time (so
/// the scans need not be held), then drawn with the paths by [`MapCanvas::draw`].
#[derive(Debug, Clone)]
pub struct MapCanvas {
    grid: OccupancyGrid,
    zoom: f64,
    plot: (u32, u32),
    x: (f64, f64),
    y: (f64, f64),
    /// Returns in each legend corner: upper right, upper left, lower right, lower left.
    corners: [usize; 4],
}

impl MapCanvas {
    /// An empty map over `[lo, hi]` (m), e.g. [`MapExtent::bounds`].
    #[must_use]
    pub fn new(lo: (f64, f64), hi: (f64, f64)) -> Self {
        let grid = OccupancyGrid::new(lo, hi, MAP_CELL_M);
        // Pixels per cell side.
        let zoom = (MAP_PIXELS / grid.width.max(grid.height) as f64).min(MAP_MAX_ZOOM);
        let plot_w = ((grid.width as f64 * zoom).ceil() as u32).max(1);
        let plot_h = ((grid.height as f64 * zoom).ceil() as u32).max(1);
        let m_per_px = MAP_CELL_M / zoom;
        let (x0, y0) = grid.origin;
        let (x1, y1) = (
            x0 + f64::from(plot_w) * m_per_px,
            y0 + f64::from(plot_h) * m_per_px,
        );
        Self {
            grid,
            zoom,
            plot: (plot_w, plot_h),
            x: (x0, x1),
            y: (y0, y1),
            corners: [0; 4],
        }
    }

    /// Adds one scan taken from `laser` (the laser's pose in the world).
    pub fn insert_scan(&mut self, laser: &Pose2, scan: &Scan) {
        self.grid.insert_scan(laser, scan);
        let returns = scan.points().iter().map(|p| {
            let q = *laser * *p;
            (q.x, q.y)
        });
        count_corners(&mut self.corners, returns, self.x, self.y);
    }

    /// Draws the map into `out` with the estimated robot path `path` and, when known, the
    /// true path. Returns the number of occupied cells.
    pub fn draw(
        mut self,
        out: &Path,
        title: &str,
        path: &[Pose2],
        truth: Option<&[Pose2]>,
    ) -> Result<usize, PlotError> {
        register_fonts();
        let grid = &self.grid;
        let zoom = self.zoom;
        let (plot_w, plot_h) = self.plot;
        // The cells under pixel column (or row) k: [k/zoom, (k+1)/zoom), at least one.
        let cells = |k: u32| {
            let a = (f64::from(k) / zoom).floor() as usize;
            let b = ((f64::from(k + 1) / zoom).floor() as usize).max(a + 1);
            (a, b)
        };
        let ((x0, x1), (y0, y1)) = (self.x, self.y);
        // The frame around the plotting area has a fixed size: measure it once, then size the
        // picture so that the plotting area is exactly plot_w × plot_h (1:1 aspect).
        let (fw, fh) = {
            let (tw, th) = (2000u32, 2000u32);
            let mut buf = vec![0u8; (tw * th * 3) as usize];
            let root = BitMapBackend::with_buffer(&mut buf, (tw, th)).into_drawing_area();
            let chart = tri!(out, map_chart(&root, title, (x0, x1), (y0, y1)));
            let (pw, ph) = chart.plotting_area().dim_in_pixel();
            (tw - pw, th - ph)
        };
        let size = (plot_w + fw, plot_h + fh);
        let root = BitMapBackend::new(out, size).into_drawing_area();
        tri!(out, root.fill(&WHITE));
        let mut chart = tri!(out, map_chart(&root, title, (x0, x1), (y0, y1)));
        {
            let area = chart.plotting_area().strip_coord_spec();
            let (pw, ph) = area.dim_in_pixel();
            for py in 0..ph.min(plot_h) {
                // Pixel rows go down, grid rows up.
                let (cy0, cy1) = cells(plot_h - 1 - py);
                for px in 0..pw.min(plot_w) {
                    let (cx0, cx1) = cells(px);
                    let c = grid.shade(cx0, cx1, cy0, cy1);
                    tri!(out, area.draw_pixel((px as i32, py as i32), &c));
                }
            }
        }
        tri!(
            out,
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x (m)")
                .y_desc("y (m)")
                .x_label_formatter(&|v| tick(*v))
                .y_label_formatter(&|v| tick(*v))
                .label_style((FONT, 16))
                .axis_desc_style((FONT, 18))
                .draw()
        );
        for (label, color) in [
            ("hit (5 cm cells)", RGBColor(0, 0, 0)),
            ("seen free", WHITE),
            ("never seen", RGBColor(205, 205, 205)),
        ] {
            tri!(
                out,
                chart.draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())
            )
            .label(label)
            .legend(move |(x, y)| {
                EmptyElement::at((x, y))
                    + Rectangle::new([(4, -7), (18, 7)], color.filled())
                    + Rectangle::new([(4, -7), (18, 7)], BLACK.stroke_width(1))
            });
        }
        if let Some(truth) = truth {
            let style = RGBColor(150, 150, 150).stroke_width(5);
            draw_path(out, &mut chart, truth, style)?;
            legend_entry(out, &mut chart, "true path", style)?;
        }
        let style = PALETTE[1].stroke_width(2);
        draw_path(out, &mut chart, path, style)?;
        legend_entry(out, &mut chart, "estimated path", style)?;
        if let Some(start) = path.first() {
            tri!(
                out,
                chart.draw_series(std::iter::once(Circle::new(
                    (start.x, start.y),
                    6,
                    PALETTE[0].filled()
                )))
            )
            .label("start")
            .legend(|(x, y)| Circle::new((x + 12, y), 5, PALETTE[0].filled()));
        }
        // Where the legend hides the fewest returns and path.
        count_corners(
            &mut self.corners,
            path.iter().map(|p| (p.x, p.y)),
            (x0, x1),
            (y0, y1),
        );
        let corner = corner_of(&self.corners);
        finish_with_legend(out, &root, &mut chart, corner)?;
        Ok(self.grid.occupied_cells())
    }
}

type MapChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

pub(super) fn map_chart<'a, 'b>(
    root: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    title: &str,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) -> Result<MapChart<'a, 'b>, DrawingAreaErrorKind<<BitMapBackend<'b> as DrawingBackend>::ErrorType>>
{
    ChartBuilder::on(root)
        .caption(title, (FONT, 22))
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)
}

/// The corner of `[x0, x1] × [y0, y1]` whose legend-sized box (a quarter of the width, a third
/// of the height) holds the fewest of `points`: where the legend hides the least.
pub(super) fn emptiest_corner(
    points: impl Iterator<Item = (f64, f64)>,
    x: (f64, f64),
    y: (f64, f64),
) -> SeriesLabelPosition {
    let mut counts = [0usize; 4];
    count_corners(&mut counts, points, x, y);
    corner_of(&counts)
}

/// Adds to `counts` (upper right, upper left, lower right, lower left) the `points` in each
/// legend-sized corner box of `[x0, x1] × [y0, y1]`.
fn count_corners(
    counts: &mut [usize; 4],
    points: impl Iterator<Item = (f64, f64)>,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) {
    let (w, h) = ((x1 - x0) / 4.0, (y1 - y0) / 3.0);
    for (x, y) in points {
        let right = x > x1 - w;
        let left = x < x0 + w;
        let upper = y > y1 - h;
        let lower = y < y0 + h;
        counts[0] += usize::from(upper && right);
        counts[1] += usize::from(upper && left);
        counts[2] += usize::from(lower && right);
        counts[3] += usize::from(lower && left);
    }
}

/// The corner of [`count_corners`]' counts holding the fewest points (the first of equals).
fn corner_of(counts: &[usize; 4]) -> SeriesLabelPosition {
    let best = (0..4).min_by_key(|&k| counts[k]).unwrap_or(0);
    [
        SeriesLabelPosition::UpperRight,
        SeriesLabelPosition::UpperLeft,
        SeriesLabelPosition::LowerRight,
        SeriesLabelPosition::LowerLeft,
    ][best]
        .clone()
}

/// Draws a path as separate segments (round joints for thick lines), leaving out steps under
/// a millimetre: plotters draws a zero-length thick segment, or the joint of a polyline that
/// turns back on itself, as a line shooting far out of the path.
pub(super) fn draw_path<'a, 'b: 'a>(
    out: &Path,
    chart: &mut ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    poses: &[Pose2],
    style: ShapeStyle,
) -> Result<(), PlotError> {
    // A zero-length thick segment has no direction: plotters draws it as a stray line.
    let mut points: Vec<(f64, f64)> = Vec::with_capacity(poses.len());
    for p in poses.iter().filter(|p| p.x.is_finite() && p.y.is_finite()) {
        if points
            .last()
            .is_none_or(|&(x, y)| (p.x - x).hypot(p.y - y) > 1e-3)
        {
            points.push((p.x, p.y));
        }
    }
    tri!(
        out,
        chart.draw_series(
            points
                .windows(2)
                .map(|w| PathElement::new(vec![w[0], w[1]], style))
        )
    );
    if style.stroke_width > 2 {
        let r = style.stroke_width / 2;
        let joint = ShapeStyle {
            filled: true,
            stroke_width: 0,
            ..style
        };
        tri!(
            out,
            chart.draw_series(points.iter().map(|&p| Circle::new(p, r, joint)))
        );
    }
    Ok(())
}

/// A legend line for something drawn without a label.
/// Draws the legend in `corner` and writes the picture.
pub(super) fn finish_with_legend<'a, 'b: 'a>(
    out: &Path,
    root: &DrawingArea<BitMapBackend<'b>, Shift>,
    chart: &mut ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    corner: SeriesLabelPosition,
) -> Result<(), PlotError> {
    tri!(
        out,
        chart
            .configure_series_labels()
            .position(corner)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 16))
            .draw()
    );
    tri!(out, root.present());
    Ok(())
}

pub(super) fn legend_entry<'a, 'b: 'a>(
    out: &Path,
    chart: &mut ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    label: &str,
    style: ShapeStyle,
) -> Result<(), PlotError> {
    tri!(
        out,
        chart.draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
    )
    .label(label)
    .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], style));
    Ok(())
}
