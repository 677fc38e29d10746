//! The condition-only baseline: what the network's condition alone (the
//! box centre, and the measured depth when the dataset has it) predicts,
//! with no image, so the evaluation shows what the image adds.
//!
//! The baseline is a ridge regression of the demonstrations' mean ProMP
//! weights on quadratic features of the condition (1, every input, every
//! product of two inputs), fitted on the training split in closed form —
//! deterministic, and as smooth a map from the condition as the data
//! supports. It is scored exactly like the network's
//! `mean_final_position_error_m`: the final TCP of the predicted mean
//! against the final TCP of the demonstrations' mean.

use super::data::Sample;
use super::eval::final_marginal;
use crate::promp::{Basis, WeightDistribution};
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Ridge weight (the features are raw condition values, all of order 1).
pub const RIDGE: f64 = 1e-3;

/// The baseline's figures, flattened into the evaluation report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BaselineEval {
    /// What the baseline reads (`box centre` or `box centre + depth`).
    pub baseline_inputs: String,
    /// Mean final TCP error (m) of the baseline's predicted mean trajectory.
    pub baseline_mean_final_position_error_m: f64,
}

/// A fitted condition-only regression.
pub struct ConditionBaseline {
    with_depth: bool,
    coefficients: DMatrix<f64>,
}

impl ConditionBaseline {
    /// Fit on `train`; with `with_depth` every sample must have its depth.
    pub fn fit(train: &[Sample], with_depth: bool) -> Result<ConditionBaseline> {
        let rows = train
            .iter()
            .map(|s| features(s, with_depth))
            .collect::<Result<Vec<_>>>()?;
        if rows.is_empty() {
            return Err(Error::invalid("split", "the train split has no targets"));
        }
        let x = DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j]);
        let y = DMatrix::from_fn(train.len(), train[0].distribution.mean.len(), |i, j| {
            train[i].distribution.mean[j]
        });
        let gram = x.transpose() * &x + DMatrix::identity(x.ncols(), x.ncols()) * RIDGE;
        let coefficients = gram
            .cholesky()
            .ok_or_else(|| Error::Numerical("baseline normal equations not positive".into()))?
            .solve(&(x.transpose() * y));
        Ok(ConditionBaseline {
            with_depth,
            coefficients,
        })
    }

    /// The predicted mean weights of one sample.
    pub fn predict(&self, sample: &Sample) -> Result<DVector<f64>> {
        let f = DVector::from_vec(features(sample, self.with_depth)?);
        Ok(self.coefficients.transpose() * f)
    }
}

/// Fit on `train`, score on `eval` (see the module docs). Depth is used
/// when every sample of both has it.
pub fn evaluate_baseline(
    train: &[Sample],
    eval: &[Sample],
    basis: &Basis,
    fk: super::eval::TcpFk,
) -> Result<BaselineEval> {
    let with_depth = train
        .iter()
        .chain(eval)
        .all(|s| s.prepared.depth_m.is_some());
    let baseline = ConditionBaseline::fit(train, with_depth)?;
    let mut total = 0.0;
    for s in eval {
        let truth = &s.distribution;
        let predicted = WeightDistribution::new(
            baseline.predict(s)?,
            truth.cov.clone(),
            truth.n_joints,
            truth.n_basis,
        )?;
        let (p, _) = final_marginal(&predicted, basis);
        let (t, _) = final_marginal(truth, basis);
        total += (fk(&p).translation.vector - fk(&t).translation.vector).norm();
    }
    Ok(BaselineEval {
        baseline_inputs: if with_depth {
            "box centre + depth"
        } else {
            "box centre"
        }
        .into(),
        baseline_mean_final_position_error_m: total / eval.len().max(1) as f64,
    })
}

/// Quadratic features of a sample's condition: 1, the inputs, the products.
fn features(sample: &Sample, with_depth: bool) -> Result<Vec<f64>> {
    let inputs: Vec<f64> = sample
        .prepared
        .condition_values(with_depth)?
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let mut f = vec![1.0];
    f.extend(&inputs);
    for i in 0..inputs.len() {
        for j in i..inputs.len() {
            f.push(inputs[i] * inputs[j]);
        }
    }
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::preprocess::Prepared;

    /// A sample whose 4 mean weights are a quadratic in its condition.
    fn sample(c: [f32; 2], depth: f64) -> Sample {
        let (x, y, d) = (f64::from(c[0]), f64::from(c[1]), (depth - 0.45) / 0.1);
        let mean = DVector::from_vec(vec![1.0 + x, x * y - d, d * d, 0.5 * y + x * d]);
        Sample {
            id: "s".into(),
            config: 0,
            prepared: Prepared {
                pixels: Vec::new(),
                condition: c,
                depth_m: Some(depth),
            },
            distribution: WeightDistribution::new(mean, DMatrix::identity(4, 4), 2, 2).unwrap(),
            mean: Vec::new(),
            cov_blocks: Vec::new(),
        }
    }

    #[test]
    fn a_quadratic_map_of_the_condition_is_recovered() {
        let train: Vec<Sample> = (0..60)
            .map(|k| {
                let t = k as f64;
                // Low-discrepancy points: the inputs vary independently.
                sample(
                    [
                        (t * 0.618_034).fract() as f32,
                        (t * 0.414_214).fract() as f32,
                    ],
                    0.35 + 0.2 * (t * 0.732_051).fract(),
                )
            })
            .collect();
        let fit = ConditionBaseline::fit(&train, true).unwrap();
        let probe = sample([0.4, 0.6], 0.5);
        let err = (fit.predict(&probe).unwrap() - &probe.distribution.mean).amax();
        assert!(err < 1e-3, "{err}");
        // Without depth the same data is not a function of the condition.
        let no_depth = ConditionBaseline::fit(&train, false).unwrap();
        let err = (no_depth.predict(&probe).unwrap() - &probe.distribution.mean).amax();
        assert!(err > 1e-2, "{err}");
    }
}
