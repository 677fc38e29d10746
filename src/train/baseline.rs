//! The condition-only baseline: what the network's condition alone (the
//! box centre, and the measured depth when the dataset has it) predicts,
//! with no image, so the evaluation shows what the image adds.
//!
//! The baseline is nearest-neighbour regression: a target gets the
//! demonstrations' mean ProMP weights of the training target whose
//! condition is nearest (Euclidean, in the network's normalised condition
//! coordinates; ties to the earlier target). It is deterministic, needs no
//! training, and was the strongest condition-only predictor measured on
//! the synthetic data (k = 1 beat k = 3 and 10, and quadratic or cubic
//! ridge regression by 4×: docs/experiments.md). It is scored exactly like
//! the network's `mean_final_position_error_m`: the final TCP of the
//! predicted mean against the final TCP of the demonstrations' mean.

use super::data::Sample;
use super::final_point::{final_marginal, TcpFk};
use crate::promp::{Basis, WeightDistribution};
use crate::{Error, Result};
use serde::Serialize;

/// The baseline's figures, flattened into the evaluation report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BaselineEval {
    /// What the baseline reads (`box centre` or `box centre + depth`).
    pub baseline_inputs: String,
    /// Mean final TCP error (m) of the baseline's predicted mean trajectory.
    pub baseline_mean_final_position_error_m: f64,
}

/// Nearest-neighbour regression on the condition.
pub struct ConditionBaseline<'a> {
    with_depth: bool,
    train: &'a [Sample],
    conditions: Vec<Vec<f32>>,
}

impl<'a> ConditionBaseline<'a> {
    /// Index the training samples; with `with_depth` every sample must
    /// have its depth.
    pub fn new(train: &'a [Sample], with_depth: bool) -> Result<Self> {
        if train.is_empty() {
            return Err(Error::invalid("split", "the train split has no targets"));
        }
        let conditions = train
            .iter()
            .map(|s| s.prepared.condition_values(with_depth))
            .collect::<Result<Vec<_>>>()?;
        Ok(ConditionBaseline {
            with_depth,
            train,
            conditions,
        })
    }

    /// The training sample whose condition is nearest to `sample`'s.
    pub fn nearest(&self, sample: &Sample) -> Result<&'a Sample> {
        let c = sample.prepared.condition_values(self.with_depth)?;
        let distance = |other: &Vec<f32>| -> f64 {
            c.iter()
                .zip(other)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum()
        };
        let (best, _) =
            self.conditions
                .iter()
                .enumerate()
                .fold((0, f64::INFINITY), |(bi, bd), (i, other)| {
                    let d = distance(other);
                    if d < bd {
                        (i, d)
                    } else {
                        (bi, bd)
                    }
                });
        Ok(&self.train[best])
    }
}

/// Index `train`, score on `eval` (see the module docs). Depth is used
/// when every sample of both has it.
pub fn evaluate_baseline(
    train: &[Sample],
    eval: &[Sample],
    basis: &Basis,
    fk: TcpFk,
) -> Result<BaselineEval> {
    let with_depth = train
        .iter()
        .chain(eval)
        .all(|s| s.prepared.depth_m.is_some());
    let baseline = ConditionBaseline::new(train, with_depth)?;
    let mut total = 0.0;
    for s in eval {
        let truth = &s.distribution;
        let neighbour = &baseline.nearest(s)?.distribution;
        let predicted = WeightDistribution::new(
            neighbour.mean.clone(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::preprocess::Prepared;
    use nalgebra::{DMatrix, DVector};

    fn sample(id: &str, c: [f32; 2], depth: Option<f64>) -> Sample {
        let mean = DVector::from_vec(vec![f64::from(c[0]), f64::from(c[1]), 0.0, 1.0]);
        Sample {
            id: id.into(),
            config: 0,
            prepared: Prepared {
                pixels: Vec::new(),
                condition: c,
                depth_m: depth,
            },
            distribution: WeightDistribution::new(mean, DMatrix::identity(4, 4), 2, 2).unwrap(),
            mean: Vec::new(),
            cov_blocks: Vec::new(),
        }
    }

    #[test]
    fn the_nearest_condition_wins_and_depth_counts_when_asked() {
        let train = vec![
            sample("a", [0.2, 0.2], Some(0.40)),
            sample("b", [0.8, 0.8], Some(0.50)),
            sample("c", [0.21, 0.2], Some(0.60)),
        ];
        let probe = sample("p", [0.2, 0.2], Some(0.59));
        let box_only = ConditionBaseline::new(&train, false).unwrap();
        assert_eq!(box_only.nearest(&probe).unwrap().id, "a");
        let with_depth = ConditionBaseline::new(&train, true).unwrap();
        assert_eq!(with_depth.nearest(&probe).unwrap().id, "c");
        assert_eq!(with_depth.nearest(&train[1]).unwrap().id, "b");
        let no_depth = vec![sample("x", [0.2, 0.2], None)];
        assert!(ConditionBaseline::new(&no_depth, true).is_err());
    }
}
