//! Detour starts for the restarts: the prior conditioned to pass an
//! obstacle that blocks its mean on one side or the other.
//!
//! A random draw of the prior starts far from the mean (the prior's spread
//! in the redundant joints is large) and in no particular relation to the
//! obstacles, so a restart from it spends most of its iterations coming
//! back. A detour starts next to the mean: at the phase where the mean's
//! trajectory comes closest to (or deepest into) an obstacle, the robot's
//! witness point is moved along the contact normal, out on the near side
//! or through to the far side of the obstacle, by the clearance plus a
//! margin; one damped least-squares step through the point's Jacobian turns
//! that into a configuration, and the start is the prior conditioned on
//! that configuration at that phase with both ends kept where the mean has
//! them: ProMP via-point conditioning, which in whitened coordinates is the
//! minimum-norm `z` meeting the three configurations (the lowest-cost
//! trajectory of the prior through them).

use crate::optim::problem::Problem;
use crate::optim::seeds::condition::{condition, Observation};
use crate::optim::solution::SolveControl;
use crate::optim::tolerances::CLEARANCE_BUFFER_M;
use crate::scene::Clearance;
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Point3, Vector3};

/// How much farther than the clearance (m) a detour moves the witness point.
const DETOUR_MARGIN_M: f64 = 0.01;

/// Damping (m²) of the least-squares step from a point displacement to a
/// configuration change.
const DAMPING: f64 = 1e-4;

impl Problem {
    /// Up to `n` whitened starts that detour around the obstacles the prior
    /// mean's trajectory comes closer to than the clearance: the worst
    /// obstacle first, each passed on its near side, then its far side.
    pub(in crate::optim) fn detour_starts(
        &self,
        n: usize,
        ctl: &SolveControl,
    ) -> Vec<DVector<f64>> {
        let zero = DVector::zeros(self.whitening.dim());
        let eval = self.evaluate_grid(&self.grid, zero.clone(), &zero, ctl);
        let target = self.clearance_m + CLEARANCE_BUFFER_M + DETOUR_MARGIN_M;
        // The closest pair of each obstacle that blocks the mean.
        let mut blocking: Vec<(usize, usize, &Clearance)> = Vec::new();
        for (k, phase) in eval.pairs.iter().enumerate() {
            for c in phase.list.iter().filter(|c| c.distance < target) {
                match blocking.iter_mut().find(|b| b.2.obstacle == c.obstacle) {
                    Some(b) if c.distance < b.2.distance => *b = (k, phase.phase, c),
                    Some(_) => {}
                    None => blocking.push((k, phase.phase, c)),
                }
            }
        }
        blocking.sort_by(|a, b| {
            a.2.distance
                .total_cmp(&b.2.distance)
                .then(a.2.obstacle.cmp(&b.2.obstacle))
        });
        let mut starts = Vec::new();
        for (k, p, c) in blocking {
            let phase = &eval.pairs[k];
            let normal = Vector3::from(c.normal);
            let width = self.obstacle_width(c.obstacle, &normal);
            let jacobian = self.robot.point_jacobian(
                &phase.q,
                &phase.frames,
                c.link,
                &Point3::from(c.point_robot),
            );
            for push in [target - c.distance, -(c.distance.max(0.0) + width + target)] {
                if starts.len() == n {
                    return starts;
                }
                let dq = damped_step(&jacobian, &(normal * push));
                if let Some(z) = self.conditioned_start(p, &dq) {
                    starts.push(z);
                }
            }
        }
        starts
    }

    /// Extent (m) of an obstacle's box along `normal`.
    fn obstacle_width(&self, obstacle: usize, normal: &Vector3<f64>) -> f64 {
        let b = &self.scene.compiled[obstacle].bounds;
        (b.max - b.min).zip_map(normal, |e, n| e * n.abs()).sum()
    }

    /// The minimum-norm whitened `z` whose configuration at grid phase `p`
    /// is the mean's plus `dq` and whose configurations at both ends are the
    /// mean's: the prior conditioned on those three configurations.
    fn conditioned_start(&self, p: usize, dq: &DVector<f64>) -> Option<DVector<f64>> {
        let at_mean = |jacobian: DMatrix<f64>| Observation {
            jacobian,
            offset: DVector::zeros(dq.len()),
        };
        condition(&[
            at_mean(self.ends.position_jacobian(0)),
            Observation {
                jacobian: self.grid.position_jacobian(p),
                offset: dq.clone(),
            },
            at_mean(self.ends.position_jacobian(1)),
        ])
    }
}

/// `Jᵀ (J Jᵀ + μI)⁻¹ dx`: the damped least-squares joint step that moves a
/// point with Jacobian `J` (3 × n) by `dx`.
fn damped_step(jacobian: &Matrix3xX<f64>, dx: &Vector3<f64>) -> DVector<f64> {
    let gram = jacobian * jacobian.transpose() + Matrix3::identity() * DAMPING;
    match gram.cholesky() {
        Some(ch) => jacobian.transpose() * ch.solve(dx),
        None => DVector::zeros(jacobian.ncols()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{typical_request, ExampleSettings};
    use crate::optim::seeds::condition::CONDITIONING_NOISE;
    use crate::robot::Robot;

    /// The conditioned start is the regularised minimum-norm solution of
    /// the three configuration equations: it meets them (to what the
    /// conditioning noise moves it: a start, not an answer) and equals the
    /// same solution computed the other way round, `(AᵀA + εI)⁻¹Aᵀb`.
    #[test]
    fn a_detour_start_is_the_prior_conditioned_on_three_configurations() {
        let robot = Robot::panda().unwrap();
        let req = typical_request(&robot, 3, &ExampleSettings::default()).unwrap();
        let p = req.validate(&robot).unwrap();
        let phase = p.grid.len() / 2;
        let dq = DVector::from_fn(robot.dof(), |j, _| 0.05 * (j as f64 - 3.0));
        let z = p.conditioned_start(phase, &dq).unwrap();
        let rows = [
            (p.ends.position_jacobian(0), DVector::zeros(robot.dof())),
            (p.grid.position_jacobian(phase), dq.clone()),
            (p.ends.position_jacobian(1), DVector::zeros(robot.dof())),
        ];
        for (a, b) in &rows {
            let residual = (a * &z - b).amax();
            assert!(residual < 1e-4, "residual {residual}");
        }
        let a = DMatrix::from_fn(3 * robot.dof(), z.len(), |r, c| {
            rows[r / robot.dof()].0[(r % robot.dof(), c)]
        });
        let b = DVector::from_fn(3 * robot.dof(), |r, _| {
            rows[r / robot.dof()].1[r % robot.dof()]
        });
        let mut normal = a.transpose() * &a;
        for i in 0..normal.nrows() {
            normal[(i, i)] += CONDITIONING_NOISE;
        }
        let reference = normal.lu().solve(&(a.transpose() * b)).unwrap();
        let gap = (&z - &reference).amax();
        assert!(gap < 1e-4 * (1.0 + reference.amax()), "{gap}");
    }

    /// On the hard scenes' kind of problem (an obstacle across the mean's
    /// path), each detour clears the obstacle it was made for at the phase
    /// it was made at, or at least moves the robot away from it.
    #[test]
    fn detours_exist_for_a_blocked_mean_and_none_for_a_clear_one() {
        let robot = Robot::panda().unwrap();
        let req = typical_request(&robot, 0, &ExampleSettings::default()).unwrap();
        let p = req.validate(&robot).unwrap();
        let ctl = SolveControl::default();
        let starts = p.detour_starts(4, &ctl);
        assert!(starts.len() <= 4);
        for z in &starts {
            assert_eq!(z.len(), p.whitening.dim());
            assert!(z.iter().all(|v| v.is_finite()));
        }
        let mut clear = typical_request(&robot, 0, &ExampleSettings::default()).unwrap();
        clear.task.obstacles.clear();
        let p = clear.validate(&robot).unwrap();
        assert!(p.detour_starts(4, &ctl).is_empty());
    }
}
