//! Per-scan values in panels (paper Fig. 4).

use super::*;

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
        let q = |f| qicp_runner::matching::quantile(&all, f);
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

pub(super) fn draw_panel<'a, 'b: 'a>(
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
        let median = qicp_runner::matching::quantile(&finite, 0.5);
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
pub(super) fn tick(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Three significant digits.
pub(super) fn short(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    let digits = (2 - v.abs().max(1e-12).log10().floor() as i32).clamp(0, 6) as usize;
    format!("{v:.digits$}")
}
