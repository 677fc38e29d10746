//! Generation-time checks of a problem's feasibility claim.
//!
//! A problem marked feasible must come with a *witness*: weights whose
//! dense verification ([`crate::optim::Problem::evaluate`]) satisfies every
//! constraint of the very request written to disk. Candidates are the
//! synthetic demonstrations and the prior mean, each moved the least (in
//! the weights' Euclidean norm) to start exactly at the request's start
//! configuration ([`pin_start`]).

use crate::optim::{OptimizeRequest, Problem, TrajectoryReport};
use crate::promp::Basis;
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::DVector;
use serde_json::Value;

/// Parse and validate a request exactly as the runner does.
pub fn validated(request: &Value, robot: &Robot) -> Result<Problem> {
    let parsed: OptimizeRequest = serde_json::from_value(request.clone())
        .map_err(|e| Error::invalid("request", format!("does not parse: {e}")))?;
    parsed.validate(robot)
}

/// `w` (joint-major, `n_basis` per joint) with each joint's weights moved
/// along the phase-0 basis row so the trajectory starts at `start`: the
/// minimum-norm correction `w_j + ψ₀ (s_j - ψ₀ᵀ w_j) / |ψ₀|²`.
pub fn pin_start(basis: &Basis, w: &DVector<f64>, start: &[f64]) -> DVector<f64> {
    let psi0 = basis.row_at(0.0);
    let nb = basis.n_basis();
    let norm2 = psi0.norm_squared();
    let mut out = w.clone();
    for (j, s) in start.iter().enumerate() {
        let block = w.rows(j * nb, nb);
        let gap = s - psi0.dot(&block);
        for i in 0..nb {
            out[j * nb + i] += psi0[i] * gap / norm2;
        }
    }
    out
}

/// One verified candidate.
pub struct Witness {
    /// Index into the candidate list.
    pub index: usize,
    /// Its dense verification.
    pub report: TrajectoryReport,
}

/// Every candidate's dense verification against `problem`.
pub fn reports(problem: &Problem, candidates: &[DVector<f64>]) -> Vec<TrajectoryReport> {
    candidates
        .iter()
        .map(|w| problem.evaluate(w.as_slice()))
        .collect()
}

/// The first candidate that satisfies every constraint of `problem`.
pub fn find_witness(problem: &Problem, candidates: &[DVector<f64>]) -> Option<Witness> {
    reports(problem, candidates)
        .into_iter()
        .enumerate()
        .find(|(_, r)| problem.is_feasible(r))
        .map(|(index, report)| Witness { index, report })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;

    #[test]
    fn pinned_weights_start_exactly_at_the_start() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let nb = basis.n_basis();
        let w = DVector::from_fn(7 * nb, |i, _| (i as f64 * 0.37).sin());
        let start: Vec<f64> = (0..7).map(|j| 0.1 * j as f64 - 0.2).collect();
        let pinned = pin_start(&basis, &w, &start);
        let psi0 = basis.row_at(0.0);
        for (j, s) in start.iter().enumerate() {
            let q0 = psi0.dot(&pinned.rows(j * nb, nb));
            assert!((q0 - s).abs() < 1e-12, "joint {j}: {q0} vs {s}");
        }
        // Minimum norm: the correction is parallel to ψ₀ in every block.
        let d = &pinned - &w;
        for j in 0..7 {
            let block = d.rows(j * nb, nb).into_owned();
            let along = psi0.dot(&block) / psi0.norm();
            assert!((block.norm() - along.abs()).abs() < 1e-12);
        }
    }
}
