//! The configuration the planner ([`super::path`]) joins to the start: the
//! request's final configuration, or for a goal position a configuration
//! of the goal region that reaches it clear of the obstacles.
//!
//! A goal position leaves the final pose free (four redundant degrees of
//! freedom with a position alone, two with an approach axis), and the prior
//! mean's own final pose may be the one an obstacle blocks: a berry beside
//! the target touches the hand that the demonstrations held at that angle.
//! So the candidates ([`Problem::goal_seeds`]) are, in order, the prior
//! mean's final configuration, the final configurations of seeded prior
//! draws, the mean's turned about the last joint, and uniform samples of
//! the joint box. Each is moved onto the goal by the robot's damped
//! least-squares inverse kinematics (null-space pull towards the
//! candidate), pushed within the goal region away from its closest
//! obstacle ([`Problem::push_clear`]: the clearance gradient in the null
//! space of the goal's rows, joints at a bound locked, and a pull back to
//! where the push began so the pose stays the prior's where it can), and
//! moved onto the goal again. A candidate *reaches* when it lies within
//! [`GOAL_FRACTION`] of the goal's tolerance (and of the approach cone,
//! when one is asked), inside the joint limits and clear of every obstacle
//! by the clearance asked. Of the prior's own candidates (its mean and
//! draws) that reach, the goal is the one the prior finds most likely at
//! the end ([`Problem::closest_to_prior_end`]); when none does, the first
//! of the others that reaches. Draws come from `options.seed` and the
//! planner's attempt, so the same problem gives the same goal; the
//! caller's stop is checked between candidates; nothing here is part of
//! the certificate (the SCP certifies the goal constraint).

use super::path::uniform_configuration;
use crate::optim::problem::linear::LinearSet;
use crate::optim::problem::Problem;
use crate::robot::{IkOptions, IkTarget};
use nalgebra::{DMatrix, DVector, Point3, Unit, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Prior draws tried after the prior mean's final configuration.
pub const GOAL_DRAWS: usize = 8;
/// Step of the last joint's turns tried on the mean's final configuration.
pub const ROLL_STEP_RAD: f64 = std::f64::consts::FRAC_PI_4;
/// Uniform samples of the joint box tried last.
pub const GOAL_RANDOM: usize = 8;
/// Clearance (m) beyond the one asked that a goal configuration is pushed
/// to.
pub const PUSH_MARGIN_M: f64 = 0.005;
/// Steps of the push out of collision.
pub const PUSH_STEPS: usize = 60;
/// Largest clearance gain (m) one push step asks for.
pub const PUSH_STEP_M: f64 = 0.02;
/// Largest joint change (rad) of one push step's move along the
/// clearance gradient.
pub const PUSH_STEP_RAD: f64 = 0.1;
/// Fraction of the way back to the starting configuration each push step
/// takes where the goal and the clearance leave the joints free.
pub const PUSH_PULL: f64 = 0.3;
/// Damping of the push step's least squares.
const PUSH_DAMPING: f64 = 1e-6;
/// Fraction of the goal tolerance within which the TCP must reach it.
pub const GOAL_FRACTION: f64 = 0.25;
/// Ridge (rad²) of the prior's final-configuration covariance when the
/// goal candidates are compared.
pub const FINAL_RIDGE: f64 = 1e-6;
/// Mixed into `options.seed` so the goal draws are not the restarts'.
const GOAL_STREAM: u64 = 0x60a1_5eed;

impl Problem {
    /// The final configuration the planner aims at: the request's
    /// `final_configuration`, else a clear configuration reaching the goal
    /// position (see the module docs), else `None` (also once `stop` says
    /// so). `attempt` picks the stream of the draws.
    pub(super) fn planner_goal(&self, attempt: u64, stop: &dyn Fn() -> bool) -> Option<Vec<f64>> {
        if let Some(q) = &self.linear.final_configuration {
            return Some(q.clone());
        }
        let goal = self.goal.as_ref()?;
        let target = IkTarget {
            position: Point3::from(goal.position),
            approach_axis: self.approach().map(|(axis, _)| Unit::new_normalize(axis)),
        };
        let seeds = self.goal_seeds(attempt);
        let (prior, others) = seeds.split_at((1 + GOAL_DRAWS).min(seeds.len()));
        let mut reached = Vec::new();
        for seed in prior {
            if stop() {
                return None;
            }
            reached.extend(self.reach_goal(&target, goal.tolerance_m, seed.clone()));
        }
        if let Some(best) = self.closest_to_prior_end(reached) {
            return Some(best);
        }
        for seed in others {
            if stop() {
                return None;
            }
            if let Some(q) = self.reach_goal(&target, goal.tolerance_m, seed.clone()) {
                return Some(q);
            }
        }
        None
    }

    /// Of `candidates`, the final configuration the prior finds most
    /// likely: the lowest Mahalanobis distance under the prior's marginal
    /// of the final configuration (`J Jᵀ` in whitened coordinates, `J` the
    /// final configuration's Jacobian, with a [`FINAL_RIDGE`] ridge since
    /// real priors are near-singular); ties to the earlier candidate.
    fn closest_to_prior_end(&self, candidates: Vec<Vec<f64>>) -> Option<Vec<f64>> {
        let jacobian = self.ends.position_jacobian(1);
        let n = jacobian.nrows();
        let covariance = &jacobian * jacobian.transpose() + DMatrix::identity(n, n) * FINAL_RIDGE;
        let cholesky = covariance.cholesky()?;
        let mean_final = DVector::from_vec(self.prior_mean_final());
        let cost = |q: &Vec<f64>| {
            let d = DVector::from_column_slice(q) - &mean_final;
            d.dot(&cholesky.solve(&d))
        };
        candidates
            .into_iter()
            .map(|q| (cost(&q), q))
            .fold(None, |best: Option<(f64, Vec<f64>)>, (c, q)| match best {
                Some((b, _)) if b <= c => best,
                _ => Some((c, q)),
            })
            .map(|(_, q)| q)
    }

    /// The configurations inverse kinematics starts from, in order: the
    /// prior mean's final configuration, the final configurations of
    /// [`GOAL_DRAWS`] prior draws, the mean's with its last joint turned
    /// by multiples of [`ROLL_STEP_RAD`] (for the Panda a roll about the
    /// gripper axis, which keeps the TCP where it is), and
    /// [`GOAL_RANDOM`] uniform samples of the joint box.
    fn goal_seeds(&self, attempt: u64) -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.options.seed ^ GOAL_STREAM ^ attempt);
        let mean_final = self.prior_mean_final();
        let mut seeds = vec![mean_final.clone()];
        seeds.extend(
            self.prior
                .sample(&mut rng, GOAL_DRAWS)
                .iter()
                .map(|w| self.ends.position(1, w)),
        );
        let last = mean_final.len() - 1;
        for k in [1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0] {
            let mut rolled = mean_final.clone();
            rolled[last] += k * ROLL_STEP_RAD;
            if (self.linear.lower[last]..=self.linear.upper[last]).contains(&rolled[last]) {
                seeds.push(rolled);
            }
        }
        seeds.extend((0..GOAL_RANDOM).map(|_| uniform_configuration(&self.linear, &mut rng)));
        seeds
    }

    /// `seed` moved onto `target` by inverse kinematics and pushed clear of
    /// the obstacles within the goal region ([`Problem::push_clear`]), when
    /// the result reaches the goal within [`GOAL_FRACTION`] of
    /// `tolerance_m` (and the approach cone), inside the joint limits and
    /// clear of the obstacles by the clearance.
    fn reach_goal(&self, target: &IkTarget, tolerance_m: f64, seed: Vec<f64>) -> Option<Vec<f64>> {
        let ik = |from: Vec<f64>| {
            let options = IkOptions {
                tolerance_m: GOAL_FRACTION * tolerance_m,
                null_space_bias: Some(from.clone()),
                restarts: 0,
                ..IkOptions::default()
            };
            self.robot.ik(target, &from, &options).ok()
        };
        let reached = ik(seed)?;
        let solution = ik(self.push_clear(target, reached.q))?;
        let within_cone = self
            .approach()
            .is_none_or(|(_, tolerance)| solution.axis_error_rad <= GOAL_FRACTION * tolerance);
        let q = solution.q;
        (solution.position_error_m <= GOAL_FRACTION * tolerance_m
            && within_cone
            && self.within_limits(&q)
            && self.clear_by(&q, self.clearance_m))
        .then_some(q)
    }

    /// `q` moved within the goal region away from its closest obstacle
    /// until it clears it by the clearance plus [`PUSH_MARGIN_M`], at most
    /// [`PUSH_STEPS`] steps, the last of them a correction alone. Each step
    /// is, first, the least-norm step that
    /// puts the TCP back on the goal (and holds the gripper axis's tilt,
    /// when the goal has an approach axis) and, second, in the null space
    /// of those rows, the step along the clearance gradient that gains the
    /// missing distance to first order (at most [`PUSH_STEP_M`], capped at
    /// [`PUSH_STEP_RAD`]); a joint at a bound is locked there.
    fn push_clear(&self, target: &IkTarget, mut q: Vec<f64>) -> Vec<f64> {
        let home = q.clone();
        let wanted = self.clearance_m + PUSH_MARGIN_M;
        for _ in 0..PUSH_STEPS {
            let Some((c, gradient)) = self.scene.min_clearance_with_gradient(&self.robot, &q)
            else {
                break;
            };
            let clear = c.distance >= wanted;
            let missing = if clear {
                0.0
            } else {
                (wanted - c.distance).min(PUSH_STEP_M)
            };
            let Some(dq) = self.push_step(target, (&q, &home), &gradient, missing) else {
                break;
            };
            step_within_limits(&mut q, &dq, &self.linear);
            if clear {
                break;
            }
        }
        q
    }

    /// One step of [`Problem::push_clear`] at `q`: the goal's correction
    /// plus, in its null space, the move gaining `missing` metres of
    /// clearance along `gradient`. Joints the step would carry past a
    /// bound are locked (their columns dropped) and the step solved again.
    /// `None` when the goal's null space leaves no way to gain clearance.
    fn push_step(
        &self,
        target: &IkTarget,
        (q, home): (&[f64], &[f64]),
        gradient: &DVector<f64>,
        missing: f64,
    ) -> Option<DVector<f64>> {
        let rows = self.goal_rows(target, q);
        let drift = target.position.coords - self.robot.tcp_pose(q).translation.vector;
        let mut error = DVector::zeros(rows.nrows());
        error.rows_mut(0, 3).copy_from(&drift);
        let mut locked = vec![false; q.len()];
        loop {
            let held = DMatrix::from_fn(rows.nrows(), q.len(), |r, j| {
                if locked[j] {
                    0.0
                } else {
                    rows[(r, j)]
                }
            });
            let g = DVector::from_fn(q.len(), |j, _| if locked[j] { 0.0 } else { gradient[j] });
            let gram = &held * held.transpose()
                + DMatrix::identity(held.nrows(), held.nrows()) * PUSH_DAMPING;
            let ch = gram.cholesky()?;
            // First the goal: the least-norm step that corrects the TCP's
            // drift (the tilt rows held at zero).
            let mut dq = held.transpose() * ch.solve(&error);
            // Then the clearance, in the goal's null space.
            if missing > 0.0 {
                let free = &g - held.transpose() * ch.solve(&(&held * &g));
                let gain = g.dot(&free);
                if gain <= PUSH_DAMPING {
                    return None;
                }
                let mut push = free * (missing / gain);
                let largest = push.amax();
                if largest > PUSH_STEP_RAD {
                    push *= PUSH_STEP_RAD / largest;
                }
                dq += push;
                // Last, back towards `home` where neither the goal nor the
                // clearance's gradient moves.
                let both = DMatrix::from_fn(held.nrows() + 1, q.len(), |r, j| {
                    if r < held.nrows() {
                        held[(r, j)]
                    } else {
                        g[j]
                    }
                });
                let gram = &both * both.transpose()
                    + DMatrix::identity(both.nrows(), both.nrows()) * PUSH_DAMPING;
                let back = DVector::from_fn(q.len(), |j, _| {
                    if locked[j] {
                        0.0
                    } else {
                        PUSH_PULL * (home[j] - q[j])
                    }
                });
                let pull = &back - both.transpose() * gram.cholesky()?.solve(&(&both * &back));
                dq += pull;
            }
            let past: Vec<usize> = (0..q.len())
                .filter(|&j| {
                    let v = q[j] + dq[j];
                    !locked[j] && (v > self.linear.upper[j] || v < self.linear.lower[j])
                })
                .collect();
            if past.is_empty() {
                return Some(dq);
            }
            for j in past {
                locked[j] = true;
            }
        }
    }

    /// The rows of the TCP Jacobian the goal holds at `q`: the position's
    /// three, and with an approach axis the two rotations that tilt the
    /// gripper axis (the roll about it is free).
    fn goal_rows(&self, target: &IkTarget, q: &[f64]) -> DMatrix<f64> {
        let jacobian = self.robot.tcp_jacobian(q);
        let Some(_) = target.approach_axis else {
            return DMatrix::from_fn(3, q.len(), |r, j| jacobian[(r, j)]);
        };
        let axis = self.robot.tcp_pose(q).rotation * Vector3::z();
        let tilt = [axis.cross(&Vector3::x()), axis.cross(&Vector3::y())];
        let tilt = if tilt[0].norm() > tilt[1].norm() {
            tilt[0].normalize()
        } else {
            tilt[1].normalize()
        };
        let other = axis.cross(&tilt);
        DMatrix::from_fn(5, q.len(), |r, j| match r {
            0..=2 => jacobian[(r, j)],
            3 => (0..3).map(|k| tilt[k] * jacobian[(3 + k, j)]).sum(),
            _ => (0..3).map(|k| other[k] * jacobian[(3 + k, j)]).sum(),
        })
    }

    /// The prior mean's final configuration.
    pub(super) fn prior_mean_final(&self) -> Vec<f64> {
        let mean = self
            .whitening
            .weights(&DVector::zeros(self.whitening.dim()));
        self.ends.position(1, &mean)
    }

    /// Whether `q` lies inside the problem's joint position bounds.
    fn within_limits(&self, q: &[f64]) -> bool {
        q.iter()
            .zip(self.linear.lower.iter().zip(&self.linear.upper))
            .all(|(v, (lo, hi))| lo <= v && v <= hi)
    }

    /// Whether configuration `q` is clear of every obstacle by `limit` (m)
    /// (always, without obstacles), by the broad-phase-culled query.
    pub(super) fn clear_by(&self, q: &[f64], limit: f64) -> bool {
        self.scene
            .closest_within(&self.robot, &self.robot.fk(q), limit)
            .is_none()
    }
}

/// `q + dq`, each joint kept inside the problem's position bounds.
fn step_within_limits(q: &mut [f64], dq: &DVector<f64>, linear: &LinearSet) {
    for (j, v) in q.iter_mut().enumerate() {
        *v = (*v + dq[j]).clamp(linear.lower[j], linear.upper[j]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::seeds::test_problems::real_problem;

    /// The unculled exact clearance of `q` to every obstacle.
    fn exact_clearance(p: &Problem, q: &[f64]) -> f64 {
        p.scene
            .min_clearance(&p.robot, &p.robot.fk(q))
            .unwrap()
            .distance
    }

    /// The planner's goal reaches the goal position within a quarter of
    /// its tolerance by forward kinematics, lies inside the joint limits
    /// and clears the berry by the clearance against the meshes, where the
    /// prior mean's final configuration touches it; the same attempt gives
    /// the same goal.
    #[test]
    fn the_goal_configuration_reaches_the_goal_clear_of_the_berry_the_mean_pose_touches() {
        for name in ["real-016.json", "real-027.json", "real-046.json"] {
            let p = real_problem(name);
            let mean = p.whitening.weights(&DVector::zeros(p.whitening.dim()));
            let mean_final = p.ends.position(1, &mean);
            assert!(exact_clearance(&p, &mean_final) < p.clearance_m, "{name}");
            let q = p
                .planner_goal(0, &|| false)
                .expect("a clear goal configuration");
            let goal = p.goal.as_ref().unwrap();
            let tcp = p.robot.tcp_pose(&q).translation.vector;
            let miss = (tcp - Vector3::from(goal.position)).norm();
            assert!(miss <= GOAL_FRACTION * goal.tolerance_m, "{name}: {miss}");
            for (j, v) in q.iter().enumerate() {
                let limit = &p.robot.limits()[j];
                assert!(limit.lower <= *v && *v <= limit.upper, "{name}: joint {j}");
            }
            let clear = exact_clearance(&p, &q);
            assert!(clear >= p.clearance_m, "{name}: {clear}");
            assert_eq!(p.planner_goal(0, &|| false), Some(q), "{name}");
        }
    }

    /// The push raises the clearance by more than a centimetre while the
    /// TCP stays within a millimetre of the goal.
    #[test]
    fn the_push_raises_the_clearance_and_keeps_the_tcp() {
        let p = real_problem("real-016.json");
        let mean = p.whitening.weights(&DVector::zeros(p.whitening.dim()));
        let start = p.ends.position(1, &mean);
        let target = IkTarget {
            position: Point3::from(p.goal.as_ref().unwrap().position),
            approach_axis: None,
        };
        let pushed = p.push_clear(&target, start.clone());
        assert!(exact_clearance(&p, &pushed) > exact_clearance(&p, &start) + 0.01);
        let miss = (p.robot.tcp_pose(&pushed).translation.vector - target.position.coords).norm();
        assert!(miss < 1e-3, "the TCP is {miss} m from the goal");
    }
}
