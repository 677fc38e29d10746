//! The prior conditioned on the request's start configuration, shared by
//! the sampling and gradient baselines (a prior draw never meets an exact
//! start equality; a draw from the conditioned prior does, up to rounding,
//! which [`StartConditioned::pin_start`] removes).

use super::Case;
use crate::promp::{Basis, ViaPoint, WeightDistribution};
use crate::Result;
use nalgebra::DVector;

/// The conditioned prior and what is needed to pin the start exactly.
pub struct StartConditioned {
    /// The prior, conditioned on `q(0) = start` when a start is given.
    pub dist: WeightDistribution,
    /// The optimisation-grid basis.
    pub basis: Basis,
    start: Option<(Vec<f64>, DVector<f64>)>,
}

impl StartConditioned {
    /// Condition `case.problem.prior()` on the request's start.
    pub fn new(case: &Case) -> Result<StartConditioned> {
        let basis = Basis::new(&case.request.task.promp)?;
        let prior = case.problem.prior();
        let Some(start) = &case.request.task.start else {
            return Ok(StartConditioned {
                dist: prior.clone(),
                basis,
                start: None,
            });
        };
        let via = ViaPoint {
            phase: 0.0,
            q: start.clone(),
            noise_var: 0.0,
        };
        let dist = prior.condition(&basis, &[via])?;
        let psi0 = basis.row_at(0.0);
        Ok(StartConditioned {
            dist,
            basis,
            start: Some((start.clone(), psi0)),
        })
    }

    /// Move `w` by the smallest Euclidean change that makes `q(0)` equal
    /// the start exactly (per joint, along `psi(0)`).
    pub fn pin_start(&self, w: &mut [f64]) {
        let Some((start, psi0)) = &self.start else {
            return;
        };
        let nb = psi0.len();
        let norm2 = psi0.norm_squared();
        for (j, s) in start.iter().enumerate() {
            let block = &mut w[j * nb..(j + 1) * nb];
            let q0: f64 = block.iter().zip(psi0.iter()).map(|(a, b)| a * b).sum();
            let step = (q0 - s) / norm2;
            for (wi, p) in block.iter_mut().zip(psi0.iter()) {
                *wi -= step * p;
            }
        }
    }
}
