//! `prior-mean`: the un-optimised mean trajectory of the prior.

use super::{verified_outcome, Case, Method, Outcome};
use crate::Result;

/// The prior mean, verified densely; "found" when it happens to be feasible.
#[derive(Clone, Copy, Debug, Default)]
pub struct PriorMean;

impl Method for PriorMean {
    fn name(&self) -> String {
        "prior-mean".to_string()
    }

    fn run(&self, case: &Case) -> Result<Outcome> {
        let mean = case.problem.prior().mean.as_slice().to_vec();
        Ok(verified_outcome(case, mean, 0))
    }
}
