//! The compared methods behind one [`Method`] trait: each takes a validated
//! problem and returns weights with the dense verification of their
//! trajectory ([`Outcome`]).
//!
//! - [`prior_mean::PriorMean`] — the un-optimised mean (what the paper executes).
//! - [`rejection::Rejection`] — N seeded prior draws, keep the most likely feasible one.
//! - [`dpmp_qp::DpmpQp`] — the optimiser ([`crate::optim::optimize`]).
//! - [`penalty_gd::PenaltyGd`] — gradient descent on `|z|²` + squared-hinge penalties.

pub mod dpmp_qp;
pub mod penalty_gd;
mod penalty_terms;
pub mod prior_mean;
pub mod rejection;
mod start_condition;

use crate::optim::{OptimizeRequest, Problem, TrajectoryReport};
use crate::robot::Robot;
use crate::{Error, Result};

/// Everything a method may use about one problem.
pub struct Case<'a> {
    /// The request as read from the problem file.
    pub request: &'a OptimizeRequest,
    /// The validated (whitened, repaired) problem.
    pub problem: &'a Problem,
    /// The robot.
    pub robot: &'a Robot,
}

/// What a method returns.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Whether the method answers "here is a feasible trajectory" (false:
    /// it reports the problem infeasible or gave up).
    pub found: bool,
    /// The returned weights (when nothing was found: the method's best
    /// effort, whose violations the report shows).
    pub weights: Vec<f64>,
    /// Dense verification of `weights`.
    pub report: TrajectoryReport,
    /// Work done: QPs, gradient steps or densely checked draws.
    pub iterations: usize,
    /// Why nothing was found, when the method says.
    pub reason: Option<String>,
}

/// A benchmarked planning method.
pub trait Method: Send + Sync {
    /// The name used in `--methods` and the reports.
    fn name(&self) -> String;
    /// Plan one problem.
    fn run(&self, case: &Case) -> Result<Outcome>;
}

/// The default method list: prior-mean, rejection-100, rejection-1000,
/// dpmp-qp, penalty-gd.
pub const DEFAULT_METHODS: [&str; 5] = [
    "prior-mean",
    "rejection-100",
    "rejection-1000",
    "dpmp-qp",
    "penalty-gd",
];

/// Build a method from its name (`prior-mean`, `rejection-N`, `dpmp-qp`,
/// `penalty-gd`); errors name `--methods`.
pub fn method_from_name(name: &str) -> Result<Box<dyn Method>> {
    match name {
        "prior-mean" => Ok(Box::new(prior_mean::PriorMean)),
        "dpmp-qp" => Ok(Box::new(dpmp_qp::DpmpQp)),
        "penalty-gd" => Ok(Box::new(penalty_gd::PenaltyGd::default())),
        _ => match name.strip_prefix("rejection-").map(str::parse::<usize>) {
            Some(Ok(n)) if (1..=100_000).contains(&n) => {
                Ok(Box::new(rejection::Rejection { draws: n, seed: 0 }))
            }
            _ => Err(Error::invalid(
                "--methods",
                format!(
                    "unknown method {name:?}: expected prior-mean, rejection-N (1 <= N <= 100000), dpmp-qp or penalty-gd"
                ),
            )),
        },
    }
}

/// The dense verification of `weights` packed as an outcome that is
/// `found` exactly when it verifies feasible.
pub fn verified_outcome(case: &Case, weights: Vec<f64>, iterations: usize) -> Outcome {
    let report = case.problem.evaluate(&weights);
    let found = case.problem.is_feasible(&report);
    Outcome {
        found,
        weights,
        report,
        iterations,
        reason: (!found).then(|| "the returned trajectory violates a constraint".to_string()),
    }
}
