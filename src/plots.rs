//! The pictures of `qicp run` (PNG), in the style of the paper's figures:
//!
//! - [`occupancy_map`]: every scan drawn at a matcher's poses into a 5 cm occupancy grid, the
//!   estimated path and the true one on top (paper Figs. 3, 5, 6);
//! - [`trajectories`]: every matcher's path with the truth and raw odometry;
//! - [`per_scan`]: a value per scan, one panel per matcher family, a series drawn in front of
//!   another and each series' mean as a thick line (paper Fig. 4).
//!
//! Text uses DejaVu Sans, embedded from the `dejavu` crate and rasterised by `ab_glyph`: no
//! system font or fontconfig is needed.

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use qicp_core::{BeamStatus, Pose2, Scan};
use std::path::Path;
use thiserror::Error;

/// Why a picture could not be drawn.
#[derive(Debug, Error)]
pub enum PlotError {
    /// The drawing backend failed (usually writing the file).
    #[error("drawing {path}: {message}")]
    Draw {
        /// The picture.
        path: String,
        /// What plotters reported.
        message: String,
    },
    /// There is nothing to draw.
    #[error("drawing {path}: {why}")]
    Empty {
        /// The picture.
        path: String,
        /// What is missing.
        why: &'static str,
    },
}

/// Side of an occupancy-grid cell (m).
pub const MAP_CELL_M: f64 = 0.05;
/// No-return beams mark free space up to this range (m), at most the laser's maximum.
pub const FREE_SPACE_MAX_M: f64 = 20.0;
/// Longest side of a map's plotting area (pixels): larger maps pool several cells into a
/// pixel, smaller ones draw a cell as a block of up to [`MAP_MAX_ZOOM`] pixels.
pub const MAP_PIXELS: f64 = 1400.0;
/// Most pixels per cell side of a small map.
pub const MAP_MAX_ZOOM: f64 = 3.0;

const FONT: &str = "sans-serif";

/// Colours of the series, in report order (a colour-blind-safe palette, Wong 2011).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 114, 178),   // blue
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(230, 159, 0),   // orange
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(240, 228, 66),  // yellow
];
/// Colour of the true path.
pub const TRUTH_COLOR: RGBColor = RGBColor(0, 0, 0);
/// Colour of the raw odometry path.
pub const ODOMETRY_COLOR: RGBColor = RGBColor(150, 150, 150);

/// Registers the embedded font with plotters (once per process).
fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            // The bytes are a valid TrueType font; a failure would leave text undrawn, not
            // break the picture.
            let _ =
                plotters::style::register_font(family, FontStyle::Normal, dejavu::sans::regular());
            let _ = plotters::style::register_font(family, FontStyle::Bold, dejavu::sans::bold());
        }
    });
}

fn draw_err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError::Draw {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// `?` for plotters results: turns any plotters error into [`PlotError::Draw`].
macro_rules! tri {
    ($path:expr, $e:expr) => {
        $e.map_err(|e| draw_err($path)(&e))?
    };
}

// ---------------------------------------------------------------------------------------------
// Occupancy map

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
fn map_bounds(poses: &[Pose2], scans: &[&Scan], extra: &[Pose2]) -> ((f64, f64), (f64, f64)) {
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for (pose, scan) in poses.iter().zip(scans) {
        for p in scan.points() {
            let q = *pose * *p;
            xs.push(q.x);
            ys.push(q.y);
        }
    }
    let q = |v: &[f64], f| crate::matching::quantile(v, f);
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
    register_fonts();
    let (lo, hi) = map_bounds(lasers, scans, truth.unwrap_or(&[]));
    let mut grid = OccupancyGrid::new(lo, hi, MAP_CELL_M);
    for (laser, scan) in lasers.iter().zip(scans) {
        grid.insert_scan(laser, scan);
    }
    // Pixels per cell side.
    let zoom = (MAP_PIXELS / grid.width.max(grid.height) as f64).min(MAP_MAX_ZOOM);
    let plot_w = ((grid.width as f64 * zoom).ceil() as u32).max(1);
    let plot_h = ((grid.height as f64 * zoom).ceil() as u32).max(1);
    let m_per_px = MAP_CELL_M / zoom;
    // The cells under pixel column (or row) k: [k/zoom, (k+1)/zoom), at least one.
    let cells = |k: u32| {
        let a = (f64::from(k) / zoom).floor() as usize;
        let b = ((f64::from(k + 1) / zoom).floor() as usize).max(a + 1);
        (a, b)
    };
    let (x0, y0) = grid.origin;
    let (x1, y1) = (
        x0 + f64::from(plot_w) * m_per_px,
        y0 + f64::from(plot_h) * m_per_px,
    );

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
    let returns = lasers.iter().zip(scans).flat_map(|(l, s)| {
        s.points().iter().map(move |p| {
            let q = *l * *p;
            (q.x, q.y)
        })
    });
    let corner = emptiest_corner(
        returns.chain(path.iter().map(|p| (p.x, p.y))),
        (x0, x1),
        (y0, y1),
    );
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
    Ok(grid.occupied_cells())
}

type MapChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn map_chart<'a, 'b>(
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
fn emptiest_corner(
    points: impl Iterator<Item = (f64, f64)>,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) -> SeriesLabelPosition {
    let (w, h) = ((x1 - x0) / 4.0, (y1 - y0) / 3.0);
    let mut counts = [0usize; 4]; // upper right, upper left, lower right, lower left
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
fn draw_path<'a, 'b: 'a>(
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
fn legend_entry<'a, 'b: 'a>(
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

// ---------------------------------------------------------------------------------------------
// Trajectories

/// One path of [`trajectories`].
#[derive(Debug, Clone)]
pub struct PathSeries<'a> {
    /// Legend text.
    pub label: String,
    /// Robot positions.
    pub poses: &'a [Pose2],
    /// Line colour.
    pub color: RGBColor,
    /// Line width (pixels).
    pub width: u32,
    /// Dashed (for a series that may coincide with an earlier one).
    pub dashed: bool,
}

/// Draws `trajectories.png`: every path in metres on equal axes, drawn in the given order
/// (later in front), with a legend.
pub fn trajectories(out: &Path, title: &str, series: &[PathSeries<'_>]) -> Result<(), PlotError> {
    register_fonts();
    let points = series.iter().flat_map(|s| s.poses.iter());
    let (mut lo, mut hi) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for p in points.filter(|p| p.x.is_finite() && p.y.is_finite()) {
        lo = (lo.0.min(p.x), lo.1.min(p.y));
        hi = (hi.0.max(p.x), hi.1.max(p.y));
    }
    if !lo.0.is_finite() {
        return Err(PlotError::Empty {
            path: out.display().to_string(),
            why: "no poses",
        });
    }
    // Equal axes: pad the shorter side; a 1200 px wide plot at most 900 px high.
    let pad = 0.05 * (hi.0 - lo.0).max(hi.1 - lo.1).max(1.0);
    let (mut w, mut h) = (hi.0 - lo.0 + 2.0 * pad, hi.1 - lo.1 + 2.0 * pad);
    let (cx, cy) = ((lo.0 + hi.0) / 2.0, (lo.1 + hi.1) / 2.0);
    let (plot_w, plot_h) = if w / h > 1200.0 / 900.0 {
        (1200u32, ((1200.0 * h / w).round() as u32).max(300))
    } else {
        (((900.0 * w / h).round() as u32).max(400), 900u32)
    };
    // Widen the ranges to the pixel aspect so one metre has the same length on both axes.
    let aspect = f64::from(plot_w) / f64::from(plot_h);
    if w / h < aspect {
        w = h * aspect;
    } else {
        h = w / aspect;
    }
    let (x0, x1, y0, y1) = (cx - w / 2.0, cx + w / 2.0, cy - h / 2.0, cy + h / 2.0);
    let frame = (12 * 2 + 64, 12 * 2 + 50 + 40);
    let root = BitMapBackend::new(out, (plot_w + frame.0, plot_h + frame.1)).into_drawing_area();
    tri!(out, root.fill(&WHITE));
    let mut chart = tri!(
        out,
        ChartBuilder::on(&root)
            .caption(title, (FONT, 22))
            .margin(12)
            .x_label_area_size(50)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, y0..y1)
    );
    tri!(
        out,
        chart
            .configure_mesh()
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(215, 215, 215))
            .x_desc("x (m)")
            .y_desc("y (m)")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style((FONT, 16))
            .axis_desc_style((FONT, 18))
            .draw()
    );
    for s in series {
        let style = s.color.stroke_width(s.width);
        let points = s.poses.iter().map(|p| (p.x, p.y));
        if s.dashed {
            tri!(
                out,
                chart.draw_series(DashedLineSeries::new(points, 10, 7, style))
            );
        } else {
            draw_path(out, &mut chart, s.poses, style)?;
        }
        tri!(
            out,
            chart.draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
        )
        .label(s.label.clone())
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], style));
    }
    if let Some(start) = series.first().and_then(|s| s.poses.first()) {
        tri!(
            out,
            chart.draw_series(std::iter::once(Circle::new(
                (start.x, start.y),
                6,
                BLACK.filled()
            )))
        )
        .label("start")
        .legend(|(x, y)| Circle::new((x + 12, y), 5, BLACK.filled()));
    }
    let corner = emptiest_corner(
        series
            .iter()
            .flat_map(|s| s.poses.iter().map(|p| (p.x, p.y))),
        (x0, x1),
        (y0, y1),
    );
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

// ---------------------------------------------------------------------------------------------
// Per-scan values (paper Fig. 4)

/// One series of a [`Panel`]: a value per scan (NaN: no value, a gap).
#[derive(Debug, Clone)]
pub struct ScanSeries {
    /// Legend text (the mean is appended).
    pub label: String,
    /// One value per scan.
    pub values: Vec<f64>,
    /// Colour.
    pub color: RGBColor,
}

/// One panel of [`per_scan`]: series drawn in order, later in front.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Panel title.
    pub title: String,
    /// Series, back to front.
    pub series: Vec<ScanSeries>,
    /// A dashed horizontal reference line (e.g. 1 for a ratio), if any.
    pub reference: Option<f64>,
    /// Upper end of the y axis at most this (for ratios, whose tails reach far past the bulk).
    pub y_cap: Option<f64>,
}

/// Draws panels side by side: x = scan index, y = `y_desc`; each series as a thin line with
/// its mean as a thick line of the same colour (paper Fig. 4), the legend giving mean and
/// median. The y axis runs from 0 to the 99.5 % quantile of the values (at most the panel's
/// `y_cap`) so a few outliers do not flatten the rest; values beyond it are drawn at its edge.
pub fn per_scan(out: &Path, y_desc: &str, panels: &[Panel]) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::Empty {
            path: out.display().to_string(),
            why: "no panels",
        });
    }
    register_fonts();
    let (pw, ph) = (760u32, 520u32);
    let root = BitMapBackend::new(out, (pw * panels.len() as u32, ph)).into_drawing_area();
    tri!(out, root.fill(&WHITE));
    let areas = root.split_evenly((1, panels.len()));
    for (area, panel) in areas.iter().zip(panels) {
        let all: Vec<f64> = panel
            .series
            .iter()
            .flat_map(|s| s.values.iter().copied())
            .filter(|v| v.is_finite())
            .collect();
        let n = panel
            .series
            .iter()
            .map(|s| s.values.len())
            .max()
            .unwrap_or(0);
        let x_max = (n.max(2) - 1) as f64;
        let q = |f| crate::matching::quantile(&all, f);
        let mut hi = q(0.995) * 1.15;
        if let Some(cap) = panel.y_cap {
            hi = hi.min(cap);
        }
        if let Some(r) = panel.reference {
            hi = hi.max(r * 1.2);
        }
        if !(hi.is_finite() && hi > 0.0) {
            hi = 1.0;
        }
        let caption = (FONT, 20);
        let mut builder = ChartBuilder::on(area);
        builder
            .caption(&panel.title, caption)
            .margin(12)
            .x_label_area_size(46)
            .y_label_area_size(70);
        let c = tri!(out, builder.build_cartesian_2d(0f64..x_max, 0f64..hi));
        draw_panel(out, c, panel, y_desc, x_max, (0.0, hi))?;
    }
    tri!(out, root.present());
    Ok(())
}

fn draw_panel<'a, 'b: 'a>(
    out: &Path,
    mut chart: ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    panel: &Panel,
    y_desc: &str,
    x_max: f64,
    (lo, hi): (f64, f64),
) -> Result<(), PlotError> {
    tri!(
        out,
        chart
            .configure_mesh()
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(220, 220, 220))
            .x_desc("scan")
            .y_desc(y_desc)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| tick(*v))
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 17))
            .draw()
    );
    if let Some(r) = panel.reference {
        tri!(
            out,
            chart.draw_series(DashedLineSeries::new(
                [(0.0, r), (x_max, r)],
                8,
                6,
                BLACK.stroke_width(1),
            ))
        );
    }
    let mut means = Vec::new();
    for s in &panel.series {
        let usable = |v: f64| v.is_finite();
        let finite: Vec<f64> = s.values.iter().copied().filter(|v| usable(*v)).collect();
        let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
        let median = crate::matching::quantile(&finite, 0.5);
        let color = s.color;
        // Gaps where a scan has no value (a fallback); single scans as dots.
        let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for (i, v) in s.values.iter().enumerate() {
            if usable(*v) {
                if let Some(r) = runs.last_mut() {
                    r.push((i as f64, v.clamp(lo, hi)));
                }
            } else if runs.last().is_some_and(|r| !r.is_empty()) {
                runs.push(Vec::new());
            }
        }
        let style = color.mix(0.85).stroke_width(1);
        for r in runs.iter().filter(|r| r.len() > 1) {
            tri!(
                out,
                chart.draw_series(LineSeries::new(r.iter().copied(), style))
            );
        }
        let singles = runs
            .iter()
            .filter(|r| r.len() == 1)
            .map(|r| Circle::new(r[0], 1, color.filled()));
        tri!(out, chart.draw_series(singles))
            .label(format!(
                "{} (mean {}{}, median {})",
                s.label,
                short(mean),
                if mean > hi { ", off scale" } else { "" },
                short(median)
            ))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], color.stroke_width(4)));
        means.push((mean, color));
    }
    // Means on top of every series (the thick lines of Fig. 4), outlined in black.
    for (mean, color) in means.into_iter().filter(|(m, _)| m.is_finite()) {
        let span = [(0.0, mean.clamp(lo, hi)), (x_max, mean.clamp(lo, hi))];
        tri!(
            out,
            chart.draw_series(LineSeries::new(span, BLACK.stroke_width(6)))
        );
        tri!(
            out,
            chart.draw_series(LineSeries::new(span, color.stroke_width(3)))
        );
    }
    tri!(
        out,
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .label_font((FONT, 15))
            .draw()
    );
    Ok(())
}

/// An axis tick: at most three decimals, trailing zeros dropped.
fn tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Three significant digits.
fn short(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    let digits = (2 - v.abs().max(1e-12).log10().floor() as i32).clamp(0, 6) as usize;
    format!("{v:.digits$}")
}
