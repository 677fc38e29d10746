//! Screened prior draws for the restarts: many seeded draws scored on the
//! optimisation phases, the closest to feasible kept.
//!
//! A restart from a random draw of the prior succeeds when the draw already
//! passes the obstacles on a side that leads to the goal; most draws do not.
//! On the real-prior hard set (`bench::hard_set::real`) the misses of the
//! default four restarts were solved by draws 7, 9 and 14 of a longer
//! sequence: the right draw exists among a few dozen, the restarts reached
//! it too rarely. Scoring a draw costs one evaluation of the optimisation
//! phases (forward kinematics and the clearance pairs within the activation
//! distance, [`Problem::evaluate_grid`]), a small fraction of one SCP
//! iteration's QP, so the restarts draw [`SCREENED_DRAWS`] and start from
//! the best: the lowest true violation (clearance deficit plus goal,
//! waypoint and approach excess), ties to the draw closer to the prior
//! mean, then to the earlier draw. Every draw and every score is fixed by
//! the seed and the problem, so the pick is the same whatever the thread
//! count.

use crate::optim::problem::Problem;
use crate::optim::solution::SolveControl;
use nalgebra::DVector;
use rayon::prelude::*;

/// How many seeded draws the restarts score before they pick theirs.
pub const SCREENED_DRAWS: usize = 32;

/// A draw's score: what [`Problem::screened_draws`] ranks by.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Score {
    /// Clearance deficit and goal excess on the optimisation phases;
    /// infinite when the caller's stop interrupted the evaluation.
    violation: f64,
    /// `|z|²`, the draw's squared Mahalanobis distance from the prior mean.
    cost: f64,
}

impl Score {
    fn order(&self, other: &Score) -> std::cmp::Ordering {
        self.violation
            .total_cmp(&other.violation)
            .then(self.cost.total_cmp(&other.cost))
    }
}

impl Problem {
    /// The `n` best of `max(n, SCREENED_DRAWS)` draws of the whitened prior
    /// (`draws`, seeded by the caller), best first (see the module doc).
    pub(super) fn screened_draws(
        &self,
        draws: Vec<DVector<f64>>,
        n: usize,
        ctl: &SolveControl,
    ) -> Vec<DVector<f64>> {
        if n == 0 {
            return Vec::new();
        }
        let score = |z: &DVector<f64>| self.screen_score(z, ctl);
        let scores: Vec<Score> = if ctl.parallel() {
            draws.par_iter().map(score).collect()
        } else {
            draws.iter().map(score).collect()
        };
        let mut order: Vec<usize> = (0..draws.len()).collect();
        order.sort_by(|&i, &j| scores[i].order(&scores[j]).then(i.cmp(&j)));
        let mut draws: Vec<Option<DVector<f64>>> = draws.into_iter().map(Some).collect();
        order
            .into_iter()
            .take(n)
            .filter_map(|k| draws[k].take())
            .collect()
    }

    /// Draw `z`'s [`Score`] on the optimisation phases.
    fn screen_score(&self, z: &DVector<f64>, ctl: &SolveControl) -> Score {
        let zero = DVector::zeros(self.whitening.dim());
        let eval = self.evaluate_grid(&self.grid, z.clone(), &zero, ctl);
        Score {
            violation: if eval.interrupted {
                f64::INFINITY
            } else {
                eval.true_violation
            },
            cost: eval.cost,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{typical_request, ExampleSettings};
    use crate::robot::Robot;

    /// The screen keeps the draws with the lowest violation, in order, and
    /// each kept draw is one of the pool's, unchanged; a stopped caller
    /// still gets `n` of the pool's draws.
    #[test]
    fn the_screen_keeps_the_least_violating_draws_in_order() {
        let robot = Robot::panda().unwrap();
        let req = typical_request(&robot, 11, &ExampleSettings::default()).unwrap();
        let p = req.validate(&robot).unwrap();
        let ctl = SolveControl::default();
        let pool = p.restart_draws(SCREENED_DRAWS);
        let kept = p.screened_draws(pool.clone(), 5, &ctl);
        assert_eq!(kept.len(), 5);
        let violation = |z: &DVector<f64>| p.screen_score(z, &ctl).violation;
        let mut all: Vec<f64> = pool.iter().map(violation).collect();
        all.sort_by(f64::total_cmp);
        for (k, z) in kept.iter().enumerate() {
            assert!(pool.contains(z), "kept draw {k} is not from the pool");
            assert_eq!(violation(z), all[k], "kept draw {k}");
        }
        let stopped = SolveControl {
            deadline: Some(std::time::Instant::now()),
            ..Default::default()
        };
        let kept = p.screened_draws(pool.clone(), 3, &stopped);
        assert_eq!(kept.len(), 3);
        assert!(kept.iter().all(|z| pool.contains(z)));
    }
}
