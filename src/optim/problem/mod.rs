//! [`Problem`]: a validated, whitened request, ready to solve — plain
//! data, built by [`OptimizeRequest::validate`](crate::optim::OptimizeRequest::validate)
//! (`request::validate`), read by the solver and the verifier.

pub mod linear;
pub mod phases;
pub mod whiten;

use crate::optim::constraints::EndConstraint;
use crate::optim::problem::linear::LinearSet;
use crate::optim::problem::phases::PhaseRows;
use crate::optim::problem::whiten::Whitening;
use crate::optim::report::{JointTrajectory, TrajectoryFormat, TrajectoryPoint};
use crate::optim::task::{Goal, SolverOptions};
use crate::optim::tolerances::FEASIBILITY_TOLERANCE;
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::scene::Scene;
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

/// A validated request: prior, whitening, robot, scene and constraints.
/// `Clone + Send + Sync`; solving does not mutate it.
#[derive(Clone, Debug)]
pub struct Problem {
    pub(crate) robot: Robot,
    pub(crate) scene: Scene,
    pub(crate) basis: Basis,
    pub(crate) prior: WeightDistribution,
    pub(crate) whitening: Whitening,
    /// Optimisation phases (the request's grid).
    pub(crate) grid: PhaseRows,
    /// Phases 0 and 1 (start / final equalities, goal).
    pub(crate) ends: PhaseRows,
    /// Dense verification phases and their basis rows, `dense[k]` the
    /// `k`-th time derivative ([`Derivative::order`](crate::optim::problem::phases::Derivative::order)).
    pub(crate) dense_phases: Vec<f64>,
    pub(crate) dense: [DMatrix<f64>; 4],
    pub(crate) linear: LinearSet,
    pub(crate) clearance_m: f64,
    pub(crate) activation_m: f64,
    pub(crate) goal: Option<Goal>,
    /// The constraints at single phases (the goal's position and approach,
    /// the tolerant waypoints), in the order their rows enter the QP.
    pub(in crate::optim) end_constraints: Vec<Arc<dyn EndConstraint>>,
    pub(crate) options: SolverOptions,
    pub(crate) duration: f64,
    /// How the phase advances with time (rest-to-rest or free ends).
    pub(crate) warp: crate::optim::problem::phases::TimeWarp,
    /// How answers write the trajectory.
    pub(crate) trajectory_format: crate::optim::report::TrajectoryFormat,
    pub(crate) n_extra_samples: usize,
    pub(crate) warnings: Vec<String>,
}

impl Problem {
    /// `n_basis x n_joints` weight matrix of joint-major `w`.
    pub(crate) fn weight_matrix(&self, w: &DVector<f64>) -> DMatrix<f64> {
        let nb = self.prior.n_basis;
        DMatrix::from_fn(nb, self.prior.n_joints, |i, j| w[j * nb + i])
    }

    /// The trajectory of `w` on the request's grid (equal time steps),
    /// ROS-shaped; accelerations only where the answer's format writes them
    /// (ROS 2).
    pub fn trajectory(&self, weights: &[f64]) -> JointTrajectory {
        let w = DVector::from_column_slice(weights);
        let wm = self.weight_matrix(&w);
        let row = |m: DVector<f64>| (m.transpose() * &wm).iter().copied().collect::<Vec<f64>>();
        let ros2 = self.trajectory_format == TrajectoryFormat::Ros2;
        let points = self
            .basis
            .phases()
            .iter()
            .map(|&tau| {
                let [psi, dpsi, ddpsi, _] = self.warp.time_rows(&self.basis, tau, self.duration);
                TrajectoryPoint {
                    positions: row(psi),
                    velocities: row(dpsi),
                    accelerations: if ros2 { row(ddpsi) } else { Vec::new() },
                    time_from_start: tau * self.duration,
                }
            })
            .collect();
        JointTrajectory {
            joint_names: self.robot.joint_names().to_vec(),
            points,
            format: self.trajectory_format,
        }
    }

    /// The (repaired) prior.
    pub fn prior(&self) -> &WeightDistribution {
        &self.prior
    }

    /// The robot.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The optimisation basis (the request's `promp`).
    pub fn basis(&self) -> &Basis {
        &self.basis
    }

    /// Motion duration (s).
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// Warnings raised while validating (covariance repairs).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Number of extra samples requested.
    pub fn extra_samples(&self) -> usize {
        self.n_extra_samples
    }

    /// The goal's approach axis (unit) and angle tolerance (rad), if any.
    pub fn approach(&self) -> Option<(nalgebra::Vector3<f64>, f64)> {
        let approach = self.goal.as_ref()?.approach()?;
        let axis = nalgebra::Vector3::from(approach.approach_axis);
        Some((axis.normalize(), approach.approach_tolerance_rad))
    }

    /// Mahalanobis distance `sqrt((w-μ)ᵀ(Σ+λI)⁻¹(w-μ))`.
    pub fn mahalanobis(&self, weights: &[f64]) -> f64 {
        self.whitening
            .mahalanobis(&DVector::from_column_slice(weights))
    }

    /// Whether every constraint in `report` holds to
    /// [`FEASIBILITY_TOLERANCE`].
    pub fn is_feasible(&self, report: &crate::optim::report::TrajectoryReport) -> bool {
        let tol = FEASIBILITY_TOLERANCE;
        let clear_ok = report
            .min_clearance_m
            .into_iter()
            .chain(report.continuous_clearance_m)
            .all(|d| d >= self.clearance_m - tol);
        let ends_ok = self.end_constraints.iter().all(|c| c.holds(report, tol));
        let ratio_ok = |r: Option<f64>| r.is_none_or(|r| r <= 1.0 + tol);
        // An interrupted verification has no clearance figures: never feasible.
        let clearance_checked = self.scene.is_empty()
            || (report.min_clearance_m.is_some() && report.continuous_clearance_m.is_some());
        // An interrupted verification checked nothing densely.
        report.verified_samples > 0
            && clearance_checked
            && clear_ok
            && ends_ok
            && report.max_joint_limit_violation_rad <= tol
            && report.max_velocity_ratio <= 1.0 + tol
            && ratio_ok(report.max_acceleration_ratio)
            && ratio_ok(report.max_jerk_ratio)
            && report.equality_error_rad <= tol
            && report.weight_bound_excess <= tol
    }
}
