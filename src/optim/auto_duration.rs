//! `duration: auto`: the shortest duration, within [`AUTO_DURATION_STEP`],
//! at which the certified answer respects the rate limits.
//!
//! The optimiser's path does not depend on the duration: the prior, the
//! clearance, the goal and the joint position limits live on the phase,
//! and only the velocity, acceleration and jerk rows scale with it (by
//! `1/T`, `1/T²`, `1/T³`). So the search
//!
//! 1. solves at an exploring duration, [`AUTO_EXPLORE_FACTOR`] times the
//!    closed-form lower bound ([`Problem::duration_lower_bound`]) and at
//!    least [`AUTO_MIN_DURATION_S`], where the rate limits seldom bind;
//! 2. from that certified answer's peak rate ratios (`r_v`, `r_a`, `r_j`
//!    of its dense verification) computes the shortest duration at which
//!    the same path keeps every limit, `T₀ · max(r_v, √r_a, ∛r_j)`;
//! 3. takes the same weights at that duration (rounded up to the
//!    millisecond) and verifies them there ([`retimed`]); when they do not
//!    pass (a rate peak the dense samples rounded), at durations
//!    [`AUTO_DURATION_STEP`] longer each time, until they pass or the
//!    exploring duration is reached.
//!
//! Retiming needs no second search. The clearance, the goal, the joint
//! position limits, the prior and the phase grids are the same at every
//! duration; only the rate rows tighten as the duration shrinks. So the
//! feasible set at the shorter duration is a subset of the exploring one,
//! and the explored optimum, once verified to lie in it, is a local optimum
//! there too, with the same Clarabel certificate: its KKT conditions hold
//! with a zero multiplier on every rate row the retiming made active. A
//! request whose waypoints are given in seconds (their phase moves with the
//! duration) or that asks for `samples` is solved again at each duration
//! instead.
//!
//! The caller's deadline bounds every solve.

use super::request::OptimizeRequest;
use super::{optimize_with, prior_mean_report, OptimizeResponse, SolveControl, Status};
use crate::robot::Robot;
use crate::Result;
use nalgebra::DVector;
use std::time::Instant;

/// Each retry's duration is this factor times the last; the answer is the
/// shortest within it.
pub const AUTO_DURATION_STEP: f64 = 1.1;
/// The exploring duration, as a multiple of the closed-form lower bound.
pub const AUTO_EXPLORE_FACTOR: f64 = 3.0;
/// The shortest exploring duration (s).
pub const AUTO_MIN_DURATION_S: f64 = 0.5;

/// [`optimize_with`] at the shortest duration (within
/// [`AUTO_DURATION_STEP`]) at which the certified answer respects the rate
/// limits; `request.task.duration_s` is ignored (see the module docs).
pub fn optimize_auto_duration(
    request: &OptimizeRequest,
    robot: &Robot,
    ctl: &SolveControl,
) -> Result<OptimizeResponse> {
    let mut at = request.clone();
    at.task.duration_s = AUTO_MIN_DURATION_S;
    let bound = at.validate(robot)?.duration_lower_bound().unwrap_or(0.0);
    let explore = round_up_ms((AUTO_EXPLORE_FACTOR * bound).max(AUTO_MIN_DURATION_S));
    at.task.duration_s = explore;
    let explored = optimize_with(&at, robot, ctl)?;
    if explored.status != Status::Optimal {
        return Ok(explored);
    }
    // A finer basis found the explored answer: its weights are on it.
    let mut at = super::finer_basis::on_answer_basis(&at, &explored);
    let mut duration = round_up_ms(explore * time_scale_to_limits(&explored).max(1e-3));
    while duration * AUTO_DURATION_STEP < explore && !ctl.should_stop() {
        at.task.duration_s = duration;
        let answer = if retimable(&at) {
            retimed(&at, robot, ctl, &explored)?
        } else {
            Some(optimize_with(&at, robot, ctl)?).filter(|a| a.status == Status::Optimal)
        };
        if let Some(answer) = answer {
            return Ok(answer);
        }
        duration = round_up_ms(duration * AUTO_DURATION_STEP);
    }
    Ok(explored)
}

/// Whether the constraints other than the rates are the same at every
/// duration, so that an answer can be retimed (see the module docs): no
/// waypoint placed in seconds and no `samples` asked.
fn retimable(request: &OptimizeRequest) -> bool {
    let task = &request.task;
    task.samples == 0 && task.via_points.iter().all(|v| v.phase.is_some())
}

/// The `optimal` answer `explored` (at a longer duration) taken at
/// `request`'s duration: the same weights, verified there; `None` when they
/// break a limit there. The search's figures (iterations, Clarabel's
/// certificate, the warnings) are the explored answer's; `solve_ms` counts
/// both.
pub fn retimed(
    request: &OptimizeRequest,
    robot: &Robot,
    ctl: &SolveControl,
    explored: &OptimizeResponse,
) -> Result<Option<OptimizeResponse>> {
    if explored.status != Status::Optimal {
        return Ok(None);
    }
    let started = Instant::now();
    let problem = request.validate(robot)?;
    let weights = DVector::from_column_slice(&explored.weights);
    let mut report = problem.verifier().verify(&weights, ctl).report;
    if !problem.is_feasible(&report) {
        return Ok(None);
    }
    let mut warnings = explored.report.warnings.clone();
    warnings.retain(|w| !report.warnings.contains(w));
    report.warnings.append(&mut warnings);
    report.iterations = explored.report.iterations;
    report.final_qp = explored.report.final_qp.clone();
    report.solve_ms = explored.report.solve_ms + started.elapsed().as_secs_f64() * 1e3;
    Ok(Some(OptimizeResponse {
        status: Status::Optimal,
        stop_reason: explored.stop_reason,
        duration_s: request.task.duration_s,
        trajectory: problem.trajectory(&explored.weights),
        mahalanobis: explored.mahalanobis,
        weights: explored.weights.clone(),
        report,
        prior_mean_report: prior_mean_report(&problem, ctl),
        samples: Vec::new(),
        reason: None,
        min_duration_s: None,
        duration_lower_bound_s: None,
        culprit: None,
        promp: explored.promp.clone(),
    }))
}

/// The factor `k` such that the answer's path timed over `k` times its
/// duration has its largest rate ratio at exactly 1: `max(r_v, √r_a,
/// ∛r_j)`.
pub fn time_scale_to_limits(answer: &OptimizeResponse) -> f64 {
    let r = &answer.report;
    let acceleration = r.max_acceleration_ratio.map_or(0.0, f64::sqrt);
    let jerk = r.max_jerk_ratio.map_or(0.0, f64::cbrt);
    r.max_velocity_ratio.max(acceleration).max(jerk)
}

fn round_up_ms(seconds: f64) -> f64 {
    (seconds * 1000.0).ceil() / 1000.0
}
