//! One panel per joint: mean trajectories over time with optional
//! `± k sigma` bands and joint-limit lines.

use super::{format_of, plot_error, register_font, write_via_temp, Format};
use crate::Result;
use nalgebra::DMatrix;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// One trajectory family to draw in every joint panel.
#[derive(Clone, Debug)]
pub struct JointSeries {
    /// Legend label.
    pub label: String,
    /// Line colour.
    pub color: RGBColor,
    /// `T x n_joints` positions (rows = time).
    pub mean: DMatrix<f64>,
    /// Optional `T x n_joints` standard deviations, drawn as a band.
    pub std: Option<DMatrix<f64>>,
    /// Band half-width in standard deviations (e.g. 2).
    pub sigmas: f64,
}

/// Draw `series` in one panel per joint into `path` (`.png` / `.svg`).
/// `times` has one entry per row; `limits` (lower, upper) are drawn as
/// dashed grey lines when given.
pub fn joint_panels(
    path: &Path,
    title: &str,
    times: &[f64],
    series: &[JointSeries],
    joint_names: &[String],
    limits: Option<&[(f64, f64)]>,
) -> Result<()> {
    register_font();
    let size = (1400, 900);
    let format = format_of(path, "out")?;
    write_via_temp(path, |tmp| match format {
        Format::Png => draw(
            BitMapBackend::new(tmp, size).into_drawing_area(),
            title,
            times,
            series,
            joint_names,
            limits,
            path,
        ),
        Format::Svg => draw(
            SVGBackend::new(tmp, size).into_drawing_area(),
            title,
            times,
            series,
            joint_names,
            limits,
            path,
        ),
    })
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    times: &[f64],
    series: &[JointSeries],
    joint_names: &[String],
    limits: Option<&[(f64, f64)]>,
    path: &Path,
) -> Result<()> {
    let err = plot_error(path);
    root.fill(&WHITE).map_err(&err)?;
    let root = root.titled(title, ("sans-serif", 26)).map_err(&err)?;
    let n_joints = joint_names.len();
    let cols = 4;
    let rows = n_joints.div_ceil(cols).max(1);
    let panels = root.split_evenly((rows, cols));
    let t_end = times.last().copied().unwrap_or(1.0).max(1e-9);
    for (j, panel) in panels.iter().enumerate().take(n_joints) {
        let (lo, hi) = value_range(series, j, limits.map(|l| l[j]));
        let mut chart = ChartBuilder::on(panel)
            .caption(&joint_names[j], ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(48)
            .build_cartesian_2d(0.0..t_end, lo..hi)
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc("q [rad]")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(&err)?;
        if let Some(l) = limits {
            for bound in [l[j].0, l[j].1] {
                chart
                    .draw_series(DashedLineSeries::new(
                        times.iter().map(|&t| (t, bound)),
                        4,
                        4,
                        RGBColor(150, 150, 150).into(),
                    ))
                    .map_err(&err)?;
            }
        }
        for s in series {
            if let Some(std) = &s.std {
                let upper: Vec<(f64, f64)> = times
                    .iter()
                    .enumerate()
                    .map(|(t, &x)| (x, s.mean[(t, j)] + s.sigmas * std[(t, j)]))
                    .collect();
                let lower = times
                    .iter()
                    .enumerate()
                    .rev()
                    .map(|(t, &x)| (x, s.mean[(t, j)] - s.sigmas * std[(t, j)]));
                let outline: Vec<(f64, f64)> = upper.into_iter().chain(lower).collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(outline, s.color.mix(0.2))))
                    .map_err(&err)?;
            }
            let line = chart
                .draw_series(LineSeries::new(
                    times.iter().enumerate().map(|(t, &x)| (x, s.mean[(t, j)])),
                    s.color.stroke_width(2),
                ))
                .map_err(&err)?;
            if j == 0 {
                let color = s.color;
                line.label(s.label.clone()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
            }
        }
        if j == 0 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 12))
                .draw()
                .map_err(&err)?;
        }
    }
    root.present().map_err(&err)?;
    Ok(())
}

/// y-range covering every series (with bands) and the limits, padded 5 %.
fn value_range(series: &[JointSeries], j: usize, limit: Option<(f64, f64)>) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in series {
        for t in 0..s.mean.nrows() {
            let half = s.std.as_ref().map_or(0.0, |std| s.sigmas * std[(t, j)]);
            lo = lo.min(s.mean[(t, j)] - half);
            hi = hi.max(s.mean[(t, j)] + half);
        }
    }
    if let Some((l, u)) = limit {
        lo = lo.min(l);
        hi = hi.max(u);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-3);
    (lo - pad, hi + pad)
}
