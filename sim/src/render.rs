//! `world.png`: the obstacles, the foliage, the true path and the odometry path, drawn without
//! fonts.
//!
//! Colours: obstacles black, foliage pale green, true path green, odometry path red, start
//! blue; the light grey grid has 10 m spacing.

use crate::world::World;
use nalgebra::Point2;
use qicp_core::Pose2;
use std::io::Write;

/// Colour of the obstacles.
pub const OBSTACLE: [u8; 3] = [20, 20, 20];
/// Colour of the foliage.
pub const FOLIAGE: [u8; 3] = [170, 215, 160];
/// Colour of the true path.
pub const TRUTH: [u8; 3] = [0, 150, 0];
/// Colour of the odometry path.
pub const ODOMETRY: [u8; 3] = [220, 30, 30];
/// Colour of the start marker.
pub const START: [u8; 3] = [30, 60, 220];
/// Colour of the 10 m grid.
pub const GRID: [u8; 3] = [225, 225, 225];
/// What the colours mean, for summaries and READMEs.
pub const LEGEND: &str = "black: obstacles, pale green: foliage, green: true path, \
red: odometry path, blue dot: start, grey grid: 10 m";

/// An RGB raster with a world-to-pixel mapping.
#[derive(Debug, Clone)]
struct Canvas {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
    origin: Point2<f64>,
    scale: f64,
}

impl Canvas {
    fn new(lo: Point2<f64>, hi: Point2<f64>, max_side: u32) -> Self {
        let span = (hi.x - lo.x).max(hi.y - lo.y).max(1e-3);
        let scale = f64::from(max_side) / span;
        let width = (((hi.x - lo.x) * scale).ceil() as u32).max(1);
        let height = (((hi.y - lo.y) * scale).ceil() as u32).max(1);
        Self {
            width,
            height,
            pixels: vec![255; (width * height * 3) as usize],
            origin: lo,
            scale,
        }
    }

    /// Pixel coordinates (x right, y down) of a world point.
    fn to_px(&self, p: &Point2<f64>) -> (f64, f64) {
        (
            (p.x - self.origin.x) * self.scale,
            f64::from(self.height) - (p.y - self.origin.y) * self.scale,
        )
    }

    fn to_world(&self, px: f64, py: f64) -> Point2<f64> {
        Point2::new(
            self.origin.x + px / self.scale,
            self.origin.y + (f64::from(self.height) - py) / self.scale,
        )
    }

    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = ((y as u32 * self.width + x as u32) * 3) as usize;
            self.pixels[i..i + 3].copy_from_slice(&c);
        }
    }

    fn disk(&mut self, cx: f64, cy: f64, r: f64, c: [u8; 3]) {
        let r = r.max(0.5);
        for y in (cy - r).floor() as i64..=(cy + r).ceil() as i64 {
            for x in (cx - r).floor() as i64..=(cx + r).ceil() as i64 {
                let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                if dx * dx + dy * dy <= r * r {
                    self.put(x, y, c);
                }
            }
        }
    }

    fn line(&mut self, a: &Point2<f64>, b: &Point2<f64>, width: f64, c: [u8; 3]) {
        let (ax, ay) = self.to_px(a);
        let (bx, by) = self.to_px(b);
        let n = ((bx - ax).hypot(by - ay) * 2.0).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            self.disk(ax + (bx - ax) * t, ay + (by - ay) * t, width / 2.0, c);
        }
    }

    fn path(&mut self, poses: &[Pose2], width: f64, c: [u8; 3]) {
        for w in poses.windows(2) {
            let a = Point2::new(w[0].x, w[0].y);
            let b = Point2::new(w[1].x, w[1].y);
            self.line(&a, &b, width, c);
        }
    }
}

/// Draws the world with the true and odometry paths and writes it as PNG.
pub fn write_png<W: Write>(
    out: W,
    world: &World,
    truth: &[Pose2],
    odometry: &[Pose2],
) -> std::io::Result<()> {
    let (mut lo, mut hi) = world.bounds;
    for p in truth.iter().chain(odometry) {
        if p.is_finite() {
            lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
        }
    }
    let margin = 0.03 * (hi.x - lo.x).max(hi.y - lo.y) + 0.5;
    lo -= nalgebra::Vector2::new(margin, margin);
    hi += nalgebra::Vector2::new(margin, margin);
    let mut canvas = Canvas::new(lo, hi, 1200);

    // 10 m grid.
    let mut gx = (lo.x / 10.0).ceil() * 10.0;
    while gx <= hi.x {
        canvas.line(&Point2::new(gx, lo.y), &Point2::new(gx, hi.y), 1.0, GRID);
        gx += 10.0;
    }
    let mut gy = (lo.y / 10.0).ceil() * 10.0;
    while gy <= hi.y {
        canvas.line(&Point2::new(lo.x, gy), &Point2::new(hi.x, gy), 1.0, GRID);
        gy += 10.0;
    }

    // Obstacles: every pixel within half a pixel of an obstacle's inside, so thin walls show;
    // foliage first, under them.
    let half_px = 0.5 / canvas.scale;
    let foliage = world.foliage.iter().map(|f| (f.outline(), FOLIAGE));
    let solids = world.obstacles.iter().map(|o| (*o, OBSTACLE));
    for (o, colour) in foliage.chain(solids) {
        let c = o.center();
        let r = o.bounding_radius() + half_px;
        let (x0, y0) = canvas.to_px(&Point2::new(c.x - r, c.y + r));
        let (x1, y1) = canvas.to_px(&Point2::new(c.x + r, c.y - r));
        for y in y0.floor() as i64..=y1.ceil() as i64 {
            for x in x0.floor() as i64..=x1.ceil() as i64 {
                let p = canvas.to_world(x as f64 + 0.5, y as f64 + 0.5);
                if o.signed_distance(&p) <= half_px {
                    canvas.put(x, y, colour);
                }
            }
        }
    }

    canvas.path(odometry, 2.0, ODOMETRY);
    canvas.path(truth, 2.0, TRUTH);
    if let Some(s) = truth.first() {
        let (x, y) = canvas.to_px(&Point2::new(s.x, s.y));
        canvas.disk(x, y, 5.0, START);
    }

    let mut enc = png::Encoder::new(out, canvas.width, canvas.height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().map_err(std::io::Error::other)?;
    w.write_image_data(&canvas.pixels)
        .map_err(std::io::Error::other)?;
    w.finish().map_err(std::io::Error::other)
}
