//! The paper's evaluation on a dataset split:
//!
//! - Table I: the Eq. 7 loss per joint (mean-trajectory and covariance
//!   terms), averaged over targets;
//! - Table III: final-point TCP position error (m) and quaternion distance
//!   `min(|q - q'|, |q + q'|)` (Eq. 9) between the predicted and the
//!   ground-truth distribution, for the mean trajectory and for the
//!   trajectories 3 sigma above and below it, in the model's space (a
//!   joint-space model's final configurations through the TCP forward
//!   kinematics, a task-space model's final poses as they are);
//! - beside Table III, the mean trajectory's final-point error per
//!   base-frame axis next to the ground truth's spread on that axis: a model
//!   that learned nothing about an axis (e.g. depth, which a single image
//!   hardly shows) scores about that axis's spread;
//! - Table II: the Davies–Bouldin index of a 2-D embedding of the latent
//!   vectors labelled by plant configuration, with a scatter plot.
//!
//! The map from a final point to a pose is passed in
//! (`crate::robot::Robot::tcp_pose` for a joint-space model, the row read
//! as position and quaternion for a task-space one), so this module does
//! not depend on a particular robot or space.

use super::data::{target_tensors, Sample};
use super::embedding::{davies_bouldin, embed, plot_embedding, Embedding};
use super::final_point::TcpFk;
use super::final_point::{final_marginal, quaternion_distance};
use super::losses::TrajectoryOperator;
use crate::net::checkpoint::write_atomic;
use crate::net::predict::predictions_from_outputs;
use crate::net::{candle_error, Model};
use crate::promp::{Basis, WeightDistribution};
use crate::{Error, Result};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::Path;

/// Table I row: Eq. 7 terms of one joint.
#[derive(Clone, Debug, Serialize)]
pub struct JointRow {
    /// Joint number, from 1.
    pub joint: usize,
    /// Mean squared error of the mean trajectory (rad^2).
    pub mean_mse: f64,
    /// Mean squared error of the trajectory covariance (rad^4).
    pub cov_mse: f64,
    /// `mean_mse + alpha * cov_mse`.
    pub eq7: f64,
    /// Root of `mean_mse` (rad), easier to read.
    pub mean_rmse_rad: f64,
}

/// Final-point errors of one trajectory kind (Table III cell pair).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FinalPointError {
    /// Mean TCP position error (m).
    pub position_m: f64,
    /// Mean quaternion distance (Eq. 9).
    pub orientation: f64,
    /// Largest TCP position error (m).
    pub max_position_m: f64,
}

/// Table III: mean and +-3 sigma trajectories, in the model's space.
#[derive(Clone, Debug, Serialize)]
pub struct FinalPointTable {
    /// The mean trajectory.
    pub mean: FinalPointError,
    /// Mean + 3 sigma (per-joint final-time marginal).
    pub plus_3sigma: FinalPointError,
    /// Mean - 3 sigma.
    pub minus_3sigma: FinalPointError,
}

/// The mean trajectory's final TCP position error per base-frame axis.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct AxisErrors {
    /// Mean absolute error on x, y and z (m).
    pub model_mae_m: [f64; 3],
    /// Mean absolute deviation of the ground-truth final positions from
    /// their mean on x, y and z (m): the error of a model that predicts the
    /// split's mean position on that axis.
    pub truth_spread_m: [f64; 3],
}

/// [`AxisErrors`] of (predicted, ground-truth) final positions.
pub fn axis_errors(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> AxisErrors {
    let mut out = AxisErrors::default();
    if pairs.is_empty() {
        return out;
    }
    let n = pairs.len() as f64;
    let truth_mean = pairs.iter().map(|(_, t)| t).sum::<Vector3<f64>>() / n;
    for k in 0..3 {
        out.model_mae_m[k] = pairs.iter().map(|(p, t)| (p[k] - t[k]).abs()).sum::<f64>() / n;
        out.truth_spread_m[k] = pairs
            .iter()
            .map(|(_, t)| (t[k] - truth_mean[k]).abs())
            .sum::<f64>()
            / n;
    }
    out
}

/// Table II: latent-space clustering.
#[derive(Clone, Debug, Serialize)]
pub struct LatentTable {
    /// Embedding method.
    pub method: String,
    /// Davies–Bouldin index by plant configuration (lower is better);
    /// `None` with fewer than two configurations.
    pub davies_bouldin: Option<f64>,
    /// Number of configurations (clusters).
    pub clusters: usize,
}

/// The whole evaluation report (written as JSON and Markdown).
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    /// Model name.
    pub model: String,
    /// Architecture (`cvae`...).
    pub arch: String,
    /// Whether the model was latent-tuned.
    pub latent_tuning: bool,
    /// The space of the model's trajectories (`joint` or `task`): Table
    /// III's half.
    pub space: String,
    /// Split evaluated.
    pub split: String,
    /// Number of targets.
    pub targets: usize,
    /// Covariance weight used in the Eq. 7 column.
    pub alpha: f64,
    /// Mean over targets of the mean-trajectory final TCP position error (m).
    pub mean_final_position_error_m: f64,
    /// Sum over joints of Table I's Eq. 7 column.
    pub eq7_total: f64,
    /// Table I.
    pub table1: Vec<JointRow>,
    /// Table II.
    pub table2: LatentTable,
    /// Table III.
    pub table3: FinalPointTable,
    /// Table III's mean-trajectory position error per base-frame axis.
    pub final_position_by_axis: AxisErrors,
    /// Depth-aware planning figures, when the dataset has depth (see
    /// [`super::plan_eval`]); flattened into the report's top level.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub planning: Option<super::plan_eval::PlanEval>,
    /// The condition-only baseline, when a training split was available
    /// (see [`super::baseline`]); flattened into the report's top level.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub baseline: Option<super::baseline::BaselineEval>,
}

/// Evaluate a model on samples; returns the report and the embedding.
pub fn evaluate(
    model: &Model,
    samples: &[Sample],
    split: &str,
    alpha: f64,
    fk: TcpFk,
) -> Result<(EvalReport, Embedding)> {
    if samples.is_empty() {
        return Err(Error::invalid(
            "split",
            format!("split {split:?} has no targets"),
        ));
    }
    let config = model.config();
    let basis = Basis::new(&config.promp)?;
    let op = TrajectoryOperator::new(&basis, model.network().device()).map_err(candle_error)?;
    let mut sums = vec![(0.0, 0.0); config.n_joints];
    let mut latents = Vec::with_capacity(samples.len());
    let mut finals = Vec::with_capacity(samples.len());
    let mut final_positions = Vec::with_capacity(samples.len());
    let indices: Vec<usize> = (0..samples.len()).collect();
    for chunk in indices.chunks(16) {
        let prepared: Vec<_> = chunk.iter().map(|&i| samples[i].prepared.clone()).collect();
        let (latent, pred) = model.infer_batch(&prepared)?;
        let predictions = predictions_from_outputs(&latent, &pred)?;
        let (mean_t, cov_t) = target_tensors(samples, chunk, config, model.network().device())?;
        let loss = op
            .trajectory_loss(&pred, &mean_t, &cov_t, alpha)
            .map_err(candle_error)?;
        let m = loss.mean.to_vec1::<f32>().map_err(candle_error)?;
        let c = loss.cov.to_vec1::<f32>().map_err(candle_error)?;
        for j in 0..config.n_joints {
            sums[j].0 += f64::from(m[j]) * chunk.len() as f64;
            sums[j].1 += f64::from(c[j]) * chunk.len() as f64;
        }
        for (prediction, &i) in predictions.into_iter().zip(chunk) {
            let (errors, positions) = final_point_errors(
                &prediction.distribution,
                &samples[i].distribution,
                &basis,
                fk,
            );
            finals.push(errors);
            final_positions.push(positions);
            latents.push(prediction.latent);
        }
    }
    let n = samples.len() as f64;
    let table1: Vec<JointRow> = sums
        .iter()
        .enumerate()
        .map(|(j, &(m, c))| JointRow {
            joint: j + 1,
            mean_mse: m / n,
            cov_mse: c / n,
            eq7: m / n + alpha * c / n,
            mean_rmse_rad: (m / n).sqrt(),
        })
        .collect();
    let table3 = FinalPointTable {
        mean: average(finals.iter().map(|f| f[0])),
        plus_3sigma: average(finals.iter().map(|f| f[1])),
        minus_3sigma: average(finals.iter().map(|f| f[2])),
    };
    let labels: Vec<usize> = samples.iter().map(|s| s.config).collect();
    let embedding = embed(&latents, &labels);
    let mut clusters = labels.clone();
    clusters.sort_unstable();
    clusters.dedup();
    let report = EvalReport {
        model: config.name.clone(),
        arch: config.arch.as_str().into(),
        latent_tuning: config.latent_tuning,
        space: config.space.as_str().into(),
        split: split.into(),
        targets: samples.len(),
        alpha,
        mean_final_position_error_m: table3.mean.position_m,
        eq7_total: table1.iter().map(|r| r.eq7).sum(),
        table1,
        table2: LatentTable {
            method: embedding.method.clone(),
            davies_bouldin: davies_bouldin(&embedding.points, &embedding.labels),
            clusters: clusters.len(),
        },
        table3,
        final_position_by_axis: axis_errors(&final_positions),
        planning: None,
        baseline: None,
    };
    Ok((report, embedding))
}

/// Errors of the mean, +3 sigma and -3 sigma final configurations, and the
/// (predicted, ground-truth) final TCP positions of the mean.
fn final_point_errors(
    predicted: &WeightDistribution,
    truth: &WeightDistribution,
    basis: &Basis,
    fk: TcpFk,
) -> ([FinalPointError; 3], (Vector3<f64>, Vector3<f64>)) {
    let (p_mean, p_std) = final_marginal(predicted, basis);
    let (t_mean, t_std) = final_marginal(truth, basis);
    let shifted = |mean: &[f64], std: &[f64], k: f64| -> Vec<f64> {
        mean.iter().zip(std).map(|(m, s)| m + k * s).collect()
    };
    let errors = [0.0, 3.0, -3.0].map(|k| {
        let a = fk(&shifted(&p_mean, &p_std, k));
        let b = fk(&shifted(&t_mean, &t_std, k));
        let position = (a.translation.vector - b.translation.vector).norm();
        FinalPointError {
            position_m: position,
            orientation: quaternion_distance(&a.rotation, &b.rotation),
            max_position_m: position,
        }
    });
    let positions = (
        fk(&p_mean).translation.vector,
        fk(&t_mean).translation.vector,
    );
    (errors, positions)
}

fn average(errors: impl Iterator<Item = FinalPointError>) -> FinalPointError {
    let mut out = FinalPointError::default();
    let mut n = 0.0;
    for e in errors {
        out.position_m += e.position_m;
        out.orientation += e.orientation;
        out.max_position_m = out.max_position_m.max(e.max_position_m);
        n += 1.0;
    }
    if n > 0.0 {
        out.position_m /= n;
        out.orientation /= n;
    }
    out
}

/// Markdown rendering of the three tables.
pub fn to_markdown(report: &EvalReport) -> String {
    let mut s = format!(
        "# Evaluation of {} ({}{}) on the {} split ({} targets)\n\n",
        report.model,
        if report.latent_tuning { "l-" } else { "" },
        report.arch,
        report.split,
        report.targets
    );
    s += &format!(
        "## Table I — Eq. 7 per {} (alpha = {})\n\n",
        if report.space == "task" {
            "dimension"
        } else {
            "joint"
        },
        report.alpha
    );
    let task = report.space == crate::net::Space::Task.as_str();
    s += if task {
        "| dimension | mean MSE | mean RMSE (m or quaternion units) | cov MSE | Eq. 7 |\n|---|---|---|---|---|\n"
    } else {
        "| joint | mean MSE (rad²) | mean RMSE (rad) | cov MSE | Eq. 7 |\n|---|---|---|---|---|\n"
    };
    for r in &report.table1 {
        let name = match crate::task_space::TASK_DIM_NAMES.get(r.joint - 1) {
            Some(dim) if task => dim.to_string(),
            _ => format!("J{}", r.joint),
        };
        s += &format!(
            "| {name} | {:.3e} | {:.4} | {:.3e} | {:.3e} |\n",
            r.mean_mse, r.mean_rmse_rad, r.cov_mse, r.eq7
        );
    }
    s += &format!("| total | | | | {:.3e} |\n\n", report.eq7_total);
    if let Some(b) = &report.baseline {
        s += &format!(
            "Condition-only baseline ({}, no image; nearest training target): final TCP error of the mean {:.4} m (the network: {:.4} m).\n\n",
            b.baseline_inputs, b.baseline_mean_final_position_error_m, report.mean_final_position_error_m
        );
    }
    if let Some(p) = &report.planning {
        s += &format!(
            "## Depth-aware planning ({} targets)\n\n| figure | value |\n|---|---|\n\
             | back-projected berry centre error, median / p95 | {} |\n\
             | goal-conditioned prior final TCP vs demonstrations' mean, mean | {:.1} mm |\n\
             | plan final TCP vs demonstrations' mean, mean / p95 | {:.1} / {:.1} mm |\n\
             | plans verified optimal | {:.1} % |\n\n",
            p.plan_targets,
            match (p.target_position_error_m, p.target_position_p95_error_m) {
                (Some(median), Some(p95)) => format!("{:.1} / {:.1} mm", median * 1e3, p95 * 1e3),
                _ => "no ground truth".into(),
            },
            p.plan_prior_mean_final_position_error_m * 1e3,
            p.plan_mean_final_position_error_m * 1e3,
            p.plan_p95_final_position_error_m * 1e3,
            p.plan_optimal_fraction * 100.0
        );
    }
    s += "## Table II — latent clustering\n\n| method | clusters | Davies–Bouldin |\n|---|---|---|\n";
    let db = report
        .table2
        .davies_bouldin
        .map_or("n/a".to_string(), |v| format!("{v:.3}"));
    s += &format!(
        "| {} | {} | {} |\n\n",
        report.table2.method, report.table2.clusters, db
    );
    s += &format!("## Table III — final point, {} space\n\n", report.space);
    s += "| trajectory | position (m) | orientation (Eq. 9) | max position (m) |\n|---|---|---|---|\n";
    for (name, e) in [
        ("mean", &report.table3.mean),
        ("+3σ", &report.table3.plus_3sigma),
        ("−3σ", &report.table3.minus_3sigma),
    ] {
        s += &format!(
            "| {name} | {:.4} | {:.4} | {:.4} |\n",
            e.position_m, e.orientation, e.max_position_m
        );
    }
    let axes = &report.final_position_by_axis;
    s += "\n### Mean trajectory's final position by base-frame axis\n\n\
          A model that learned nothing about an axis scores about the ground truth's spread on it.\n\n\
          | axis | model MAE (m) | ground-truth spread (m) |\n|---|---|---|\n";
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        s += &format!(
            "| {axis} | {:.4} | {:.4} |\n",
            axes.model_mae_m[k], axes.truth_spread_m[k]
        );
    }
    s
}

/// Write `eval.json`, `eval.md` and `embedding.png` into `dir`.
pub fn write_outputs(dir: &Path, report: &EvalReport, embedding: &Embedding) -> Result<()> {
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::Numerical(format!("cannot serialise report: {e}")))?;
    write_atomic(&dir.join("eval.json"), json.as_bytes())?;
    write_atomic(&dir.join("eval.md"), to_markdown(report).as_bytes())?;
    let title = format!(
        "{} latent space ({}), DB = {}",
        report.model,
        embedding.method.split(' ').next().unwrap_or("embedding"),
        report
            .table2
            .davies_bouldin
            .map_or("n/a".into(), |v| format!("{v:.3}"))
    );
    plot_embedding(embedding, &title, &dir.join("embedding.png"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_errors_are_zero_for_a_perfect_model_and_the_spread_for_the_mean() {
        let truth = [
            Vector3::new(0.60, -0.10, 0.70),
            Vector3::new(0.64, 0.00, 0.74),
            Vector3::new(0.70, 0.05, 0.66),
            Vector3::new(0.66, -0.15, 0.72),
        ];
        let perfect: Vec<_> = truth.iter().map(|t| (*t, *t)).collect();
        let a = axis_errors(&perfect);
        assert_eq!(a.model_mae_m, [0.0; 3]);
        // Spread on x: mean 0.65, deviations 0.05, 0.01, 0.05, 0.01.
        assert!((a.truth_spread_m[0] - 0.03).abs() < 1e-12);
        let mean = truth.iter().sum::<Vector3<f64>>() / 4.0;
        let constant: Vec<_> = truth.iter().map(|t| (mean, *t)).collect();
        let c = axis_errors(&constant);
        for k in 0..3 {
            assert!((c.model_mae_m[k] - c.truth_spread_m[k]).abs() < 1e-12);
            assert!(c.truth_spread_m[k] > 0.0);
        }
        // An offset of 1 cm on y only.
        let shifted: Vec<_> = truth
            .iter()
            .map(|t| (t + Vector3::new(0.0, 0.01, 0.0), *t))
            .collect();
        let d = axis_errors(&shifted);
        assert!((d.model_mae_m[1] - 0.01).abs() < 1e-12);
        assert!(d.model_mae_m[0].abs() < 1e-15 && d.model_mae_m[2].abs() < 1e-15);
        assert_eq!(axis_errors(&[]), AxisErrors::default());
    }
}
