//! The TCP within `tolerance_m` of a point at one phase: the goal's
//! `position` at the end, a waypoint's `position` on the way.
//!
//! `|TCP(q) − target| ≤ tolerance` is a second-order cone in the TCP; the
//! subproblem linearises the TCP at the iterate (`TCP + J_v Δq`, `J_v` the
//! TCP Jacobian's linear rows) and keeps the cone's radius at the buffered
//! tolerance ([`buffered_tolerance`]), with an L1-penalised slack.

use super::{worst, EndConstraint, EndEval, EndRows};
use crate::optim::qp::Cone;
use crate::optim::report::TrajectoryReport;
use crate::optim::tolerances::buffered_tolerance;
use crate::robot::Robot;
use nalgebra::{DMatrix, DVector, Vector3};

/// Which request field a [`TcpPosition`] comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(in crate::optim) enum TcpTarget {
    /// `goal.position` (report: `goal_error_m`).
    Goal,
    /// `via_points[i].position` (report: `via_position_excess_m`).
    Waypoint(usize),
}

/// The TCP within `tolerance_m` of `position` at `ends` phase `phase`.
#[derive(Clone, Debug)]
pub(in crate::optim) struct TcpPosition {
    /// Where the target comes from.
    pub(in crate::optim) target: TcpTarget,
    /// Index of the phase in the problem's `ends` rows.
    pub(in crate::optim) phase: usize,
    /// Target TCP position (m, base frame).
    pub(in crate::optim) position: Vector3<f64>,
    /// Allowed distance (m).
    pub(in crate::optim) tolerance_m: f64,
}

impl EndConstraint for TcpPosition {
    fn phase(&self) -> usize {
        self.phase
    }

    /// `value`: the TCP's residual `TCP(q) − position`.
    fn evaluate(&self, robot: &Robot, q: Vec<f64>) -> EndEval {
        let pose = robot.tcp_pose(&q);
        let residual = pose.translation.vector - self.position;
        EndEval {
            excess: (residual.norm() - self.tolerance_m).max(0.0),
            buffered_excess: (residual.norm() - buffered_tolerance(self.tolerance_m)).max(0.0),
            q,
            value: residual.iter().copied().collect(),
            gradient: Vec::new(),
        }
    }

    fn linearise(
        &self,
        robot: &Robot,
        jacobian: &DMatrix<f64>,
        eval: &EndEval,
        z: &DVector<f64>,
        rho: f64,
    ) -> EndRows {
        let j = robot.tcp_jacobian(&eval.q);
        let linear = DMatrix::from_iterator(3, j.ncols(), j.rows(0, 3).iter().cloned());
        let g = linear * jacobian;
        let gz = &g * z;
        let cone = Cone {
            offset: DVector::from_fn(3, |i, _| eval.value[i] - gz[i]),
            matrix: g,
            radius: buffered_tolerance(self.tolerance_m),
            penalty: rho,
        };
        EndRows {
            cones: vec![cone],
            inequalities: Vec::new(),
        }
    }

    fn report(&self, robot: &Robot, q: &[f64], report: &mut TrajectoryReport) {
        let p = robot.tcp_pose(q).translation.vector;
        match self.target {
            TcpTarget::Goal => {
                let g = &self.position;
                report.goal_error_m = Some(
                    ((p.x - g[0]).powi(2) + (p.y - g[1]).powi(2) + (p.z - g[2]).powi(2)).sqrt(),
                );
            }
            TcpTarget::Waypoint(_) => {
                let excess = (p - self.position).norm() - self.tolerance_m;
                report.via_position_excess_m = worst(report.via_position_excess_m, excess);
            }
        }
    }

    fn holds(&self, report: &TrajectoryReport, tolerance: f64) -> bool {
        match self.target {
            TcpTarget::Goal => report
                .goal_error_m
                .is_some_and(|e| e <= self.tolerance_m + tolerance),
            TcpTarget::Waypoint(_) => report.via_position_excess_m.is_some_and(|e| e <= tolerance),
        }
    }

    fn describe(&self, eval: &EndEval) -> String {
        let distance = Vector3::from_column_slice(&eval.value).norm();
        match self.target {
            TcpTarget::Goal => format!(
                "goal: the TCP ends {distance:.4} m from the goal (tolerance_m {:.4})",
                self.tolerance_m
            ),
            TcpTarget::Waypoint(i) => format!(
                "via_points[{i}]: the TCP passes {distance:.4} m from the position (tolerance_m {:.4})",
                self.tolerance_m
            ),
        }
    }
}
