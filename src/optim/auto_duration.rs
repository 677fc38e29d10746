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
//! 3. solves there (rounded up to the millisecond) and, when that is not
//!    `optimal`, at durations [`AUTO_DURATION_STEP`] longer each time,
//!    until one is or the exploring duration is reached.
//!
//! The answer is the first `optimal` one; its `duration_s` says which
//! duration it used. A duration [`AUTO_DURATION_STEP`] shorter breaks a
//! rate limit on the answer's path (the tests check it by time scaling).
//! When the exploring solve is not `optimal` its answer is returned: a
//! longer duration would not move a path the rate limits do not bind.
//! The caller's deadline bounds every solve.

use super::request::OptimizeRequest;
use super::{optimize_with, OptimizeResponse, SolveControl, Status};
use crate::robot::Robot;
use crate::Result;

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
    let mut duration = round_up_ms(explore * time_scale_to_limits(&explored).max(1e-3));
    while duration * AUTO_DURATION_STEP < explore && !ctl.should_stop() {
        at.task.duration_s = duration;
        let answer = optimize_with(&at, robot, ctl)?;
        if answer.status == Status::Optimal {
            return Ok(answer);
        }
        duration = round_up_ms(duration * AUTO_DURATION_STEP);
    }
    Ok(explored)
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
