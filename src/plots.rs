//! PNG plots of the fits, which people would rather look at than read:
//! noise std vs luma per level and channel with the samples behind it, δ vs depth
//! with the per-pixel estimates and both fitted forms, and the MB loss over λ.
//! Labels use the bundled DejaVu Sans (no system font lookup).

use crate::fit::{DofPlotData, MbPlotData, NoisePlotData};
use crate::model::{DepthOfField, DepthUnits, DofCurve, Noise};
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

#[derive(Debug, thiserror::Error)]
#[error("plot {path}: {problem}")]
pub struct PlotError {
    pub path: String,
    pub problem: String,
}

fn err(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError { path: path.display().to_string(), problem: e.to_string() }
}

fn register_font() {
    static ONCE: OnceLock<()> = OnceLock::new();
    ONCE.get_or_init(|| {
        let font: &'static [u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
        if plotters::style::register_font("sans-serif", FontStyle::Normal, font).is_err() {
            log::warn!("bundled font could not be registered; plot labels may be missing");
        }
    });
}

const CHANNEL_COLOURS: [RGBColor; 3] = [RGBColor(220, 50, 47), RGBColor(60, 160, 60), RGBColor(38, 110, 210)];

/// Every k-th index so at most `max` points are drawn.
fn thin(n: usize, max: usize) -> impl Iterator<Item = usize> {
    (0..n).step_by(n.div_ceil(max).max(1))
}

/// Noise: one panel per level (and the low-pass if modelled): samples as dots,
/// the fitted map as lines, per channel.
pub fn noise_plot(path: &Path, data: &NoisePlotData, noise: &Noise) -> Result<(), PlotError> {
    register_font();
    let root = BitMapBackend::new(path, (1500, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(path, e))?;
    let panels = root.split_evenly((2, 3));
    let levels: Vec<(String, Option<crate::model::NoiseLevel>)> = (0..data.levels.len())
        .map(|l| {
            if l < noise.levels.len() {
                (format!("level {l}"), Some(noise.levels[l]))
            } else {
                ("low-pass".to_string(), noise.lowpass)
            }
        })
        .collect();
    for (l, (title, level)) in levels.iter().enumerate() {
        let (ys, stds) = &data.levels[l];
        let mut ymax = stds.iter().flatten().cloned().fold(1e-6f32, f32::max);
        if let Some(lv) = level {
            for c in 0..3 {
                ymax = ymax.max(lv.std(noise.form, c, noise.luminance_range[1]) * 1.2);
            }
        }
        let mut chart = ChartBuilder::on(&panels[l])
            .caption(format!("noise {title} ({:?})", noise.form), ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(60)
            .build_cartesian_2d(0f32..1f32, 0f32..ymax)
            .map_err(|e| err(path, e))?;
        chart
            .configure_mesh()
            .x_desc("luma Y")
            .y_desc("std")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| err(path, e))?;
        for c in 0..3 {
            let col = CHANNEL_COLOURS[c];
            chart
                .draw_series(thin(ys.len(), 1500).map(|i| Circle::new((ys[i], stds[c][i]), 1, col.mix(0.35).filled())))
                .map_err(|e| err(path, e))?;
            if let Some(lv) = level {
                let [lo, hi] = noise.luminance_range;
                chart
                    .draw_series(LineSeries::new(
                        (0..=50).map(|k| {
                            let y = lo + (hi - lo) * k as f32 / 50.0;
                            (y, lv.std(noise.form, c, y))
                        }),
                        col.stroke_width(2),
                    ))
                    .map_err(|e| err(path, e))?;
            }
        }
    }
    root.present().map_err(|e| err(path, e))
}

/// DoF: per-pixel σ estimates vs depth, both fitted forms and the kept curve.
pub fn dof_plot(path: &Path, data: &DofPlotData, dof: &DepthOfField) -> Result<(), PlotError> {
    register_font();
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(path, e))?;
    let [lo, hi] = dof.depth_range;
    let (lo, hi) = if hi > lo { (lo, hi) } else { (lo - 0.5, lo + 0.5) };
    let smax = data.sigma_px.iter().cloned().fold(0.5f32, f32::max) * 1.1;
    let unit = match dof.units {
        DepthUnits::MetricM => "depth Z (m)",
        DepthUnits::RelativeInverse => "relative inverse depth",
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("depth of field δ(Z) [{}]", dof.diagnostics.status_str()), ("sans-serif", 22))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(lo..hi, 0f32..smax)
        .map_err(|e| err(path, e))?;
    chart.configure_mesh().x_desc(unit).y_desc("blur std δ (px)").draw().map_err(|e| err(path, e))?;
    chart
        .draw_series(
            thin(data.depth.len(), 4000)
                .map(|i| Circle::new((data.depth[i], data.sigma_px[i]), 1, BLACK.mix(0.25).filled())),
        )
        .map_err(|e| err(path, e))?
        .label("per-pixel estimates")
        .legend(|(x, y)| Circle::new((x, y), 3, BLACK.filled()));
    let curve_series = |c: DofCurve| {
        (0..=100).map(move |k| {
            let z = lo + (hi - lo) * k as f32 / 100.0;
            (z, c.sigma_px(dof.units, z))
        })
    };
    let candidates =
        [("quadratic", data.quadratic, RGBColor(220, 120, 0)), ("thin lens", data.thin_lens, RGBColor(38, 110, 210))];
    for (name, curve, col) in candidates {
        if let Some(c) = curve {
            chart
                .draw_series(LineSeries::new(curve_series(c), col.stroke_width(2)))
                .map_err(|e| err(path, e))?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        }
    }
    if let Some(c) = dof.curve {
        chart
            .draw_series(LineSeries::new(curve_series(c), RGBColor(200, 30, 30).stroke_width(4)))
            .map_err(|e| err(path, e))?
            .label("kept")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(200, 30, 30).stroke_width(4)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(path, e))?;
    root.present().map_err(|e| err(path, e))
}

/// MB: the loss L(λ) on the coarse grid and the refined estimate.
pub fn mb_plot(path: &Path, data: &MbPlotData) -> Result<(), PlotError> {
    register_font();
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(path, e))?;
    let lmax = data.losses.iter().cloned().fold(1e-12f64, f64::max) * 1.05;
    let mut chart = ChartBuilder::on(&root)
        .caption("motion blur: loss over exposure λ", ("sans-serif", 22))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(0f32..1f32, 0f64..lmax)
        .map_err(|e| err(path, e))?;
    chart.configure_mesh().x_desc("exposure λ").y_desc("mean squared error").draw().map_err(|e| err(path, e))?;
    chart
        .draw_series(LineSeries::new(
            data.lambdas.iter().cloned().zip(data.losses.iter().cloned()),
            BLUE.stroke_width(2),
        ))
        .map_err(|e| err(path, e))?;
    chart
        .draw_series(data.lambdas.iter().zip(&data.losses).map(|(&l, &v)| Circle::new((l, v), 3, BLUE.filled())))
        .map_err(|e| err(path, e))?;
    if let Some(est) = data.estimate {
        chart
            .draw_series(LineSeries::new(vec![(est, 0.0), (est, lmax)], RED.stroke_width(2)))
            .map_err(|e| err(path, e))?
            .label(format!("λ = {est:.4}"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        chart.configure_series_labels().border_style(BLACK).draw().map_err(|e| err(path, e))?;
    }
    root.present().map_err(|e| err(path, e))
}

/// One curve of a multi-panel plot: points (x, y), and whether it is drawn as a
/// line (truth, estimates over time) or as dots (the frames fitted).
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub colour: RGBColor,
    pub dots: bool,
}

/// One panel: a title, axis names and its curves.
pub struct Panel {
    pub title: String,
    pub x_desc: String,
    pub y_desc: String,
    pub series: Vec<Series>,
    pub log_x: bool,
}

/// Panels stacked vertically (the calibration timeline: one parameter per panel
/// over video time; the tier trade: error against compute).
pub fn panels_plot(path: &Path, panels: &[Panel], width: u32, panel_height: u32) -> Result<(), PlotError> {
    register_font();
    let root = BitMapBackend::new(path, (width, panel_height * panels.len().max(1) as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(path, e))?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (area, p) in areas.iter().zip(panels) {
        let all = p.series.iter().flat_map(|s| s.points.iter()).filter(|(x, y)| x.is_finite() && y.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0f64, f64::NEG_INFINITY);
        for &(x, y) in all {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !(x0.is_finite() && x1.is_finite() && y1.is_finite()) {
            continue;
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let y1 = if y1 > y0 { y1 + 0.08 * (y1 - y0) } else { y0 + 1.0 };
        let mut builder = ChartBuilder::on(area);
        builder.caption(&p.title, ("sans-serif", 20)).margin(10).x_label_area_size(36).y_label_area_size(70);
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart.configure_mesh().x_desc(&p.x_desc).y_desc(&p.y_desc).draw().map_err(|e| err(path, e))?;
                for s in &p.series {
                    let colour = s.colour;
                    // Missing values (NaN) are left out, not drawn at 0.
                    let pts: Vec<(f64, f64)> =
                        s.points.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
                    if s.dots {
                        chart
                            .draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), 4, colour.filled())))
                            .map_err(|e| err(path, e))?
                            .label(s.label.clone())
                            .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
                    } else {
                        chart
                            .draw_series(LineSeries::new(pts.iter().cloned(), colour.stroke_width(2)))
                            .map_err(|e| err(path, e))?
                            .label(s.label.clone())
                            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
                    }
                }
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .draw()
                    .map_err(|e| err(path, e))?;
            }};
        }
        if p.log_x && x0 > 0.0 {
            draw!(builder.build_cartesian_2d((x0 * 0.8..x1 * 1.25).log_scale(), y0..y1).map_err(|e| err(path, e))?);
        } else {
            draw!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| err(path, e))?);
        }
    }
    root.present().map_err(|e| err(path, e))
}
