//! Sequential convex programming towards a centre in whitened coordinates
//! (the prior mean for [`Problem::solve`], a draw for [`Problem::project`]).
//!
//! Each iteration linearises every clearance pair within the activation
//! distance (at every optimisation phase) and the goal at the current
//! iterate, and solves one QP with Clarabel: hard limit rows, L1-slacked
//! clearance rows and goal cone, and a trust-region ball `|z - z_k| ≤ Δ`.
//! The QP is solved on a small [`working_set`](crate::optim::scp::working_set): the
//! rows active in the previous QP, thinned limit rows a step can reach, and
//! thinned clearance rows near the target. Limit rows the solution breaks
//! are always generated until none is left; clearance rows get
//! [`WORKING_SET_ROUNDS`] round(s), so that an iterate deep in collision
//! (hundreds of violated rows) still costs a small QP; the model the step
//! is judged against is then the working set's. A step is accepted when the
//! true merit `|z - c|² + ρ·violation` (real FK and parry distances, every
//! pair at every phase) improves by at least 10 % of the model's
//! prediction; otherwise a second-order correction is tried (the QP again
//! with the rejected point's short pairs linearised where they were
//! measured: a step along curved clearance rows breaks them by its square),
//! then up to two halvings of the step (an evaluation is much cheaper than
//! a QP) before the trust region shrinks.
//! When the iteration stalls short of feasibility, generation becomes exact
//! (every violated clearance row joins the QP), and only a stall on that
//! full model raises the penalty (each switch resets the trust region to at
//! least its initial radius: the model changed, and a radius shrunk while
//! stalling would cost one QP per doubling to grow back), up to a cap,
//! after which the solve stops as `max_iterations` naming the worst
//! constraint (`infeasible` is reserved for proofs: [`Problem::diagnose`]'s
//! certificates and a QP whose hard limit rows Clarabel proves
//! incompatible). A converged feasible iterate is verified densely; flagged
//! phases join the optimisation set and the loop goes on. Where the
//! verification found the trajectory inside the clearance (at a dense
//! sample, or by the continuous certificate between two), the flagged
//! phases' clearance rows also aim that much farther out (at most
//! [`MAX_MARGIN_STEP_M`](crate::optim::tolerances::MAX_MARGIN_STEP_M) more
//! per round), up to
//! [`MAX_CLEARANCE_MARGIN_M`](crate::optim::tolerances::MAX_CLEARANCE_MARGIN_M)
//! ([`PhaseRows::margin`](crate::optim::problem::phases::PhaseRows::margin)):
//! a trajectory that slides along an obstacle dips between whatever phases
//! hold it, so holding it only at the new phases moved the dip along, one
//! verification round after another.

mod evaluate;
mod line_search;
mod state;
mod subproblem;
pub mod working_set;

use crate::optim::problem::Problem;
pub(in crate::optim) use crate::optim::scp::state::{Progress, Scp};
pub use crate::optim::solution::{Solution, SolveControl, SolveStats};
use crate::Result;
use nalgebra::DVector;

impl Problem {
    /// SCP towards the prior mean (the Mahalanobis-closest feasible weights).
    /// When the mean is blocked and the start and end are fixed (the end
    /// as a configuration or a goal position), a run from a collision-free
    /// path races it from the start (see
    /// [`global`](crate::optim::seeds::global)); when that first stage ends
    /// without a feasible answer, it is restarted from detours around the
    /// blocking obstacles and seeded prior draws (see
    /// [`restart`](crate::optim::seeds::restart)).
    pub fn solve(&self, ctl: &SolveControl) -> Result<Solution> {
        let first = self.first_run(ctl)?;
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
    pub(in crate::optim) fn run(
        &self,
        start: &DVector<f64>,
        centre: &DVector<f64>,
        max_iterations: usize,
        ctl: &SolveControl,
    ) -> Result<Solution> {
        Scp::new(self, start, centre, max_iterations, ctl).run()
    }
}
