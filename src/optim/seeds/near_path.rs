//! A restart from the restarts' planned path, made feasible near itself.
//!
//! The restarts' second planned path ([`Problem::path_start`], attempt 1)
//! is collision-free as a polyline, but its fit in the basis is not: the
//! smoothed curve cuts the corners the planner turned around a shelf or a
//! box wall. Run towards the prior mean from there, the SCP trades
//! clearance for Mahalanobis distance from the first step and, on
//! MotionBenchMaker's shelves, boxes and under-table picks, ends in the same
//! local minimum as the mean's run. So this start is made in two steps,
//! like [`super::pinned`]'s:
//!
//! 1. the SCP from the fitted path towards *the path itself* (the path is
//!    the centre of the cost instead of the prior mean), capped at
//!    [`super::restart::RESTART_MAX_ITERATIONS`]: it only has to push the smoothed curve
//!    clear, and the nearest feasible trajectory to a nearly feasible one is
//!    close by;
//! 2. when that run ends `optimal`, its answer (feasible for the problem
//!    itself) is the restart's start, and the restart keeps feasibility
//!    ([`crate::optim::scp::Scp::keeping_feasibility`]) while it moves
//!    towards the prior, for up to the problem's whole iteration limit.
//!
//! When the first run does not end `optimal`, the fitted path is the start
//! as before (capped, not kept feasible).

use crate::optim::problem::Problem;
use crate::optim::seeds::restart::RestartStart;
use crate::optim::solution::SolveControl;
use std::sync::atomic::AtomicBool;

impl Problem {
    /// The restart from the second planned path (see the module docs), when
    /// the planner finds one.
    pub(super) fn near_path_start(&self, ctl: &SolveControl) -> Option<RestartStart> {
        let never = AtomicBool::new(false);
        let path = self.path_start(ctl, &never, 1)?;
        let near = self.run(&path, &path, self.restart_cap(), ctl);
        Some(match self.optimal_start(near) {
            Some(z) => RestartStart::kept_feasible(z, self),
            None => RestartStart::capped(path, self),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::report::Status;
    use crate::optim::scp::Scp;
    use crate::optim::seeds::test_problems::real_problem;
    use nalgebra::DVector;

    /// On a real-prior problem whose mean collides, the second planned
    /// path's run towards itself ends `optimal`: the start is feasible for
    /// the problem by the dense verification against the meshes, and the
    /// restart from it, which keeps feasibility, ends `optimal` and no
    /// farther from the prior than its start. The same start again.
    #[test]
    fn the_near_path_start_is_feasible_and_its_run_ends_optimal() {
        let p = real_problem(NEAR_PATH_PROBLEM);
        let ctl = SolveControl::default();
        let start = p.near_path_start(&ctl).expect("a planned path");
        assert!(start.keep_feasible, "the path's run ended optimal");
        assert_eq!(start.cap, p.options.max_iterations);
        let at_start = p.evaluate(p.whitening.weights(&start.z).as_slice());
        assert!(p.is_feasible(&at_start), "{at_start:?}");
        let zero = DVector::zeros(start.z.len());
        let run = Scp::new(&p, &start.z, &zero, start.cap, &ctl)
            .keeping_feasibility()
            .run()
            .unwrap();
        assert_eq!(run.status, Status::Optimal, "{:?}", run.reason);
        assert!(p.is_feasible(&run.report));
        assert!(run.mahalanobis <= start.z.norm() + 1e-9);
        let again = p.near_path_start(&ctl).expect("a planned path");
        assert_eq!(again.z, start.z, "the same start again");
    }

    const NEAR_PATH_PROBLEM: &str = "real-000.json";
}
