//! `samples: N`: draws from the prior (seeded by `options.seed`), each
//! projected onto the feasible set by the same solver (Mahalanobis-closest
//! feasible weights to the draw); the feasible projections are returned.

use crate::optim::problem::Problem;
use crate::optim::report::{SampleResult, Status};
use crate::optim::solution::SolveControl;
use crate::Result;
use nalgebra::DVector;
use rand::SeedableRng;
use rayon::prelude::*;

impl Problem {
    /// Project `n` seeded prior draws; keep the `optimal` ones, in draw order.
    pub fn feasible_samples(&self, n: usize, ctl: &SolveControl) -> Result<Vec<SampleResult>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.options.seed);
        let draws = self.prior.sample(&mut rng, n);
        let project = |draw| self.project_draw(draw, ctl);
        let results: Vec<Result<Option<SampleResult>>> = if ctl.parallel() {
            draws.par_iter().map(project).collect()
        } else {
            draws.iter().map(project).collect()
        };
        let mut out = Vec::new();
        for r in results {
            if let Some(s) = r? {
                out.push(s);
            }
        }
        Ok(out)
    }

    fn project_draw(
        &self,
        draw: &DVector<f64>,
        ctl: &SolveControl,
    ) -> Result<Option<SampleResult>> {
        let sol = self.project(draw.as_slice(), ctl)?;
        if sol.status != Status::Optimal {
            return Ok(None);
        }
        let w = DVector::from_column_slice(&sol.weights);
        let distance_to_draw = (self.whitening.whiten(&w) - self.whitening.whiten(draw)).norm();
        Ok(Some(SampleResult {
            status: sol.status,
            trajectory: self.trajectory(&sol.weights),
            mahalanobis: sol.mahalanobis,
            distance_to_draw,
            weights: sol.weights,
            report: sol.report,
        }))
    }
}
