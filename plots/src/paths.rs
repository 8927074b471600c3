//! Robot paths, one series per matcher.

use super::*;

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
    finish_with_legend(out, &root, &mut chart, corner)?;
    Ok(())
}
