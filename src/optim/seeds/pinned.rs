//! A restart from a feasible trajectory that ends clear of the obstacles in
//! the goal region.
//!
//! With a goal position the final configuration is free, and on the real
//! priors (`bench::hard_set::real`) the prior's final poses hold the hand
//! against a berry beside the goal: the runs from the mean, the planned
//! path, the detours and the draws all end in a local minimum with the TCP
//! 1-3 cm short of the goal, because every step towards the goal pushes the
//! hand into the berry and the clearance rows push it back. A clear
//! configuration of the goal region exists ([`super::goal_pose`]); what
//! the SCP lacks is a trajectory that already ends there. So this start is
//! made in two steps:
//!
//! 1. the problem with that configuration *pinned* as the final one (an
//!    equality, as `options.final_configuration` is), solved from the prior
//!    conditioned on it ([`super::condition`]); the end no longer slides
//!    into the berry, and the run ends `optimal` within a few dozen
//!    iterations;
//! 2. that answer, feasible for the problem itself, is the restart's start.
//!    A run from a feasible iterate never accepts an infeasible step (the
//!    SCP's line search), so it moves the end within the goal region towards
//!    the prior and stays clear; it may crawl along the clearance for longer
//!    than a restart from a draw, so it may take the problem's whole
//!    iteration limit.

use crate::optim::problem::Problem;
use crate::optim::solution::SolveControl;
use nalgebra::DVector;

impl Problem {
    /// The whitened weights of the pinned problem's `optimal` answer (see
    /// the module docs), when the end is a goal position (not a final
    /// configuration), a clear configuration of the goal region is found,
    /// and the pinned run ends `optimal`.
    pub(super) fn pinned_goal_start(&self, ctl: &SolveControl) -> Option<DVector<f64>> {
        if self.linear.final_configuration.is_some() || self.goal.is_none() {
            return None;
        }
        let goal = self.planner_goal(0, &|| ctl.should_stop())?;
        let start = self.goal_conditioned_start(&goal)?;
        let mut pinned = self.clone();
        pinned.linear.final_configuration = Some(goal);
        let zero = DVector::zeros(start.len());
        self.optimal_start(pinned.run(&start, &zero, self.restart_cap(), ctl))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::report::Status;
    use crate::optim::scp::Scp;
    use crate::optim::seeds::test_problems::real_problem;

    /// On a real-prior problem whose first stage ends in a local minimum
    /// with the hand against a berry, the pinned goal start is feasible for
    /// the problem itself by the dense verification against the meshes
    /// (goal within its tolerance), and the run from it that keeps
    /// feasibility ends `optimal` closer to the prior than its start.
    #[test]
    fn the_pinned_start_is_feasible_and_its_run_ends_optimal_closer_to_the_prior() {
        let p = real_problem("real-067.json");
        let ctl = SolveControl::default();
        let z = p.pinned_goal_start(&ctl).expect("a pinned goal start");
        let start = p.evaluate(p.whitening.weights(&z).as_slice());
        assert!(p.is_feasible(&start), "{start:?}");
        let goal_error = start.goal_error_m.expect("a goal");
        assert!(
            goal_error <= p.goal.as_ref().unwrap().tolerance_m,
            "{goal_error}"
        );
        let zero = DVector::zeros(z.len());
        let run = Scp::new(&p, &z, &zero, p.options.max_iterations, &ctl)
            .keeping_feasibility()
            .run()
            .unwrap();
        assert_eq!(run.status, Status::Optimal, "{:?}", run.reason);
        assert!(p.is_feasible(&run.report));
        assert!(
            run.mahalanobis < z.norm() - 1.0,
            "{} vs {}",
            run.mahalanobis,
            z.norm()
        );
        assert_eq!(p.pinned_goal_start(&ctl), Some(z), "the same start again");
    }
}
