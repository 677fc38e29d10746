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
//! - [`duration`] — the shortest feasible duration when the limits make a request infeasible.
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

/// Validate, diagnose, solve and verify one request.
pub fn optimize(request: &OptimizeRequest, robot: &Robot) -> Result<OptimizeResponse> {
    optimize_with(request, robot, &SolveControl::default())
}

/// [`optimize`] with a deadline / cancel flag: a stopped solve answers
/// status `max_iterations` with a warning.
pub fn optimize_with(
    request: &OptimizeRequest,
    robot: &Robot,
    ctl: &SolveControl,
) -> Result<OptimizeResponse> {
    let problem = request.validate(robot)?;
    let mean = problem.prior().mean.as_slice().to_vec();
    let mut prior_mean_report = problem.evaluate(&mean);
    prior_mean_report.warnings = problem.warnings().to_vec();
    if let Some(reason) = problem.diagnose() {
        return Ok(OptimizeResponse {
            status: Status::Infeasible,
            mahalanobis: 0.0,
            trajectory: problem.trajectory(&mean),
            report: prior_mean_report.clone(),
            prior_mean_report,
            weights: mean,
            samples: Vec::new(),
            reason: Some(reason),
            min_duration_s: None,
        });
    }
    let mut solution = problem.solve(ctl)?;
    let mut min_duration_s = None;
    // A stopped solve (deadline, cancel) answers at once, undiagnosed.
    if solution.status != Status::Optimal && ctl.stop_reason().is_none() {
        if let Some(d) = problem.duration_diagnosis() {
            solution.status = Status::Infeasible;
            solution.reason = Some(d.reason);
            min_duration_s = d.min_duration_s;
        }
    }
    let samples = if problem.extra_samples() > 0 {
        problem.feasible_samples(problem.extra_samples(), ctl)?
    } else {
        Vec::new()
    };
    Ok(OptimizeResponse {
        status: solution.status,
        trajectory: problem.trajectory(&solution.weights),
        mahalanobis: solution.mahalanobis,
        weights: solution.weights,
        report: solution.report,
        prior_mean_report,
        samples,
        reason: solution.reason,
        min_duration_s,
    })
}
