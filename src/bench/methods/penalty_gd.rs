//! `penalty-gd`: gradient descent with a backtracking (Armijo) line search
//! on `|z|² + ρ·P(w(z))`, where `w = μ_s + L_s z` whitens the prior
//! conditioned on the start ([`super::start_condition`]) and `P` is the
//! squared-hinge penalty of [`super::penalty_terms`] (clearance, limits,
//! velocity, goal). `ρ` grows over rounds until the dense verification
//! passes: the simple penalty baseline that TrajOpt and CHOMP refine.

use super::penalty_terms::PenaltyModel;
use super::start_condition::StartConditioned;
use super::{verified_outcome, Case, Method, Outcome};
use crate::promp::psd;
use crate::Result;
use nalgebra::{DMatrix, DVector};

/// Settings of the penalty descent.
#[derive(Clone, Debug)]
pub struct PenaltyGd {
    /// Phases of the penalty grid.
    pub phases: usize,
    /// Gradient steps per penalty round.
    pub steps_per_round: usize,
    /// Penalty weights, one round each.
    pub rho: Vec<f64>,
}

impl Default for PenaltyGd {
    fn default() -> Self {
        PenaltyGd {
            phases: 60,
            steps_per_round: 80,
            rho: vec![1e3, 1e5, 1e7],
        }
    }
}

/// The whitened objective of one round.
struct Objective<'a> {
    case: &'a Case<'a>,
    model: &'a PenaltyModel,
    mean: &'a DVector<f64>,
    l: &'a DMatrix<f64>,
    rho: f64,
}

impl Objective<'_> {
    fn weights(&self, z: &DVector<f64>) -> DVector<f64> {
        self.mean + self.l * z
    }

    fn value(&self, z: &DVector<f64>) -> f64 {
        let w = self.weights(z);
        z.norm_squared()
            + self.rho
                * self
                    .model
                    .value_and_gradient(self.case.robot, w.as_slice())
                    .0
    }

    fn value_and_gradient(&self, z: &DVector<f64>) -> (f64, DVector<f64>) {
        let w = self.weights(z);
        let (p, gp) = self.model.value_and_gradient(self.case.robot, w.as_slice());
        let grad = z * 2.0 + self.l.tr_mul(&gp) * self.rho;
        (z.norm_squared() + self.rho * p, grad)
    }
}

impl PenaltyGd {
    /// Gradient descent from `z`; returns the final `z` and the steps taken.
    fn descend(&self, obj: &Objective, mut z: DVector<f64>) -> (DVector<f64>, usize) {
        let mut alpha = 1.0;
        for step in 0..self.steps_per_round {
            let (f, g) = obj.value_and_gradient(&z);
            let g2 = g.norm_squared();
            if g2 <= 1e-18 * (1.0 + f * f) {
                return (z, step);
            }
            alpha *= 4.0;
            loop {
                let trial = &z - &g * alpha;
                if obj.value(&trial) <= f - 1e-4 * alpha * g2 {
                    z = trial;
                    break;
                }
                alpha *= 0.5;
                if alpha < 1e-14 {
                    return (z, step);
                }
            }
        }
        (z, self.steps_per_round)
    }
}

impl Method for PenaltyGd {
    fn name(&self) -> String {
        "penalty-gd".to_string()
    }

    fn run(&self, case: &Case) -> Result<Outcome> {
        let cond = StartConditioned::new(case)?;
        let l = psd::factor(&cond.dist.cov);
        let model = PenaltyModel::new(case, &cond.basis, self.phases)?;
        let mut z = DVector::zeros(l.ncols());
        let mut steps = 0;
        let mut outcome = None;
        for &rho in &self.rho {
            let obj = Objective {
                case,
                model: &model,
                mean: &cond.dist.mean,
                l: &l,
                rho,
            };
            let (next, taken) = self.descend(&obj, z);
            z = next;
            steps += taken;
            let mut w = obj.weights(&z).as_slice().to_vec();
            cond.pin_start(&mut w);
            let result = verified_outcome(case, w, steps);
            let done = result.found;
            outcome = Some(result);
            if done {
                break;
            }
        }
        match outcome {
            Some(o) => Ok(o),
            None => {
                let mut w = cond.dist.mean.as_slice().to_vec();
                cond.pin_start(&mut w);
                Ok(verified_outcome(case, w, 0))
            }
        }
    }
}
