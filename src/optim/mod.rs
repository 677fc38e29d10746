//! The Mahalanobis-closest trajectory optimiser: given a Gaussian prior over
//! ProMP weights, find the weights closest to it (in Mahalanobis distance)
//! whose trajectory respects the joint position, velocity, acceleration and
//! jerk limits, rest at both ends, the start configuration, the goal (a
//! position and an approach direction) and the clearance to every obstacle.
//!
//! The folders follow a request through the optimiser:
//!
//! - [`request`] — [`OptimizeRequest`] (DESIGN.md's JSON), the request
//!   limits, and the validation into a [`Problem`].
//! - [`task`] — what the request asks besides its prior: [`Goal`],
//!   [`Boundary`], [`SolverOptions`] and the bounds their fields are checked
//!   against.
//! - [`problem`] — the whitened [`Problem`] (plain data) and its parts:
//!   [`problem::whiten`] (`Σ + λI = L Lᵀ`, `w = μ + L z`: cost `|z|²`),
//!   [`problem::phases`] (joint positions and their time derivatives as rows
//!   in `z` per phase), [`problem::linear`] (limit rows, end conditions,
//!   opt-in weight bounds).
//! - `constraints` — the constraints at single phases (the goal's position
//!   and approach, the tolerant waypoints), one kind per file behind the
//!   `EndConstraint` trait that the SCP, the subproblem and the
//!   verification call alike.
//! - [`infeasible`] — proofs before any solve that a request cannot be met:
//!   the joint-space diagnosis and the closed-form duration bound.
//! - [`scp`] — the sequential convex programme: its entry points, the
//!   driver's state struct with one method per decision (`scp::state`), one
//!   iterate evaluated on the optimisation phases (`scp::evaluate`), one QP's
//!   linearisation and constraint generation (`scp::subproblem`) and the
//!   rows each QP starts with ([`scp::working_set`]).
//! - [`qp`] — one QP in Clarabel (CSC built directly), the warm-started
//!   dual active-set method ([`qp::dual_active_set`], Goldfarb–Idnani) that
//!   solves the intermediate ones ([`qp::active_set`]), and the null-space
//!   elimination of equality rows ([`qp::nullspace`]).
//! - [`verify`] — [`verify::Verifier`]: dense verification and the
//!   continuous-motion certificate ([`verify::continuous`]) of a problem's
//!   trajectories; [`Problem::trajectory`] writes the answer's samples.
//! - [`seeds`] — restarts from detours and seeded prior draws after a local minimum, and
//!   the `samples: N` projected prior draws.
//! - [`solution`] — [`Solution`], [`SolveStats`], [`SolveControl`], [`Sharing`];
//!   [`report`] — the response types; [`tolerances`] — every tolerance and
//!   convergence threshold.
//!
//! The arrows run one way: `request` → `task`, `problem` → `scp` / `verify`
//! → `qp`; nothing below `request` imports it.
//!
//! Determinism: the same request gives the same response bytes except for
//! the wall-clock `solve_ms` fields.

pub mod auto_duration;
mod constraints;
pub mod finer_basis;
pub mod infeasible;
pub mod problem;
pub mod qp;
pub mod report;
pub mod request;
pub mod scp;
pub mod seeds;
pub mod solution;
pub mod stop_reason;
pub mod task;
pub mod tolerances;
pub mod verify;

pub use auto_duration::optimize_auto_duration;
pub use problem::Problem;
pub use report::{
    Closest, JointTrajectory, OptimizeResponse, SampleResult, Status, TrajectoryPoint,
    TrajectoryReport,
};
pub use request::{OptimizeRequest, PriorSpec, Task};
pub use solution::{Sharing, Solution, SolveControl, SolveStats};
pub use stop_reason::{Interruption, StopReason};
pub use task::{Boundary, Goal, GoalApproach, InnerSolver, SolverOptions, Waypoint};
pub use tolerances::FEASIBILITY_TOLERANCE;

use crate::promp::{Basis, WeightDistribution};
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
///
/// With the smoothness prior on its default basis, a solve that finds no
/// certified answer is tried again on finer bases
/// ([`finer_basis::refine`]).
pub fn optimize_with(
    request: &OptimizeRequest,
    robot: &Robot,
    ctl: &SolveControl,
) -> Result<OptimizeResponse> {
    let on_its_basis = |request: &OptimizeRequest| {
        respond(&request.task, ctl, &|task: &Task| {
            request::validate_spec(&request.prior, task, robot)
        })
    };
    let answer = on_its_basis(request)?;
    finer_basis::refine(request, answer, ctl, &on_its_basis)
}

/// [`optimize_with`] for a prior that is already a distribution (the
/// network's, in [`crate::plan`]): the task validated with it
/// ([`Task::validate`], which reuses `basis` when it is the task's), no
/// round trip through the wire format; the same answer as the request
/// with `PriorSpec::from(prior)`.
pub fn optimize_prior(
    prior: &WeightDistribution,
    task: &Task,
    basis: &Basis,
    robot: &Robot,
    ctl: &SolveControl,
) -> Result<OptimizeResponse> {
    respond(task, ctl, &|task: &Task| task.validate(robot, prior, basis))
}

/// Validate `task` (with its prior, by `validate`), diagnose, solve and
/// verify; `validate` also builds the problems of the duration search.
fn respond(
    task: &Task,
    ctl: &SolveControl,
    validate: &dyn Fn(&Task) -> Result<Problem>,
) -> Result<OptimizeResponse> {
    let started = Instant::now();
    let problem = validate(task)?;
    let mean = problem.prior().mean.as_slice().to_vec();
    let prior_mean_report = prior_mean_report(&problem, ctl);
    let mut response = if let Some(found) = problem.diagnosis() {
        let proof = (StopReason::ProvenInfeasible, found.reason);
        let mut r = infeasible_at_prior_mean(&problem, mean, prior_mean_report, proof);
        r.culprit = Some(found.culprit);
        r
    } else if let Some(proof) = problem.duration_proof() {
        let why = (StopReason::DurationTooShort, proof.reason);
        let mut r = infeasible_at_prior_mean(&problem, mean, prior_mean_report, why);
        r.duration_lower_bound_s = proof.lower_bound_s;
        r.min_duration_s = verified_duration(task, validate, proof.lower_bound_s, ctl);
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
            stop_reason: solution.stop_reason,
            duration_s: task.duration_s,
            trajectory: problem.trajectory(&solution.weights),
            mahalanobis: solution.mahalanobis,
            weights: solution.weights,
            report: solution.report,
            prior_mean_report,
            samples,
            reason: solution.reason,
            min_duration_s: None,
            duration_lower_bound_s: None,
            culprit: None,
            promp: None,
        }
    };
    response.report.solve_ms = started.elapsed().as_secs_f64() * 1e3;
    Ok(response)
}

/// The dense verification of the prior mean, with the problem's own
/// warnings first: every answer's `prior_mean_report`.
fn prior_mean_report(problem: &Problem, ctl: &SolveControl) -> TrajectoryReport {
    let mut report = problem.evaluate_with(problem.prior().mean.as_slice(), ctl);
    let mut warnings = problem.warnings().to_vec();
    warnings.append(&mut report.warnings);
    report.warnings = warnings;
    report
}

/// The answer for a request proven infeasible before any solve: the prior
/// mean, its report, and why (the proof's kind and its words).
fn infeasible_at_prior_mean(
    problem: &Problem,
    mean: Vec<f64>,
    prior_mean_report: TrajectoryReport,
    (stop_reason, reason): (StopReason, String),
) -> OptimizeResponse {
    OptimizeResponse {
        status: stop_reason.status(),
        stop_reason,
        duration_s: problem.duration(),
        mahalanobis: 0.0,
        trajectory: problem.trajectory(&mean),
        report: prior_mean_report.clone(),
        prior_mean_report,
        weights: mean,
        samples: Vec::new(),
        reason: Some(reason),
        min_duration_s: None,
        duration_lower_bound_s: None,
        culprit: None,
        promp: None,
    }
}

/// The first duration, from the proven lower bound up by
/// [`infeasible::duration::DURATION_SEARCH_GROWTH`] each try, at which a verified
/// solve of `task` (without its extra samples) reaches `optimal`;
/// `None` when none does within [`infeasible::duration::DURATION_SEARCH_BUDGET`], the
/// caller's deadline or [`task::MAX_DURATION_S`]. The solve is
/// deterministic, so the same request at the returned duration answers
/// `optimal` again.
fn verified_duration(
    task: &Task,
    validate: &dyn Fn(&Task) -> Result<Problem>,
    lower_bound: Option<f64>,
    ctl: &SolveControl,
) -> Option<f64> {
    let budget_end = Instant::now() + infeasible::duration::DURATION_SEARCH_BUDGET;
    let search = SolveControl {
        deadline: Some(ctl.deadline.map_or(budget_end, |d| d.min(budget_end))),
        cancel: ctl.cancel.clone(),
        sharing: ctl.sharing.clone(),
    };
    let mut duration = lower_bound? * infeasible::duration::DURATION_SEARCH_GROWTH;
    while duration <= task::MAX_DURATION_S && !search.should_stop() {
        let mut at = task.clone();
        at.duration_s = (duration * 1000.0).ceil() / 1000.0;
        at.samples = 0;
        let problem = validate(&at).ok()?;
        if problem.diagnose().is_none() && problem.duration_proof().is_none() {
            let solution = problem.solve(&search).ok()?;
            if solution.status == Status::Optimal {
                return Some(at.duration_s);
            }
        }
        duration *= infeasible::duration::DURATION_SEARCH_GROWTH;
    }
    None
}
