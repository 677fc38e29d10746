//! `dpmp-qp`: the product's optimiser end to end ([`crate::optim::optimize`]:
//! validation, diagnosis, SCP with Clarabel, dense verification).

use super::{Case, Method, Outcome};
use crate::optim::{optimize, Status};
use crate::Result;

/// The trust-region SCP optimiser; "found" when it answers `optimal`.
#[derive(Clone, Copy, Debug, Default)]
pub struct DpmpQp;

impl Method for DpmpQp {
    fn name(&self) -> String {
        "dpmp-qp".to_string()
    }

    fn run(&self, case: &Case) -> Result<Outcome> {
        let response = optimize(case.request, case.robot)?;
        Ok(Outcome {
            found: response.status == Status::Optimal,
            iterations: response.report.iterations,
            weights: response.weights,
            report: response.report,
            reason: response.reason,
        })
    }
}
