//! Restarts of the SCP from seeded prior draws when the run from the prior
//! mean ends without a feasible solution.
//!
//! Clearance makes the problem non-convex. The run from the prior mean
//! decides early on which side of each obstacle the trajectory passes, and
//! when it picks a side that leads nowhere it ends in a local minimum of the
//! violation (`max_iterations`: the penalty reached its cap, or the
//! iteration limit). On the typical problems (`fixtures::typical`) most such
//! problems are feasible: a run started elsewhere finds a feasible answer.
//! So [`Problem::solve`] restarts `options.restarts` times, still
//! minimising the distance to the prior mean: first from detours around the
//! obstacles that block the mean (the prior conditioned to pass each on its
//! near or far side, [`super::detour`]), then from draws `z ~ N(0, I)` of
//! the whitened prior (seeded by `options.seed`) to make up the number. The restarts run in
//! parallel and the answer is the closest `optimal` one (lowest cost, ties
//! to the lower index), so it is the same whatever the thread count and
//! whichever run finishes first. That answer is a local optimum found from
//! a draw: a warning says so.
//!
//! A restart may take at most [`RESTART_MAX_ITERATIONS`] iterations (the
//! successful restarts on the typical problems mostly need 7-35), so that a
//! problem with no feasible answer costs a bounded multiple of one run.
//! Nothing restarts after a proof of infeasibility, after an `optimal`
//! answer, or once the deadline or the cancel flag has stopped the solve.
//! A stop during the restarts still answers with the closest restart that
//! had already verified `optimal`, if any (the best verified trajectory
//! found within the budget), else with the first run's iterate.

use crate::optim::problem::Problem;
use crate::optim::report::Status;
use crate::optim::solution::{Solution, SolveControl, SolveStats};
use crate::Result;
use nalgebra::DVector;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

pub use crate::optim::task::MAX_RESTARTS;
/// Iteration limit of one restart (less when `options.max_iterations` is).
pub const RESTART_MAX_ITERATIONS: usize = 40;
/// Mixed into `options.seed` so that the restart draws are not the
/// `samples` draws.
const RESTART_STREAM: u64 = 0x7e57_a275;

impl Problem {
    /// `first` (the run from the prior mean) when it is `optimal`,
    /// `infeasible`, stopped by the caller or restarts are off; otherwise
    /// the best `optimal` restart, or `first` with every run's counters
    /// when none is.
    ///
    /// The restarts run in parallel (rayon), and the answer does not depend
    /// on which finishes first: every draw is fixed up front by the seed,
    /// every restart runs to its own end, and the pick is the lowest cost
    /// among the `optimal` runs, ties to the lower restart index.
    pub(in crate::optim) fn restart_if_stuck(
        &self,
        first: Solution,
        ctl: &SolveControl,
    ) -> Result<Solution> {
        let restarts = self.options.restarts;
        if first.status != Status::MaxIterations || restarts == 0 || ctl.stop_reason().is_some() {
            return Ok(first);
        }
        let starts = self.restart_starts(restarts, ctl);
        let mean = DVector::zeros(self.whitening.dim());
        let cap = self.options.max_iterations.min(RESTART_MAX_ITERATIONS);
        let began = std::time::Instant::now();
        let runs: Vec<Solution> = starts
            .par_iter()
            .map(|start| self.run(start, &mean, cap, ctl))
            .collect::<Result<_>>()?;
        let mut spent = Spent::from(&first);
        spent.solve_ms += began.elapsed().as_secs_f64() * 1e3;
        for run in &runs {
            spent.add(run);
        }
        let stopped = ctl.stop_reason();
        let best = runs
            .into_iter()
            .enumerate()
            .filter(|(_, r)| r.status == Status::Optimal)
            .min_by(|(i, a), (j, b)| a.mahalanobis.total_cmp(&b.mahalanobis).then(i.cmp(j)));
        match (best, stopped) {
            (Some((k, sol)), _) => {
                let mut note = format!(
                    "the run from the prior mean found no feasible solution ({}); of {restarts} restarts (detours around the blocking obstacles, then seeded prior draws), restart {} found the closest feasible one: a local optimum, a feasible solution closer to the prior may exist",
                    first.reason.as_deref().unwrap_or("no reason given"),
                    k + 1
                );
                if let Some(why) = stopped {
                    note.push_str(&format!(" (the other restarts were stopped: {why})"));
                }
                Ok(spent.onto(sol, note))
            }
            (None, Some(why)) => Ok(spent.onto(first, format!("restarts stopped: {why}"))),
            (None, None) => {
                let note = format!(
                    "{restarts} restarts (detours around the blocking obstacles, then seeded prior draws) found no feasible solution either"
                );
                Ok(spent.onto(first, note))
            }
        }
    }

    /// The `n` restart starts: the detours around the obstacles that block
    /// the prior mean ([`Problem::detour_starts`]), then draws to make up
    /// the number.
    fn restart_starts(&self, n: usize, ctl: &SolveControl) -> Vec<DVector<f64>> {
        let mut starts = self.detour_starts(n, ctl);
        let draws = self.restart_draws(n);
        starts.extend(draws.into_iter().take(n - starts.len()));
        starts
    }

    /// `n` draws `z ~ N(0, I)` of the whitened prior from `options.seed`.
    fn restart_draws(&self, n: usize) -> Vec<DVector<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.options.seed ^ RESTART_STREAM);
        let dim = self.whitening.dim();
        (0..n)
            .map(|_| DVector::from_fn(dim, |_, _| StandardNormal.sample(&mut rng)))
            .collect()
    }
}

/// Counters of every run of one solve, and its wall time (the restarts
/// overlap, so their times do not add up).
struct Spent {
    stats: SolveStats,
    solve_ms: f64,
}

impl Spent {
    fn from(first: &Solution) -> Spent {
        Spent {
            stats: first.stats.clone(),
            solve_ms: first.report.solve_ms,
        }
    }

    fn add(&mut self, restart: &Solution) {
        self.stats.absorb(&restart.stats);
        self.stats.restarts += 1;
    }

    /// `sol` reporting the work of every run, with `note` as a warning.
    fn onto(self, mut sol: Solution, note: String) -> Solution {
        sol.report.iterations = self.stats.iterations;
        sol.report.solve_ms = self.solve_ms;
        sol.report.warnings.push(note);
        sol.stats = self.stats;
        sol
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{typical_request, ExampleSettings};
    use crate::optim::qp::nullspace::NullSpace;
    use crate::robot::Robot;

    /// A run that starts at a feasible point other than the prior mean
    /// (a restart whose draw happens to be feasible) must still move to the
    /// Mahalanobis-closest point, not return its start.
    #[test]
    fn a_run_from_a_feasible_start_still_converges_to_the_closest_point() {
        let robot = Robot::panda().unwrap();
        let settings = ExampleSettings {
            n_obstacles: 0,
            ..Default::default()
        };
        let mut req = typical_request(&robot, 5, &settings).unwrap();
        req.task.goal = None;
        req.task.obstacles.clear();
        let p = req.validate(&robot).unwrap();
        let ctl = SolveControl::default();
        let best = p.solve(&ctl).unwrap();
        assert_eq!(best.status, Status::Optimal);
        // With only the start equality, the optimum is its projection.
        let dim = p.whitening.dim();
        let equalities = p.linear.equalities(&p.ends, &p.prior.mean);
        let space = NullSpace::new(&equalities, dim).unwrap();
        let z_best = p
            .whitening
            .whiten(&DVector::from_column_slice(&best.weights));
        // A feasible start: the optimum moved 0.3 along the affine set.
        let start = &z_best + space.basis.column(0) * 0.3;
        let probe = p.evaluate(p.whitening.weights(&start).as_slice());
        assert!(p.is_feasible(&probe), "the start must be feasible");
        let zero = DVector::zeros(dim);
        let run = p.run(&start, &zero, 100, &ctl).unwrap();
        assert_eq!(run.status, Status::Optimal);
        assert!(run.stats.iterations >= 1);
        let z_run = p
            .whitening
            .whiten(&DVector::from_column_slice(&run.weights));
        assert!(
            (&z_run - &z_best).amax() < 1e-6,
            "{}",
            (&z_run - &z_best).amax()
        );
        assert!((run.mahalanobis - best.mahalanobis).abs() < 1e-6);
    }
}
