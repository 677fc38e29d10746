//! Why a solve ended, as data: [`StopReason`] (the answer's `stop_reason`)
//! and [`Interruption`] (the caller's deadline or cancel flag). `status`
//! says what the answer is worth; `stop_reason` says why the optimiser
//! stopped where it did, so that a client (or MoveIt's error codes, in
//! [`crate::moveit`]) can tell a deadline from a local minimum without
//! parsing `reason`.

use super::report::Status;
use serde::Serialize;
use std::fmt;

/// Why a solve ended. Each value belongs to one [`Status`]
/// ([`StopReason::status`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// Converged, and the dense verification and continuous certificate
    /// hold (`optimal`).
    Converged,
    /// Proven before any solve that no trajectory meets the request: the
    /// joint-space diagnosis (a start or goal outside the limits or out of
    /// reach, a start in collision, ...) (`infeasible`).
    ProvenInfeasible,
    /// Proven before any solve that `duration_s` is too short for the
    /// velocity, acceleration and jerk limits (`infeasible`).
    DurationTooShort,
    /// The hard linear rows (joint limits, velocity limits, start and final
    /// configuration) of a QP are incompatible (`infeasible`).
    LimitsIncompatible,
    /// `options.max_iterations` reached before converging
    /// (`max_iterations`).
    IterationLimit,
    /// The violation could not be reduced at the largest penalty: a local
    /// minimum, possibly of an infeasible problem (`max_iterations`).
    LocalMinimum,
    /// The request's deadline passed (`max_iterations`).
    Deadline,
    /// The caller cancelled the solve (`max_iterations`).
    Cancelled,
    /// A QP solver failed numerically (`max_iterations`).
    QpNumericalFailure,
    /// The dense verification failed on a constraint the optimiser cannot
    /// refine, e.g. the goal or an equality (`max_iterations`).
    VerificationFailed,
}

impl StopReason {
    /// Every value, in declaration order.
    pub const ALL: [StopReason; 10] = [
        StopReason::Converged,
        StopReason::ProvenInfeasible,
        StopReason::DurationTooShort,
        StopReason::LimitsIncompatible,
        StopReason::IterationLimit,
        StopReason::LocalMinimum,
        StopReason::Deadline,
        StopReason::Cancelled,
        StopReason::QpNumericalFailure,
        StopReason::VerificationFailed,
    ];

    /// The status an answer that stopped for this reason has.
    pub fn status(self) -> Status {
        match self {
            StopReason::Converged => Status::Optimal,
            StopReason::ProvenInfeasible
            | StopReason::DurationTooShort
            | StopReason::LimitsIncompatible => Status::Infeasible,
            StopReason::IterationLimit
            | StopReason::LocalMinimum
            | StopReason::Deadline
            | StopReason::Cancelled
            | StopReason::QpNumericalFailure
            | StopReason::VerificationFailed => Status::MaxIterations,
        }
    }

    /// The name as the JSON writes it (`converged`, `deadline`, ...).
    pub fn as_str(self) -> &'static str {
        match self {
            StopReason::Converged => "converged",
            StopReason::ProvenInfeasible => "proven_infeasible",
            StopReason::DurationTooShort => "duration_too_short",
            StopReason::LimitsIncompatible => "limits_incompatible",
            StopReason::IterationLimit => "iteration_limit",
            StopReason::LocalMinimum => "local_minimum",
            StopReason::Deadline => "deadline",
            StopReason::Cancelled => "cancelled",
            StopReason::QpNumericalFailure => "qp_numerical_failure",
            StopReason::VerificationFailed => "verification_failed",
        }
    }
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why the caller stopped a running solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interruption {
    /// The cancel flag was set.
    Cancelled,
    /// The deadline passed.
    Deadline,
}

impl Interruption {
    /// The answer's [`StopReason`] for this interruption.
    pub fn stop_reason(self) -> StopReason {
        match self {
            Interruption::Cancelled => StopReason::Cancelled,
            Interruption::Deadline => StopReason::Deadline,
        }
    }
}

impl fmt::Display for Interruption {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Interruption::Cancelled => "cancelled by the caller",
            Interruption::Deadline => "deadline reached",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stop_reason_names_are_the_json_names_and_only_converged_is_optimal() {
        for s in StopReason::ALL {
            assert_eq!(serde_json::to_value(s).unwrap(), s.as_str());
            assert_eq!(
                s.status() == Status::Optimal,
                s == StopReason::Converged,
                "{s}"
            );
        }
        let names: std::collections::BTreeSet<_> =
            StopReason::ALL.iter().map(|s| s.as_str()).collect();
        assert_eq!(names.len(), StopReason::ALL.len());
    }

    #[test]
    fn an_interruption_stops_a_solve_as_max_iterations() {
        for i in [Interruption::Cancelled, Interruption::Deadline] {
            assert_eq!(i.stop_reason().status(), Status::MaxIterations);
        }
    }
}
