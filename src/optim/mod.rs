//! The Mahalanobis-closest trajectory optimiser: given a Gaussian prior over
//! ProMP weights, find the weights closest to it (in Mahalanobis distance)
//! whose trajectory respects the joint position, velocity, acceleration and
//! jerk limits, rest at both ends, the start configuration, the goal (a
//! position and an approach direction) and the clearance to every obstacle.
//!
//! - [`request`] — [`OptimizeRequest`] (DESIGN.md's JSON), [`SolverOptions`],
//!   the request limits, and the validation into a [`Problem`].
//! - [`problem`] — the whitened [`Problem`] (plain data).
//! - [`whiten`] — `Σ + λI = L Lᵀ`, `w = μ + L z`: cost `|z|²`.
//! - [`phases`] — joint positions and their time derivatives as rows in `z` per phase.
//! - [`linear`] — limit rows (position to jerk), end conditions, opt-in weight bounds.
//! - [`duration`] — the closed-form duration bound from the rate limits: a proof that a request is too short.
//! - [`qp`] — one QP in Clarabel (CSC built directly).
//! - [`dual_active_set`] — the warm-started inner QP solver (Goldfarb–Idnani).
//! - [`qp_active_set`] — a [`qp::Qp`] solved by it (the SCP's intermediate steps).
//! - [`nullspace`] — equality rows eliminated before Clarabel sees a QP.
//! - [`scp`] — the entry points of the SCP: solve towards the prior mean, project a draw.
//! - `scp_state` — the driver's state struct and its named steps.
//! - [`solution`] — [`Solution`], [`SolveStats`], [`SolveControl`].
//! - [`tolerances`] — every tolerance and convergence threshold.
//! - [`restart`] — restarts from seeded prior draws after a local minimum.
//! - `evaluate` — one iterate on the optimisation phases: clearances, goal, merit.
//! - `subproblem` — one QP: linearisation, working set, constraint generation.
//! - [`verify`] — dense verification and the trajectory output.
//! - [`working_set`] — which candidate rows each QP starts with and gains.
//! - [`diagnose`] — infeasibility diagnosis before solving.
//! - [`sampling`] — `samples: N` projected prior draws.
//! - [`report`] — the response types.
//!
//! Determinism: the same request gives the same response bytes except for
//! the wall-clock `solve_ms` fields.

pub mod continuous;
pub mod diagnose;
pub mod dual_active_set;
pub mod duration;
mod evaluate;
pub mod linear;
pub mod nullspace;
pub mod phases;
pub mod problem;
pub mod qp;
pub mod qp_active_set;
pub mod report;
pub mod request;
pub mod restart;
pub mod sampling;
pub mod scp;
mod scp_state;
pub mod solution;
mod subproblem;
pub mod tolerances;
pub mod verify;
pub mod whiten;
pub mod working_set;

pub use problem::Problem;
pub use report::{
    Closest, JointTrajectory, OptimizeResponse, SampleResult, Status, TrajectoryPoint,
    TrajectoryReport,
};
pub use request::{Boundary, Goal, InnerSolver, OptimizeRequest, PriorSpec, SolverOptions};
pub use solution::{Solution, SolveControl, SolveStats};
pub use tolerances::FEASIBILITY_TOLERANCE;

use crate::robot::Robot;
use crate::Result;
use std::time::Instant;

/// Validate, diagnose, solve and verify one request.
pub fn optimize(request: &OptimizeRequest, robot: &Robot) -> Result<OptimizeResponse> {
    optimize_with(request, robot, &SolveControl::default())
}

/// [`optimize`] with a deadline / cancel flag, which bound all of the
/// request's work (validation aside): the prior mean's verification, the
/// solve with its restarts, the duration search and the samples. A stopped
/// solve answers status `max_iterations` with a warning. `report.solve_ms`
/// is the whole call's wall time.
pub fn optimize_with(
    request: &OptimizeRequest,
    robot: &Robot,
    ctl: &SolveControl,
) -> Result<OptimizeResponse> {
    let started = Instant::now();
    let problem = request.validate(robot)?;
    let mean = problem.prior().mean.as_slice().to_vec();
    let mut prior_mean_report = problem.evaluate_with(&mean, ctl);
    let mut warnings = problem.warnings().to_vec();
    warnings.append(&mut prior_mean_report.warnings);
    prior_mean_report.warnings = warnings;
    let mut response = if let Some(reason) = problem.diagnose() {
        infeasible_at_prior_mean(&problem, mean, prior_mean_report, reason)
    } else if let Some(proof) = problem.duration_proof() {
        let mut r = infeasible_at_prior_mean(&problem, mean, prior_mean_report, proof.reason);
        r.duration_lower_bound_s = proof.lower_bound_s;
        r.min_duration_s = verified_duration(request, robot, proof.lower_bound_s, ctl);
        r
    } else {
        let solution = problem.solve(ctl)?;
        let samples = if problem.extra_samples() > 0 {
            problem.feasible_samples(problem.extra_samples(), ctl)?
        } else {
            Vec::new()
        };
        OptimizeResponse {
            status: solution.status,
            trajectory: problem.trajectory(&solution.weights),
            mahalanobis: solution.mahalanobis,
            weights: solution.weights,
            report: solution.report,
            prior_mean_report,
            samples,
            reason: solution.reason,
            min_duration_s: None,
            duration_lower_bound_s: None,
        }
    };
    response.report.solve_ms = started.elapsed().as_secs_f64() * 1e3;
    Ok(response)
}

/// The answer for a request proven infeasible before any solve: the prior
/// mean, its report, and why.
fn infeasible_at_prior_mean(
    problem: &Problem,
    mean: Vec<f64>,
    prior_mean_report: TrajectoryReport,
    reason: String,
) -> OptimizeResponse {
    OptimizeResponse {
        status: Status::Infeasible,
        mahalanobis: 0.0,
        trajectory: problem.trajectory(&mean),
        report: prior_mean_report.clone(),
        prior_mean_report,
        weights: mean,
        samples: Vec::new(),
        reason: Some(reason),
        min_duration_s: None,
        duration_lower_bound_s: None,
    }
}

/// The first duration, from the proven lower bound up by
/// [`duration::DURATION_SEARCH_GROWTH`] each try, at which a verified
/// solve of `request` (without its extra samples) reaches `optimal`;
/// `None` when none does within [`duration::DURATION_SEARCH_BUDGET`], the
/// caller's deadline or [`request::MAX_DURATION_S`]. The solve is
/// deterministic, so the same request at the returned duration answers
/// `optimal` again.
fn verified_duration(
    request: &OptimizeRequest,
    robot: &Robot,
    lower_bound: Option<f64>,
    ctl: &SolveControl,
) -> Option<f64> {
    let budget_end = Instant::now() + duration::DURATION_SEARCH_BUDGET;
    let search = SolveControl {
        deadline: Some(ctl.deadline.map_or(budget_end, |d| d.min(budget_end))),
        cancel: ctl.cancel.clone(),
    };
    let mut duration = lower_bound? * duration::DURATION_SEARCH_GROWTH;
    while duration <= request::MAX_DURATION_S && !search.should_stop() {
        let mut at = request.clone();
        at.duration_s = (duration * 1000.0).ceil() / 1000.0;
        at.samples = 0;
        let problem = at.validate(robot).ok()?;
        if problem.diagnose().is_none() && problem.duration_proof().is_none() {
            let solution = problem.solve(&search).ok()?;
            if solution.status == Status::Optimal {
                return Some(at.duration_s);
            }
        }
        duration *= duration::DURATION_SEARCH_GROWTH;
    }
    None
}
