//! Sequential convex programming towards a centre in whitened coordinates
//! (the prior mean for [`Problem::solve`], a draw for [`Problem::project`]).
//!
//! Each iteration linearises every clearance pair within the activation
//! distance (at every optimisation phase) and the goal at the current
//! iterate, and solves one QP with Clarabel: hard limit rows, L1-slacked
//! clearance rows and goal cone, and a trust-region ball `|z - z_k| ≤ Δ`.
//! The QP is solved on a small [`working_set`](super::working_set): the
//! rows active in the previous QP, thinned limit rows a step can reach, and
//! thinned clearance rows near the target. Limit rows the solution breaks
//! are always generated until none is left; clearance rows get
//! [`WORKING_SET_ROUNDS`] round(s), so that an iterate deep in collision
//! (hundreds of violated rows) still costs a small QP; the model the step
//! is judged against is then the working set's. A step is accepted when the
//! true merit `|z - c|² + ρ·violation` (real FK and parry distances, every
//! pair at every phase) improves by at least 10 % of the model's
//! prediction; otherwise up to two halvings of the step are tried (an
//! evaluation is much cheaper than a QP) before the trust region shrinks.
//! When the iteration stalls short of feasibility, generation becomes exact
//! (every violated clearance row joins the QP), and only a stall on that
//! full model raises the penalty (each switch resets the trust region to at
//! least its initial radius: the model changed, and a radius shrunk while
//! stalling would cost one QP per doubling to grow back), up to a cap,
//! after which the solve stops as `max_iterations` naming the worst
//! constraint (`infeasible` is reserved for proofs: [`Problem::diagnose`]'s
//! certificates and a QP whose hard limit rows Clarabel proves
//! incompatible). A converged feasible iterate is verified densely; flagged
//! phases join the optimisation set and the loop goes on.

use super::evaluate::GridEval;
use super::phases::PhaseRows;
use super::problem::Problem;
use super::qp::{QpFailure, QpSolution};
use super::report::{Status, TrajectoryReport};
use super::scp_state::Scp;
use super::tolerances::CLEARANCE_BUFFER_M;
use super::verify::Verification;
use crate::{Error, Result};
use nalgebra::DVector;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Goal tolerance the QP aims for: `tolerance_m` less a buffer of
/// [`CLEARANCE_BUFFER_M`] (at most half the tolerance), for the same reason.
pub(super) fn buffered_tolerance(tolerance_m: f64) -> f64 {
    tolerance_m - CLEARANCE_BUFFER_M.min(0.5 * tolerance_m)
}
/// Most phases added per dense verification round.
const MAX_ADDED_PER_ROUND: usize = 64;

/// Halvings of a rejected QP step tried before the trust region shrinks
/// (2 cut the SCP iterations on the typical benchmark by 17 % with the
/// same statuses; more traded statuses for iterations).
const LINE_SEARCH_HALVINGS: usize = 2;

/// One QP step to judge: from `eval` towards `target` (whitened).
pub(super) struct StepTrial<'a> {
    pub(super) eval: &'a GridEval,
    /// `eval`'s merit at penalty `rho`.
    pub(super) merit: f64,
    pub(super) target: &'a DVector<f64>,
    pub(super) rows: &'a PhaseRows,
    pub(super) centre: &'a DVector<f64>,
    pub(super) rho: f64,
    /// The model's predicted merit decrease for the whole step.
    pub(super) predicted: f64,
}

/// How a caller stops a running solve.
#[derive(Clone, Debug, Default)]
pub struct SolveControl {
    /// Stop (status `max_iterations`, with a warning) after this instant.
    pub deadline: Option<Instant>,
    /// Stop when this becomes true.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl SolveControl {
    /// Why the solve must stop now, if it must.
    pub fn stop_reason(&self) -> Option<&'static str> {
        if self
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
        {
            return Some("cancelled by the caller");
        }
        if self.deadline.is_some_and(|d| Instant::now() >= d) {
            return Some("deadline reached");
        }
        None
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
    /// Largest QP: rows of the constraint matrix.
    pub max_qp_rows: usize,
    /// Largest QP: variables.
    pub max_qp_variables: usize,
    /// Phases added by dense verification.
    pub added_phases: usize,
    /// Final L1 penalty.
    pub final_penalty: f64,
    /// Wall time building and solving QPs (ms).
    pub qp_ms: f64,
    /// Wall time evaluating iterates on the optimisation phases (ms).
    pub evaluation_ms: f64,
    /// Wall time in dense verification (ms).
    pub verification_ms: f64,
    /// Restarts from prior draws that ran (see [`restart`](super::restart)).
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
        self.max_qp_rows = self.max_qp_rows.max(later.max_qp_rows);
        self.max_qp_variables = self.max_qp_variables.max(later.max_qp_variables);
        self.added_phases += later.added_phases;
        self.final_penalty = later.final_penalty;
        self.qp_ms += later.qp_ms;
        self.evaluation_ms += later.evaluation_ms;
        self.verification_ms += later.verification_ms;
        self.restarts += later.restarts;
    }
}

/// Run `f`, adding its wall time in milliseconds to `acc`.
pub(super) fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
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
    /// Counters.
    pub stats: SolveStats,
}

impl Problem {
    /// SCP towards the prior mean (the Mahalanobis-closest feasible weights).
    /// When that run ends without a feasible answer, it is restarted from
    /// seeded prior draws (see [`restart`](super::restart)).
    pub fn solve(&self, ctl: &SolveControl) -> Result<Solution> {
        let zero = DVector::zeros(self.whitening.dim());
        let first = self.run(&zero, &zero, self.options.max_iterations, ctl)?;
        self.restart_if_stuck(first, ctl)
    }

    /// Mahalanobis-closest feasible weights to `target` (under `Σ + λI`).
    pub fn project(&self, target: &[f64], ctl: &SolveControl) -> Result<Solution> {
        crate::error::ensure_len("target", target, self.prior.dim())?;
        crate::error::ensure_finite("target", target)?;
        let centre = self.whitening.whiten(&DVector::from_column_slice(target));
        self.run(&centre, &centre, self.options.max_iterations, ctl)
    }

    /// One SCP run from `start` towards `centre`, of at most
    /// `max_iterations` QP iterations.
    pub(super) fn run(
        &self,
        start: &DVector<f64>,
        centre: &DVector<f64>,
        max_iterations: usize,
        ctl: &SolveControl,
    ) -> Result<Solution> {
        Scp::new(self, start, centre, max_iterations, ctl).run()
    }

    /// The step of an SCP iteration, judged on the true merit: the QP's
    /// solution if it achieves at least 10 % of the predicted decrease, else
    /// up to [`LINE_SEARCH_HALVINGS`] halvings of it (each predicted to
    /// achieve at least its fraction of the decrease: the model is convex),
    /// which are cheaper than another QP on a smaller trust region. Returns
    /// the accepted iterate with its predicted and actual decrease, and the
    /// step fraction tried last.
    pub(super) fn line_search(
        &self,
        trial: &StepTrial,
        stats: &mut SolveStats,
    ) -> (Option<(GridEval, f64, f64)>, f64) {
        let StepTrial {
            eval,
            merit: merit_here,
            target,
            rows,
            centre,
            rho,
            predicted,
        } = *trial;
        let scale = 1.0 + merit_here.abs();
        // Halving keeps the hard (linear) rows only from a point satisfying them.
        let halvings = if eval.linear_ok {
            LINE_SEARCH_HALVINGS
        } else {
            0
        };
        let mut alpha = 1.0;
        for attempt in 0..=halvings {
            let z = if attempt == 0 {
                target.clone()
            } else {
                alpha *= 0.5;
                &eval.z + (target - &eval.z) * alpha
            };
            let next = timed(&mut stats.evaluation_ms, || {
                self.evaluate_grid(rows, z, centre)
            });
            let predicted = alpha * predicted;
            let actual = merit_here - next.merit(rho);
            if !eval.linear_ok || actual >= 0.1 * predicted.max(0.0) - 1e-12 * scale {
                return (Some((next, predicted, actual)), alpha);
            }
        }
        (None, alpha)
    }

    /// Add (a spread-out subset of) the phases dense verification flagged.
    pub(super) fn add_flagged(&self, rows: &mut PhaseRows, v: &Verification) -> usize {
        let before = rows.len();
        let stride = v.flagged.len().div_ceil(MAX_ADDED_PER_ROUND).max(1);
        for &p in v.flagged.iter().step_by(stride) {
            rows.push(&self.basis, &self.whitening, p);
        }
        rows.len() - before
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn finish(
        &self,
        status: Status,
        eval: &GridEval,
        verification: Option<Verification>,
        reason: Option<String>,
        stats: SolveStats,
        started: Instant,
        extra_warnings: &[String],
    ) -> Solution {
        let v = verification.unwrap_or_else(|| self.verify(&eval.w));
        let mut report = v.report;
        report.iterations = stats.iterations;
        report.warnings = self.warnings.clone();
        report.warnings.extend(extra_warnings.iter().cloned());
        if stats.added_phases > 0 {
            report.warnings.push(format!(
                "dense verification added {} phases to the optimisation set",
                stats.added_phases
            ));
        }
        report.solve_ms = started.elapsed().as_secs_f64() * 1e3;
        Solution {
            status,
            weights: eval.w.as_slice().to_vec(),
            mahalanobis: self.whitening.mahalanobis(&eval.w),
            report,
            reason,
            stats,
        }
    }
}

impl From<QpFailure> for Error {
    fn from(f: QpFailure) -> Error {
        f.into_error()
    }
}
