//! The direction the gripper approaches the goal from: its z axis `a(q)`
//! at the end within `tolerance_rad` of the goal's unit `approach_axis`
//! `u`, i.e. `a(q)·u ≥ cos(tolerance)`.
//!
//! The cosine's gradient is `∂(a·u)/∂q_j = (ω_j × a)·u`, `ω_j` the TCP
//! Jacobian's angular column; the subproblem keeps the linearised row at
//! the buffered angle ([`buffered_angle`]), with an L1-penalised slack.

use super::{EndConstraint, EndEval, EndRows};
use crate::optim::qp::Inequality;
use crate::optim::report::TrajectoryReport;
use crate::optim::tolerances::buffered_angle;
use crate::robot::Robot;
use nalgebra::{DMatrix, DVector, Vector3};

/// The gripper's z axis at the end within `tolerance_rad` of `axis`.
#[derive(Clone, Debug)]
pub(in crate::optim) struct Approach {
    /// The goal's approach axis (unit, base frame).
    pub(in crate::optim) axis: Vector3<f64>,
    /// Allowed angle (rad).
    pub(in crate::optim) tolerance_rad: f64,
}

/// The end of the motion in the problem's `ends` rows.
const END_PHASE: usize = 1;

impl EndConstraint for Approach {
    fn phase(&self) -> usize {
        END_PHASE
    }

    /// `value`: `[a·u]`; `gradient`: `∂(a·u)/∂q`.
    fn evaluate(&self, robot: &Robot, q: Vec<f64>) -> EndEval {
        let a = robot.tcp_pose(&q).rotation * Vector3::z();
        let jac = robot.tcp_jacobian(&q);
        let gradient = (0..jac.ncols())
            .map(|j| {
                let omega = Vector3::new(jac[(3, j)], jac[(4, j)], jac[(5, j)]);
                omega.cross(&a).dot(&self.axis)
            })
            .collect();
        let cosine = a.dot(&self.axis);
        EndEval {
            excess: (self.tolerance_rad.cos() - cosine).max(0.0),
            buffered_excess: (self.target() - cosine).max(0.0),
            q,
            value: vec![cosine],
            gradient,
        }
    }

    /// `a·u + ∇(a·u)·(z − z_k) ≥ cos(buffered tolerance)`.
    fn linearise(
        &self,
        _robot: &Robot,
        jacobian: &DMatrix<f64>,
        eval: &EndEval,
        z: &DVector<f64>,
        rho: f64,
    ) -> EndRows {
        let g = DVector::from_column_slice(&eval.gradient);
        let a = jacobian.tr_mul(&g);
        let row = Inequality {
            b: eval.value[0] - a.dot(z) - self.target(),
            a: -a,
            penalty: Some(rho),
        };
        EndRows {
            cones: Vec::new(),
            inequalities: vec![row],
        }
    }

    fn report(&self, robot: &Robot, q: &[f64], report: &mut TrajectoryReport) {
        let z = robot.tcp_pose(q).rotation * Vector3::z();
        report.goal_angle_error_rad = Some(z.dot(&self.axis).clamp(-1.0, 1.0).acos());
    }

    fn holds(&self, report: &TrajectoryReport, tolerance: f64) -> bool {
        report
            .goal_angle_error_rad
            .is_some_and(|angle| angle <= self.tolerance_rad + tolerance)
    }

    fn describe(&self, eval: &EndEval) -> String {
        format!(
            "goal.approach_axis: the gripper ends {:.4} rad off the approach axis (approach_tolerance_rad {:.4})",
            eval.value[0].clamp(-1.0, 1.0).acos(),
            self.tolerance_rad
        )
    }
}

impl Approach {
    /// The cosine the QP aims for.
    fn target(&self) -> f64 {
        buffered_angle(self.tolerance_rad).cos()
    }
}
