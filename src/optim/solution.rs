//! What a solve returns and how a caller controls it: [`Solution`],
//! [`SolveStats`] (the counters benchmarks and the CLI print) and
//! [`SolveControl`] (deadline, cancel flag, and whether the solve may use
//! more than one core). Plain types: the SCP driver (`scp`, `scp::state`)
//! fills them.

use super::qp::{QpFailure, QpSolution};
use super::report::{Status, TrajectoryReport};
use super::stop_reason::{Interruption, StopReason};
use crate::Error;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// How a caller stops a running solve, and whether it may spread over the
/// machine's cores.
#[derive(Clone, Debug, Default)]
pub struct SolveControl {
    /// Stop (status `max_iterations`, with a warning) after this instant.
    pub deadline: Option<Instant>,
    /// Stop when this becomes true.
    pub cancel: Option<Arc<AtomicBool>>,
    /// The solves sharing the machine (`None`: this one has it to itself).
    pub sharing: Option<Sharing>,
}

/// A count of the solves running at once on `cores` cores, e.g. a
/// service's jobs. While every core has a solve of its own, each solve runs
/// its loops (phases, dense samples, restarts) on its own thread: rayon's
/// hand-offs and idle spinning then only cost CPU time that another solve
/// could use (measured: 10-15 % of a typical solve's CPU time). The answer
/// is the same either way: every parallel loop keeps its order.
#[derive(Clone, Debug)]
pub struct Sharing {
    /// Solves running now, this one included.
    pub running: Arc<AtomicUsize>,
    /// Cores the solves share.
    pub cores: usize,
}

impl SolveControl {
    /// Whether the solve's loops may run on several threads: no
    /// [`Sharing`], or fewer solves running than cores.
    pub fn parallel(&self) -> bool {
        self.sharing
            .as_ref()
            .is_none_or(|s| s.running.load(Ordering::Relaxed) < s.cores)
    }

    /// Why the solve must stop now, if it must.
    pub fn stop_reason(&self) -> Option<Interruption> {
        if self
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
        {
            return Some(Interruption::Cancelled);
        }
        if self.deadline.is_some_and(|d| Instant::now() >= d) {
            return Some(Interruption::Deadline);
        }
        None
    }

    /// Whether the solve must stop now (cheap: one atomic load and, with a
    /// deadline, one clock read; checked once per phase in the long loops).
    pub fn should_stop(&self) -> bool {
        self.stop_reason().is_some()
    }

    pub(super) fn seconds_left(&self) -> Option<f64> {
        self.deadline
            .map(|d| d.saturating_duration_since(Instant::now()).as_secs_f64())
    }
}

/// Counters of one solve (for benchmarks and the CLI).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SolveStats {
    /// SCP iterations (QP subproblems).
    pub iterations: usize,
    /// Clarabel solves (a subproblem takes one per generation round).
    pub qp_solves: usize,
    /// Clarabel interior-point iterations over all solves.
    pub ipm_iterations: usize,
    /// QPs solved by the dual active-set method (the rest by Clarabel).
    pub active_set_solves: usize,
    /// Multiplier steps of the dual active-set method over all its solves.
    pub active_set_steps: usize,
    /// Steps rejected by the merit test.
    pub rejected_steps: usize,
    /// Second-order corrections tried after a full step failed the merit
    /// test, and how many of them were accepted.
    pub corrections: (usize, usize),
    /// Largest QP: rows of the constraint matrix.
    pub max_qp_rows: usize,
    /// Largest QP: variables.
    pub max_qp_variables: usize,
    /// Phases added by dense verification.
    pub added_phases: usize,
    /// Converged iterates verified densely before certification (after a
    /// dip between the phases), and how many of those answered with the
    /// screen's own verification (certification left the point in place).
    pub screens: (usize, usize),
    /// Final L1 penalty.
    pub final_penalty: f64,
    /// Wall time building and solving QPs (ms).
    pub qp_ms: f64,
    /// Of [`SolveStats::qp_ms`], the wall time in Clarabel's solves (the
    /// certifying QPs, and any infeasibility the active-set method reports).
    pub clarabel_ms: f64,
    /// Wall time evaluating iterates on the optimisation phases (ms).
    pub evaluation_ms: f64,
    /// Wall time in dense verification (ms).
    pub verification_ms: f64,
    /// Restarts (detours and prior draws) that ran (see [`restart`](super::seeds::restart)).
    pub restarts: usize,
}

impl SolveStats {
    /// Count one Clarabel solve.
    pub(super) fn count(&mut self, sol: &QpSolution) {
        self.qp_solves += 1;
        self.ipm_iterations += sol.ipm_iterations as usize;
        if sol.clarabel.is_none() {
            self.active_set_solves += 1;
            self.active_set_steps += sol.active_set_steps;
        }
        self.max_qp_rows = self.max_qp_rows.max(sol.rows);
        self.max_qp_variables = self.max_qp_variables.max(sol.variables);
    }

    /// Add the counters of a later run of the same solve (a restart).
    pub(super) fn absorb(&mut self, later: &SolveStats) {
        self.iterations += later.iterations;
        self.qp_solves += later.qp_solves;
        self.ipm_iterations += later.ipm_iterations;
        self.active_set_solves += later.active_set_solves;
        self.active_set_steps += later.active_set_steps;
        self.rejected_steps += later.rejected_steps;
        self.corrections.0 += later.corrections.0;
        self.corrections.1 += later.corrections.1;
        self.max_qp_rows = self.max_qp_rows.max(later.max_qp_rows);
        self.max_qp_variables = self.max_qp_variables.max(later.max_qp_variables);
        self.added_phases += later.added_phases;
        self.screens.0 += later.screens.0;
        self.screens.1 += later.screens.1;
        self.final_penalty = later.final_penalty;
        self.qp_ms += later.qp_ms;
        self.clarabel_ms += later.clarabel_ms;
        self.evaluation_ms += later.evaluation_ms;
        self.verification_ms += later.verification_ms;
        self.restarts += later.restarts;
    }
}

/// Run `f`, adding its wall time in milliseconds to `acc`.
pub(in crate::optim) fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    *acc += t.elapsed().as_secs_f64() * 1e3;
    out
}

/// The result of [`Problem::solve`] / [`Problem::project`].
#[derive(Clone, Debug)]
pub struct Solution {
    /// Outcome.
    pub status: Status,
    /// Weights (joint-major).
    pub weights: Vec<f64>,
    /// Mahalanobis distance of the weights to the prior.
    pub mahalanobis: f64,
    /// Dense verification of the weights.
    pub report: TrajectoryReport,
    /// Why the status is not `optimal`.
    pub reason: Option<String>,
    /// Why the solve ended (its status is `stop_reason.status()`).
    pub stop_reason: StopReason,
    /// Counters.
    pub stats: SolveStats,
}

impl From<QpFailure> for Error {
    fn from(f: QpFailure) -> Error {
        f.into_error()
    }
}
