//! Training metrics: one record per epoch appended to `metrics.jsonl` and
//! `metrics.csv`, and the loss curves (train and validation per phase,
//! log scale) drawn to `loss_curves.png` with plotters.

use crate::net::checkpoint::write_atomic;
use crate::{Error, Result};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// One epoch's metrics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// `tp1`, `tp2`, `tp3` or `direct`.
    pub phase: String,
    /// Epoch index within the phase (from 0).
    pub epoch: usize,
    /// Learning rate used.
    pub lr: f64,
    /// Mean training loss over the epoch's batches.
    pub train_loss: f64,
    /// Validation loss (the phase objective, evaluation mode).
    pub val_loss: f64,
    /// Whether this epoch improved the best validation loss.
    pub improved: bool,
    /// Seconds spent in the epoch.
    pub seconds: f64,
}

/// Appends epoch records to the JSONL and CSV logs in a directory.
#[derive(Clone, Debug)]
pub struct MetricsLog {
    jsonl: PathBuf,
    csv: PathBuf,
}

const CSV_HEADER: &str = "phase,epoch,lr,train_loss,val_loss,improved,seconds\n";

impl MetricsLog {
    /// Open the logs in `dir`; `fresh` truncates them (a new training run),
    /// otherwise records are appended (resume).
    pub fn open(dir: &Path, fresh: bool) -> Result<MetricsLog> {
        let log = MetricsLog {
            jsonl: dir.join("metrics.jsonl"),
            csv: dir.join("metrics.csv"),
        };
        if fresh || !log.csv.exists() {
            write_atomic(&log.jsonl, b"")?;
            write_atomic(&log.csv, CSV_HEADER.as_bytes())?;
        }
        Ok(log)
    }

    /// Append one record to both files.
    pub fn append(&self, record: &EpochRecord) -> Result<()> {
        let json = serde_json::to_string(record)
            .map_err(|e| Error::Numerical(format!("cannot serialise metrics: {e}")))?;
        append_line(&self.jsonl, &json)?;
        let csv = format!(
            "{},{},{},{},{},{},{:.3}",
            record.phase,
            record.epoch,
            record.lr,
            record.train_loss,
            record.val_loss,
            record.improved,
            record.seconds
        );
        append_line(&self.csv, &csv)
    }

    /// Every record written so far.
    pub fn records(&self) -> Result<Vec<EpochRecord>> {
        let text = std::fs::read_to_string(&self.jsonl)
            .map_err(|e| Error::file(&self.jsonl, e.to_string()))?;
        text.lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                serde_json::from_str(l)
                    .map_err(|e| Error::file(&self.jsonl, format!("malformed record: {e}")))
            })
            .collect()
    }
}

fn append_line(path: &Path, line: &str) -> Result<()> {
    let mut file = std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .map_err(|e| Error::file(path, e.to_string()))?;
    writeln!(file, "{line}").map_err(|e| Error::write(path, e.to_string()))
}

/// Draw train (solid) and validation (dashed-looking thin) loss curves per
/// phase on a log scale to `path` (PNG, written atomically).
pub fn plot_loss_curves(records: &[EpochRecord], path: &Path) -> Result<()> {
    crate::plot::write_via_temp(path, |tmp| {
        draw_curves(records, tmp).map_err(|e| Error::write(path, format!("cannot plot: {e}")))
    })
}

/// Short tick text: three decimals down to 0.01, scientific below.
fn tick_label(v: f64) -> String {
    if v == 0.0 || v.abs() >= 0.01 {
        format!("{v:.3}")
    } else {
        format!("{v:.1e}")
    }
}

fn draw_curves(
    records: &[EpochRecord],
    path: &Path,
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    crate::plot::register_font();
    let mut phases: Vec<String> = Vec::new();
    for r in records {
        if !phases.contains(&r.phase) {
            phases.push(r.phase.clone());
        }
    }
    let root =
        BitMapBackend::new(path, (480 * phases.len().max(1) as u32, 360)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, phases.len().max(1)));
    for (phase, panel) in phases.iter().zip(panels.iter()) {
        let rows: Vec<&EpochRecord> = records.iter().filter(|r| &r.phase == phase).collect();
        let values = rows.iter().flat_map(|r| [r.train_loss, r.val_loss]);
        let positive: Vec<f64> = values.filter(|v| v.is_finite() && *v > 0.0).collect();
        let lo = positive.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = positive.iter().cloned().fold(0.0, f64::max);
        let (lo, hi) = if lo.is_finite() && hi > lo {
            (lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
        } else {
            (1e-6, 1.0)
        };
        let epochs = rows.len().max(2) as f64;
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{phase} loss"), ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..epochs, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("epoch")
            .y_desc("loss")
            .y_label_formatter(&|v| tick_label(*v))
            .y_labels(6)
            .draw()?;
        let train = rows.iter().map(|r| (r.epoch as f64, r.train_loss.max(lo)));
        chart
            .draw_series(LineSeries::new(train, BLUE.stroke_width(2)))?
            .label("train")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        let val = rows.iter().map(|r| (r.epoch as f64, r.val_loss.max(lo)));
        chart
            .draw_series(LineSeries::new(val, RED.stroke_width(2)))?
            .label("validation")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
