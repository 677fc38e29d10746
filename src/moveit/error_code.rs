//! `moveit_msgs/MoveItErrorCodes`: the answer's outcome in MoveIt's
//! vocabulary, mapped from the optimiser's [`StopReason`] and, for a
//! request proven infeasible, the part the diagnosis blamed
//! ([`Culprit`]).

use crate::optim::report::Culprit;
use crate::optim::{OptimizeResponse, StopReason};
use serde::Serialize;

/// The MoveIt error codes dPMP answers with (values of
/// `moveit_msgs/msg/MoveItErrorCodes`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MoveItErrorCode {
    /// A certified (`optimal`) trajectory.
    Success,
    /// No certified trajectory found (a local minimum, the iteration
    /// limit, a numerical failure, a proof other than the ones below).
    PlanningFailed,
    /// The request's deadline (`allowed_planning_time`) passed.
    TimedOut,
    /// The caller cancelled.
    Preempted,
    /// The start is closer to an obstacle than the clearance asked.
    StartStateInCollision,
    /// The goal is closer to an obstacle than the clearance asked.
    GoalInCollision,
    /// The goal is outside the joint limits.
    InvalidGoalConstraints,
    /// The start is outside the joint limits.
    StartStateInvalid,
    /// No configuration reaches the goal position.
    NoIkSolution,
}

impl MoveItErrorCode {
    /// Every code, in declaration order.
    pub const ALL: [MoveItErrorCode; 9] = [
        MoveItErrorCode::Success,
        MoveItErrorCode::PlanningFailed,
        MoveItErrorCode::TimedOut,
        MoveItErrorCode::Preempted,
        MoveItErrorCode::StartStateInCollision,
        MoveItErrorCode::GoalInCollision,
        MoveItErrorCode::InvalidGoalConstraints,
        MoveItErrorCode::StartStateInvalid,
        MoveItErrorCode::NoIkSolution,
    ];

    /// The message's `val`.
    pub fn val(self) -> i32 {
        match self {
            MoveItErrorCode::Success => 1,
            MoveItErrorCode::PlanningFailed => -1,
            MoveItErrorCode::TimedOut => -6,
            MoveItErrorCode::Preempted => -7,
            MoveItErrorCode::StartStateInCollision => -10,
            MoveItErrorCode::GoalInCollision => -12,
            MoveItErrorCode::InvalidGoalConstraints => -16,
            MoveItErrorCode::StartStateInvalid => -26,
            MoveItErrorCode::NoIkSolution => -31,
        }
    }

    /// The constant's name in the message definition.
    pub fn name(self) -> &'static str {
        match self {
            MoveItErrorCode::Success => "SUCCESS",
            MoveItErrorCode::PlanningFailed => "PLANNING_FAILED",
            MoveItErrorCode::TimedOut => "TIMED_OUT",
            MoveItErrorCode::Preempted => "PREEMPTED",
            MoveItErrorCode::StartStateInCollision => "START_STATE_IN_COLLISION",
            MoveItErrorCode::GoalInCollision => "GOAL_IN_COLLISION",
            MoveItErrorCode::InvalidGoalConstraints => "INVALID_GOAL_CONSTRAINTS",
            MoveItErrorCode::StartStateInvalid => "START_STATE_INVALID",
            MoveItErrorCode::NoIkSolution => "NO_IK_SOLUTION",
        }
    }

    /// The code of an optimiser answer.
    pub fn of(answer: &OptimizeResponse) -> MoveItErrorCode {
        match answer.stop_reason {
            StopReason::Converged => MoveItErrorCode::Success,
            StopReason::Deadline => MoveItErrorCode::TimedOut,
            StopReason::Cancelled => MoveItErrorCode::Preempted,
            StopReason::ProvenInfeasible => match answer.culprit {
                Some(Culprit::StartInCollision) => MoveItErrorCode::StartStateInCollision,
                Some(Culprit::StartOutsideLimits) => MoveItErrorCode::StartStateInvalid,
                Some(Culprit::GoalInCollision) => MoveItErrorCode::GoalInCollision,
                Some(Culprit::GoalOutsideLimits) => MoveItErrorCode::InvalidGoalConstraints,
                Some(Culprit::GoalUnreachable) => MoveItErrorCode::NoIkSolution,
                Some(Culprit::ViaPointOutsideLimits) | None => MoveItErrorCode::PlanningFailed,
            },
            StopReason::DurationTooShort
            | StopReason::LimitsIncompatible
            | StopReason::IterationLimit
            | StopReason::LocalMinimum
            | StopReason::QpNumericalFailure
            | StopReason::VerificationFailed => MoveItErrorCode::PlanningFailed,
        }
    }
}

/// `moveit_msgs/MoveItErrorCodes` as ROS 2 serialises it (`{"val": 1}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct ErrorCodeMsg {
    /// The code.
    pub val: i32,
}

impl From<MoveItErrorCode> for ErrorCodeMsg {
    fn from(code: MoveItErrorCode) -> Self {
        ErrorCodeMsg { val: code.val() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_moveits_and_distinct() {
        let vals: std::collections::BTreeSet<i32> =
            MoveItErrorCode::ALL.iter().map(|c| c.val()).collect();
        assert_eq!(vals.len(), MoveItErrorCode::ALL.len());
        assert_eq!(MoveItErrorCode::Success.val(), 1);
        assert_eq!(MoveItErrorCode::GoalInCollision.val(), -12);
        assert_eq!(MoveItErrorCode::InvalidGoalConstraints.val(), -16);
        for c in MoveItErrorCode::ALL {
            assert!(c
                .name()
                .chars()
                .all(|ch| ch.is_ascii_uppercase() || ch == '_'));
        }
    }
}
