//! Report plots (PNG, plotters): success rate by category, solve time
//! p50/p95/max per method (log10), and per-problem scatters of the
//! Mahalanobis cost, the minimum clearance, the goal error and the total
//! constraint violation (problems sorted by name, i.e. grouped by category).

use super::report::Report;
use super::runner::RunRecord;
use crate::plot::{register_font, write_via_temp};
use crate::{Error, Result};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

const SIZE: (u32, u32) = (960, 480);

/// One scatter plot: file name, title, the value per record, optional reference line.
type ScatterSpec = (
    &'static str,
    &'static str,
    fn(&RunRecord) -> Option<f64>,
    Option<f64>,
);

/// Write every plot of `report` into `dir`; returns the files written.
pub fn write_plots(report: &Report, dir: &Path) -> Result<Vec<PathBuf>> {
    register_font();
    let mut files = Vec::new();
    let mut emit = |name: &str, draw: &dyn Fn(&Path) -> Result<()>| -> Result<()> {
        let path = dir.join(name);
        write_via_temp(&path, draw)?;
        files.push(path);
        Ok(())
    };
    emit("success_by_category.png", &|p| {
        success_by_category(report, p)
    })?;
    emit("solve_time.png", &|p| solve_time(report, p))?;
    let scatters: [ScatterSpec; 4] = [
        (
            "mahalanobis.png",
            "Mahalanobis cost (verified trajectories)",
            |r| r.mahalanobis.filter(|_| r.found && r.verified_feasible),
            None,
        ),
        (
            "min_clearance.png",
            "min clearance of the returned trajectory (mm); line = 20 mm",
            |r| r.min_clearance_m.map(|c| c * 1e3),
            Some(20.0),
        ),
        (
            "goal_error.png",
            "final TCP goal error (mm); line = 10 mm tolerance",
            |r| r.goal_error_m.map(|e| e * 1e3),
            Some(10.0),
        ),
        (
            "violations.png",
            "log10(total constraint violation + 1e-9)",
            |r| {
                r.error
                    .is_none()
                    .then(|| (r.total_violation() + 1e-9).log10())
            },
            None,
        ),
    ];
    for (name, title, value, line) in scatters {
        emit(name, &|p| per_problem(report, p, title, value, line))?;
    }
    Ok(files)
}

fn plot_err<E: std::fmt::Debug>(e: E) -> Error {
    Error::Numerical(format!("plotting failed: {e:?}"))
}

fn color(i: usize) -> RGBColor {
    let c = Palette99::pick(i).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// Grouped bars: success rate per category and method.
fn success_by_category(report: &Report, path: &Path) -> Result<()> {
    let cats: Vec<String> = category_order(report);
    let m = report.methods.len().max(1);
    let values = |c: &str, method: &str| {
        report
            .by_category
            .iter()
            .find(|s| s.category == c && s.method == method)
            .map_or(0.0, |s| 100.0 * s.success_rate)
    };
    grouped_bars(
        path,
        "success rate (%) by category",
        &cats,
        &report.methods,
        0.0..105.0,
        &|ci, mi| values(&cats[ci], &report.methods[mi.min(m - 1)]),
    )
}

/// Grouped bars: log10 time p50/p95/max per method.
fn solve_time(report: &Report, path: &Path) -> Result<()> {
    let stats = vec!["p50".to_string(), "p95".to_string(), "max".to_string()];
    let value = |mi: usize, si: usize| {
        let t = report.summary[mi].time_ms;
        [t.p50, t.p95, t.max][si].max(1e-3).log10()
    };
    let hi = (0..report.summary.len())
        .flat_map(|mi| (0..3).map(move |si| (mi, si)))
        .map(|(mi, si)| value(mi, si))
        .fold(1.0f64, f64::max)
        + 0.5;
    grouped_bars(
        path,
        "log10(time per problem, ms)",
        &report.methods,
        &stats,
        -3.0..hi,
        &|mi, si| value(mi, si),
    )
}

fn grouped_bars(
    path: &Path,
    title: &str,
    groups: &[String],
    series: &[String],
    y: std::ops::Range<f64>,
    value: &dyn Fn(usize, usize) -> f64,
) -> Result<()> {
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let n = groups.len().max(1) as f64;
    let y0 = y.start;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..n, y)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(groups.len() * 2 + 1)
        .x_label_formatter(&|x| {
            let i = x.floor() as usize;
            if (x - x.floor() - 0.5).abs() < 0.01 && i < groups.len() {
                groups[i].clone()
            } else {
                String::new()
            }
        })
        .draw()
        .map_err(plot_err)?;
    let width = 0.8 / series.len().max(1) as f64;
    for (si, name) in series.iter().enumerate() {
        let c = color(si);
        let bars = (0..groups.len()).map(|gi| {
            let x0 = gi as f64 + 0.1 + si as f64 * width;
            Rectangle::new([(x0, y0), (x0 + width * 0.9, value(gi, si))], c.filled())
        });
        chart
            .draw_series(bars)
            .map_err(plot_err)?
            .label(name.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], c.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;
    root.present().map_err(plot_err)
}

fn category_order(report: &Report) -> Vec<String> {
    let mut cats: Vec<String> = Vec::new();
    for s in &report.by_category {
        if !cats.contains(&s.category) {
            cats.push(s.category.clone());
        }
    }
    cats
}

/// Per-problem scatter of `value`, one colour per method.
fn per_problem(
    report: &Report,
    path: &Path,
    title: &str,
    value: fn(&RunRecord) -> Option<f64>,
    line: Option<f64>,
) -> Result<()> {
    let mut problems: Vec<&str> = report.records.iter().map(|r| r.problem.as_str()).collect();
    problems.dedup();
    let index = |name: &str| problems.iter().position(|p| *p == name).unwrap_or(0) as f64;
    let points: Vec<(usize, f64, f64)> = report
        .records
        .iter()
        .filter_map(|r| {
            let mi = report.methods.iter().position(|m| *m == r.method)?;
            value(r)
                .filter(|v| v.is_finite())
                .map(|v| (mi, index(&r.problem), v))
        })
        .collect();
    let (mut lo, mut hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.2), hi.max(p.2))
        });
    if let Some(l) = line {
        lo = lo.min(l);
        hi = hi.max(l);
    }
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-6);
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(-1.0..problems.len() as f64, (lo - pad)..(hi + pad))
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("problem (sorted by name: grouped by category)")
        .draw()
        .map_err(plot_err)?;
    if let Some(l) = line {
        chart
            .draw_series(LineSeries::new(
                [(-1.0, l), (problems.len() as f64, l)],
                BLACK.stroke_width(1),
            ))
            .map_err(plot_err)?;
    }
    for (mi, name) in report.methods.iter().enumerate() {
        let c = color(mi);
        let offset = (mi as f64 - report.methods.len() as f64 / 2.0) * 0.08;
        let series = points
            .iter()
            .filter(|p| p.0 == mi)
            .map(|p| Circle::new((p.1 + offset, p.2), 3, c.filled()));
        chart
            .draw_series(series)
            .map_err(plot_err)?
            .label(name.as_str())
            .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;
    root.present().map_err(plot_err)
}
