//! The merit test on one QP step of the SCP ([`StepTrial::search`]): the
//! step as the QP gave it, a second-order correction of it, or a halving,
//! judged on the true merit (real forward kinematics and parry distances).

use crate::optim::problem::phases::PhaseRows;
use crate::optim::problem::Problem;
use crate::optim::scp::evaluate::GridEval;
use crate::optim::solution::{timed, SolveControl, SolveStats};
use nalgebra::DVector;

/// Halvings of a rejected QP step tried before the trust region shrinks
/// (2 cut the SCP iterations on the typical benchmark by 17 % with the
/// same statuses; more traded statuses for iterations).
pub(super) const LINE_SEARCH_HALVINGS: usize = 2;

/// A second-order correction: the corrected step's end (whitened) for a
/// rejected trial point, from the QP with that point's short pairs added.
pub(super) type Correction<'c> = dyn Fn(&GridEval, &mut SolveStats) -> Option<DVector<f64>> + 'c;

/// One QP step to judge: from `eval` towards `target` (whitened).
pub(super) struct StepTrial<'a> {
    pub(super) problem: &'a Problem,
    pub(super) eval: &'a GridEval,
    /// `eval`'s merit at penalty `rho`.
    pub(super) merit: f64,
    pub(super) target: &'a DVector<f64>,
    pub(super) rows: &'a PhaseRows,
    pub(super) centre: &'a DVector<f64>,
    pub(super) rho: f64,
    /// The model's predicted merit decrease for the whole step.
    pub(super) predicted: f64,
    /// The caller's stop: an interrupted trial is never accepted.
    pub(super) ctl: &'a SolveControl,
    /// From a feasible `eval`, accept only a feasible point
    /// ([`Scp::keeping_feasibility`](super::state::Scp::keeping_feasibility)).
    pub(super) keep_feasible: bool,
}

impl StepTrial<'_> {
    /// The step of an SCP iteration, judged on the true merit: the QP's
    /// solution if it achieves at least 10 % of the predicted decrease;
    /// else, with a `correction`, the second-order corrected point judged
    /// against the same prediction (one more QP and evaluation, counted in
    /// [`SolveStats::corrections`]); else up to [`LINE_SEARCH_HALVINGS`]
    /// halvings of the step (each predicted to achieve at least its
    /// fraction of the decrease: the model is convex), which are cheaper
    /// than another QP on a smaller trust region. Returns the accepted
    /// iterate with its predicted and actual decrease, and the step
    /// fraction tried last (1 for the corrected point).
    pub(super) fn search(
        &self,
        correction: Option<&Correction>,
        stats: &mut SolveStats,
    ) -> (Option<(GridEval, f64, f64)>, f64) {
        let StepTrial {
            problem,
            eval,
            merit: merit_here,
            target,
            rows,
            centre,
            rho,
            predicted,
            ctl,
            keep_feasible: _,
        } = *self;
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
                problem.evaluate_grid(rows, z, centre, ctl)
            });
            if next.interrupted {
                return (None, alpha);
            }
            let predicted = alpha * predicted;
            let actual = merit_here - next.merit(rho);
            let gains = !eval.linear_ok || actual >= 0.1 * predicted.max(0.0) - 1e-12 * scale;
            if gains && self.stays_feasible(&next) {
                return (Some((next, predicted, actual)), alpha);
            }
            if attempt > 0 {
                continue;
            }
            let Some(z) = correction.and_then(|correct| correct(&next, stats)) else {
                continue;
            };
            stats.corrections.0 += 1;
            let corrected = timed(&mut stats.evaluation_ms, || {
                problem.evaluate_grid(rows, z, centre, ctl)
            });
            if corrected.interrupted {
                return (None, alpha);
            }
            let actual = merit_here - corrected.merit(rho);
            if actual >= 0.1 * predicted.max(0.0) - 1e-12 * scale && self.stays_feasible(&corrected)
            {
                stats.corrections.1 += 1;
                return (Some((corrected, predicted, actual)), alpha);
            }
        }
        (None, alpha)
    }

    /// Whether moving to `next` is allowed by `keep_feasible` (always,
    /// without it): from a feasible iterate, only onto a feasible one.
    fn stays_feasible(&self, next: &GridEval) -> bool {
        !self.keep_feasible || !self.eval.feasible() || next.feasible()
    }
}
