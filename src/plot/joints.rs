//! One panel per joint: mean trajectories over time with optional
//! `± k sigma` bands and joint-limit lines.
//!
//! Each panel is scaled to its own data (bands included); a joint limit is
//! drawn, labelled, only where it falls inside that range, so a joint far
//! from its limits keeps its detail. The legend sits in the grid's spare
//! cell (7 joints in 2 x 4), off the data.

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
    /// Line width (px): 2 for a mean, 1 for a demonstration.
    pub width: u32,
}

impl JointSeries {
    /// A mean line with a `± sigmas` band.
    pub fn band(
        label: String,
        color: RGBColor,
        mean: DMatrix<f64>,
        std: DMatrix<f64>,
        sigmas: f64,
    ) -> Self {
        JointSeries {
            label,
            color,
            mean,
            std: Some(std),
            sigmas,
            width: 2,
        }
    }

    /// A line without a band; an empty `label` keeps it out of the legend.
    pub fn line(label: String, color: RGBColor, mean: DMatrix<f64>, width: u32) -> Self {
        JointSeries {
            label,
            color,
            mean,
            std: None,
            sigmas: 0.0,
            width,
        }
    }
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
        let (lo, hi) = value_range(series, j);
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
            for (bound, name) in [(l[j].0, "lower limit"), (l[j].1, "upper limit")] {
                if !(lo..=hi).contains(&bound) {
                    continue;
                }
                let grey = RGBColor(150, 150, 150);
                chart
                    .draw_series(DashedLineSeries::new(
                        times.iter().map(|&t| (t, bound)),
                        4,
                        4,
                        grey.into(),
                    ))
                    .map_err(&err)?;
                chart
                    .draw_series(std::iter::once(Text::new(
                        format!("{name} {bound:.3}"),
                        (0.02 * t_end, bound),
                        ("sans-serif", 11).into_font().color(&grey),
                    )))
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
            chart
                .draw_series(LineSeries::new(
                    times.iter().enumerate().map(|(t, &x)| (x, s.mean[(t, j)])),
                    s.color.stroke_width(s.width),
                ))
                .map_err(&err)?;
        }
    }
    if let Some(spare) = panels.get(n_joints) {
        draw_legend(spare, series, limits.is_some(), &err)?;
    }
    root.present().map_err(&err)?;
    Ok(())
}

/// The legend in a cell of its own: one entry per labelled series, and
/// the limit line's meaning.
fn draw_legend<DB: DrawingBackend, E: Fn(DrawingAreaErrorKind<DB::ErrorType>) -> crate::Error>(
    area: &DrawingArea<DB, Shift>,
    series: &[JointSeries],
    with_limits: bool,
    err: &E,
) -> Result<()> {
    let mut y = 40;
    let mut entry = |color: RGBColor, label: &str, dashed: bool| -> Result<()> {
        let style = color.stroke_width(if dashed { 1 } else { 3 });
        area.draw(&PathElement::new(vec![(20, y), (60, y)], style))
            .map_err(err)?;
        area.draw(&Text::new(
            label.to_string(),
            (70, y - 7),
            ("sans-serif", 15).into_font(),
        ))
        .map_err(err)?;
        y += 28;
        Ok(())
    };
    for s in series.iter().filter(|s| !s.label.is_empty()) {
        entry(s.color, &s.label, false)?;
    }
    if with_limits {
        entry(
            RGBColor(150, 150, 150),
            "joint limit (where in range), dashed",
            true,
        )?;
    }
    Ok(())
}

/// y-range covering every series (with bands), padded 5 %.
fn value_range(series: &[JointSeries], j: usize) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in series {
        for t in 0..s.mean.nrows() {
            let half = s.std.as_ref().map_or(0.0, |std| s.sigmas * std[(t, j)]);
            lo = lo.min(s.mean[(t, j)] - half);
            hi = hi.max(s.mean[(t, j)] + half);
        }
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-3);
    (lo - pad, hi + pad)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A panel spans its own data and band, padded 5 %, whatever the
    /// joint's limits: a joint 0.1 rad wide is not squashed into 5.8 rad.
    #[test]
    fn a_panel_is_scaled_to_its_data() {
        let mean = DMatrix::from_fn(10, 2, |t, j| 0.01 * t as f64 + j as f64);
        let std = DMatrix::from_element(10, 2, 0.005);
        let series = [JointSeries::band("p".into(), RED, mean, std, 2.0)];
        let (lo, hi) = value_range(&series, 0);
        let (data_lo, data_hi) = (-0.01, 0.09 + 0.01);
        let pad = 0.05 * (data_hi - data_lo);
        assert!((lo - (data_lo - pad)).abs() < 1e-12, "{lo}");
        assert!((hi - (data_hi + pad)).abs() < 1e-12, "{hi}");
        let (lo1, _) = value_range(&series, 1);
        assert!((lo1 - (1.0 - 0.01 - pad)).abs() < 1e-12, "{lo1}");
    }
}
