//! The prior conditioned on configurations at given phases: ProMP via-point
//! conditioning, which in the whitened coordinates the SCP works in is the
//! minimum-norm `z` that meets the configurations (the trajectory of the
//! prior through them that the prior finds most likely).
//!
//! The detours ([`super::detour`]) condition on a configuration beside an
//! obstacle between the mean's two ends; the pinned goal start
//! ([`super::pinned`]) on a clear configuration of the goal region at the
//! end ([`Problem::goal_conditioned_start`]).

use crate::optim::problem::Problem;
use nalgebra::{DMatrix, DVector};

/// Observation noise (rad²) of the conditioning: keeps the Gram matrix of
/// the configurations invertible when they are dependent.
pub(super) const CONDITIONING_NOISE: f64 = 1e-9;

/// One observed configuration: `jacobian · z = offset`, `jacobian` the
/// configuration's rows at its phase (whitened, so `z = 0` is the prior
/// mean) and `offset` the configuration minus the mean's there.
pub(super) struct Observation {
    pub(super) jacobian: DMatrix<f64>,
    pub(super) offset: DVector<f64>,
}

/// The minimum-norm `z` meeting `observations` (regularised by
/// [`CONDITIONING_NOISE`]); `None` when the Gram matrix is singular even so
/// or the result is not finite.
pub(super) fn condition(observations: &[Observation]) -> Option<DVector<f64>> {
    let a = DMatrix::from_rows(
        &observations
            .iter()
            .flat_map(|o| o.jacobian.row_iter().map(|r| r.into_owned()))
            .collect::<Vec<_>>(),
    );
    let b = DVector::from_iterator(
        a.nrows(),
        observations.iter().flat_map(|o| o.offset.iter().copied()),
    );
    let mut gram = &a * a.transpose();
    for i in 0..gram.nrows() {
        gram[(i, i)] += CONDITIONING_NOISE;
    }
    let y = gram.cholesky()?.solve(&b);
    let z = a.transpose() * y;
    z.iter().all(|v| v.is_finite()).then_some(z)
}

impl Problem {
    /// The prior conditioned on its mean's start and on `goal` as the final
    /// configuration: a start next to the prior that ends clear of the
    /// obstacles in the goal region, where the mean's own final pose
    /// touches one.
    pub(super) fn goal_conditioned_start(&self, goal: &[f64]) -> Option<DVector<f64>> {
        let n = goal.len();
        let mean_final = self.prior_mean_final();
        let observations = [
            Observation {
                jacobian: self.ends.position_jacobian(0),
                offset: DVector::zeros(n),
            },
            Observation {
                jacobian: self.ends.position_jacobian(1),
                offset: DVector::from_iterator(n, goal.iter().zip(&mean_final).map(|(g, m)| g - m)),
            },
        ];
        condition(&observations)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{typical_request, ExampleSettings};
    use crate::robot::Robot;

    /// The goal-conditioned start keeps the mean's start, ends at the goal
    /// configuration, and is the closest such `z` to the prior mean: no
    /// step within the null space of the two observations shortens it.
    #[test]
    fn the_goal_start_meets_both_ends_with_the_least_norm() {
        let robot = Robot::panda().unwrap();
        let req = typical_request(&robot, 3, &ExampleSettings::default()).unwrap();
        let p = req.validate(&robot).unwrap();
        let mut goal = p.prior_mean_final();
        for (j, v) in goal.iter_mut().enumerate() {
            *v += 0.04 * (j as f64 - 3.0);
        }
        let z = p.goal_conditioned_start(&goal).unwrap();
        let w = p.whitening.weights(&z);
        let mean_w = p.whitening.weights(&DVector::zeros(z.len()));
        let start_gap = DVector::from_vec(p.ends.position(0, &w))
            - DVector::from_vec(p.ends.position(0, &mean_w));
        let end_gap = DVector::from_vec(p.ends.position(1, &w)) - DVector::from_vec(goal.clone());
        assert!(start_gap.amax() < 1e-4, "start moved {}", start_gap.amax());
        assert!(end_gap.amax() < 1e-4, "end misses by {}", end_gap.amax());
        // Minimum norm: z lies in the row space of the observations, so it
        // is orthogonal to every direction that moves neither end.
        let a = DMatrix::from_rows(
            &[p.ends.position_jacobian(0), p.ends.position_jacobian(1)]
                .iter()
                .flat_map(|m| m.row_iter().map(|r| r.into_owned()).collect::<Vec<_>>())
                .collect::<Vec<_>>(),
        );
        let gram = (&a * a.transpose()).pseudo_inverse(1e-12).unwrap();
        for k in 0..5 {
            let r = DVector::from_fn(z.len(), |i, _| ((i * 7 + k * 13) % 11) as f64 - 5.0);
            let free = &r - a.transpose() * (&gram * (&a * &r));
            assert!((&a * &free).amax() < 1e-6, "not a free direction");
            let along = free.dot(&z) / free.norm();
            assert!(
                along.abs() < 1e-5 * (1.0 + z.norm()),
                "direction {k}: {along}"
            );
        }
    }
}
