//! `rejection-N`: N seeded draws from the prior (conditioned on the start),
//! keep the most likely one (smallest Mahalanobis distance) that satisfies
//! every constraint under dense verification.
//!
//! Draws are checked in order of increasing Mahalanobis distance, so the
//! first feasible one is the answer; a cheap goal check (FK of the final
//! configuration only) skips draws that miss the goal before the dense
//! verification.

use super::start_condition::StartConditioned;
use super::{Case, Method, Outcome};
use crate::optim::FEASIBILITY_TOLERANCE;
use crate::Result;
use nalgebra::DVector;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Rejection sampling from the prior.
#[derive(Clone, Copy, Debug)]
pub struct Rejection {
    /// Number of draws N.
    pub draws: usize,
    /// Seed of the draws.
    pub seed: u64,
}

impl Method for Rejection {
    fn name(&self) -> String {
        format!("rejection-{}", self.draws)
    }

    fn run(&self, case: &Case) -> Result<Outcome> {
        let cond = StartConditioned::new(case)?;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut ranked: Vec<(f64, Vec<f64>)> = cond
            .dist
            .sample(&mut rng, self.draws)
            .into_iter()
            .map(|w| {
                let mut w = w.as_slice().to_vec();
                cond.pin_start(&mut w);
                (case.problem.mahalanobis(&w), w)
            })
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        let psi1 = cond.basis.row_at(1.0);
        let mut checked = 0;
        for (_, w) in &ranked {
            if !reaches_goal(case, &psi1, w) {
                continue;
            }
            checked += 1;
            let report = case.problem.evaluate(w);
            if case.problem.is_feasible(&report) {
                return Ok(Outcome {
                    found: true,
                    weights: w.clone(),
                    report,
                    iterations: checked,
                    reason: None,
                });
            }
        }
        let best = ranked
            .into_iter()
            .next()
            .map(|(_, w)| w)
            .unwrap_or_else(|| case.problem.prior().mean.as_slice().to_vec());
        Ok(Outcome {
            report: case.problem.evaluate(&best),
            weights: best,
            found: false,
            iterations: checked,
            reason: Some(format!("none of {} draws is feasible", self.draws)),
        })
    }
}

/// Whether the final TCP of `w` is within the goal tolerance (true without a goal).
fn reaches_goal(case: &Case, psi1: &DVector<f64>, w: &[f64]) -> bool {
    let Some(goal) = &case.request.task.goal else {
        return true;
    };
    let nb = psi1.len();
    let q: Vec<f64> = (0..case.robot.dof())
        .map(|j| {
            psi1.iter()
                .zip(&w[j * nb..(j + 1) * nb])
                .map(|(a, b)| a * b)
                .sum()
        })
        .collect();
    let p = case.robot.tcp_pose(&q).translation.vector;
    let g = nalgebra::Vector3::from(goal.position);
    (p - g).norm() <= goal.tolerance_m + FEASIBILITY_TOLERANCE
}
