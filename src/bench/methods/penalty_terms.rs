//! The squared-hinge constraint penalty of the `penalty-gd` baseline and its
//! gradient in the weights, evaluated on a coarse phase grid:
//! clearance (`clearance_m + buffer - d`, gradient from
//! [`crate::scene::Scene::clearance_gradient`]), joint position limits
//! (minus the request's margin), velocity limits and the goal tolerance.

use super::Case;
use crate::robot::{JointLimit, Robot};
use crate::scene::Scene;
use crate::Result;
use nalgebra::{DVector, Vector3};

/// Clearance target above the request's `clearance_m` (m), so that the
/// coarse-grid optimum also passes the dense verification.
const CLEARANCE_BUFFER_M: f64 = 0.005;
/// Fraction of the velocity limit / goal tolerance aimed at.
const INNER_FRACTION: f64 = 0.95;

/// Penalty terms of one problem on a fixed phase grid.
pub struct PenaltyModel {
    psi: Vec<DVector<f64>>,
    dpsi: Vec<DVector<f64>>,
    scene: Scene,
    limits: Vec<JointLimit>,
    margin: f64,
    clearance: f64,
    duration: f64,
    goal: Option<(Vector3<f64>, f64)>,
    nb: usize,
}

impl PenaltyModel {
    /// Build the model on `n_phases` evenly spaced phases.
    pub fn new(case: &Case, basis: &crate::promp::Basis, n_phases: usize) -> Result<PenaltyModel> {
        let n = n_phases.max(2);
        let phases: Vec<f64> = (0..n).map(|i| i as f64 / (n - 1) as f64).collect();
        let r = case.request;
        Ok(PenaltyModel {
            psi: phases.iter().map(|&z| basis.row_at(z)).collect(),
            dpsi: phases.iter().map(|&z| basis.derivative_row_at(z)).collect(),
            scene: Scene::new(r.task.obstacles.clone())?,
            limits: case.robot.limits().to_vec(),
            margin: r.task.joint_limit_margin_rad,
            clearance: r.task.clearance_m + CLEARANCE_BUFFER_M,
            duration: r.task.duration_s,
            goal: r
                .task
                .goal
                .as_ref()
                .map(|g| (Vector3::from(g.position), g.tolerance_m * INNER_FRACTION)),
            nb: basis.n_basis(),
        })
    }

    /// `(P(w), dP/dw)`: the sum of squared constraint excesses and its gradient.
    pub fn value_and_gradient(&self, robot: &Robot, w: &[f64]) -> (f64, DVector<f64>) {
        let mut value = 0.0;
        let mut grad = DVector::zeros(w.len());
        for (psi, dpsi) in self.psi.iter().zip(&self.dpsi) {
            let q = self.eval(psi, w);
            let mut gq = DVector::zeros(q.len());
            value += self.limit_terms(&q, &mut gq);
            value += self.clearance_terms(robot, &q, &mut gq);
            value += self.velocity_terms(dpsi, w, &mut grad);
            self.scatter(psi, &gq, &mut grad);
        }
        if let (Some(goal), Some(psi)) = (&self.goal, self.psi.last()) {
            let q = self.eval(psi, w);
            let mut gq = DVector::zeros(q.len());
            value += goal_terms(robot, &q, goal, &mut gq);
            self.scatter(psi, &gq, &mut grad);
        }
        (value, grad)
    }

    fn eval(&self, row: &DVector<f64>, w: &[f64]) -> Vec<f64> {
        (0..self.limits.len())
            .map(|j| {
                row.iter()
                    .zip(&w[j * self.nb..(j + 1) * self.nb])
                    .map(|(a, b)| a * b)
                    .sum()
            })
            .collect()
    }

    /// `grad_w[j, i] += row[i] * gq[j]`.
    fn scatter(&self, row: &DVector<f64>, gq: &DVector<f64>, grad: &mut DVector<f64>) {
        for (j, g) in gq.iter().enumerate() {
            if *g != 0.0 {
                for (i, r) in row.iter().enumerate() {
                    grad[j * self.nb + i] += r * g;
                }
            }
        }
    }

    fn limit_terms(&self, q: &[f64], gq: &mut DVector<f64>) -> f64 {
        let mut value = 0.0;
        for (j, (qj, l)) in q.iter().zip(&self.limits).enumerate() {
            let over = qj - (l.upper - self.margin);
            let under = (l.lower + self.margin) - qj;
            if over > 0.0 {
                value += over * over;
                gq[j] += 2.0 * over;
            } else if under > 0.0 {
                value += under * under;
                gq[j] -= 2.0 * under;
            }
        }
        value
    }

    fn clearance_terms(&self, robot: &Robot, q: &[f64], gq: &mut DVector<f64>) -> f64 {
        if self.scene.is_empty() {
            return 0.0;
        }
        let frames = robot.fk(q);
        let mut value = 0.0;
        for c in self.scene.clearances_within(robot, &frames, self.clearance) {
            let h = self.clearance - c.distance;
            if h > 0.0 {
                value += h * h;
                *gq -= self.scene.clearance_gradient(robot, q, &frames, &c) * (2.0 * h);
            }
        }
        value
    }

    fn velocity_terms(&self, dpsi: &DVector<f64>, w: &[f64], grad: &mut DVector<f64>) -> f64 {
        let qd: Vec<f64> = self
            .eval(dpsi, w)
            .iter()
            .map(|v| v / self.duration)
            .collect();
        let mut value = 0.0;
        for (j, (v, l)) in qd.iter().zip(&self.limits).enumerate() {
            let h = v.abs() - l.velocity * INNER_FRACTION;
            if h > 0.0 {
                value += h * h;
                let scale = 2.0 * h * v.signum() / self.duration;
                for (i, d) in dpsi.iter().enumerate() {
                    grad[j * self.nb + i] += scale * d;
                }
            }
        }
        value
    }
}

fn goal_terms(robot: &Robot, q: &[f64], goal: &(Vector3<f64>, f64), gq: &mut DVector<f64>) -> f64 {
    let p = robot.tcp_pose(q).translation.vector;
    let e = p - goal.0;
    let dist = e.norm();
    let h = dist - goal.1;
    if h <= 0.0 || dist == 0.0 {
        return 0.0;
    }
    let jac = robot.tcp_jacobian(q);
    let unit = e / dist;
    for j in 0..q.len() {
        let col = Vector3::new(jac[(0, j)], jac[(1, j)], jac[(2, j)]);
        gq[j] += 2.0 * h * unit.dot(&col);
    }
    h * h
}
