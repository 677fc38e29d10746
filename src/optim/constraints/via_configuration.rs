//! A configuration waypoint with a tolerance: every joint within
//! `tolerance_rad` of `configuration` at the waypoint's phase (exact
//! configuration waypoints are equalities in
//! [`crate::optim::problem::linear`]).
//!
//! A configuration is linear in the weights, so the rows are exact: two per
//! joint at the buffered tolerance ([`buffered_angle`]), each with an
//! L1-penalised slack.

use super::{worst, EndConstraint, EndEval, EndRows};
use crate::optim::qp::Inequality;
use crate::optim::report::TrajectoryReport;
use crate::optim::tolerances::buffered_angle;
use crate::robot::Robot;
use nalgebra::{DMatrix, DVector};

/// Every joint within `tolerance_rad` of `configuration` at `ends` phase
/// `phase` (`via_points[index]`).
#[derive(Clone, Debug)]
pub(in crate::optim) struct ViaConfiguration {
    /// Index in the request's `via_points`.
    pub(in crate::optim) index: usize,
    /// Index of its phase in the problem's `ends` rows.
    pub(in crate::optim) phase: usize,
    /// Target joint positions (rad).
    pub(in crate::optim) configuration: Vec<f64>,
    /// Allowed difference per joint (rad).
    pub(in crate::optim) tolerance_rad: f64,
}

impl ViaConfiguration {
    /// `Σ_j max(0, |q_j − c_j| − tolerance)` at configuration `q`.
    fn excess(&self, q: &[f64], tolerance: f64) -> f64 {
        q.iter()
            .zip(&self.configuration)
            .map(|(a, c)| ((a - c).abs() - tolerance).max(0.0))
            .sum()
    }
}

impl EndConstraint for ViaConfiguration {
    fn phase(&self) -> usize {
        self.phase
    }

    fn evaluate(&self, _robot: &Robot, q: Vec<f64>) -> EndEval {
        EndEval {
            excess: self.excess(&q, self.tolerance_rad),
            buffered_excess: self.excess(&q, buffered_angle(self.tolerance_rad)),
            q,
            value: Vec::new(),
            gradient: Vec::new(),
        }
    }

    /// `|q_j(z) − c_j| ≤ buffered tolerance`, two rows per joint.
    fn linearise(
        &self,
        _robot: &Robot,
        jacobian: &DMatrix<f64>,
        eval: &EndEval,
        z: &DVector<f64>,
        rho: f64,
    ) -> EndRows {
        let tolerance = buffered_angle(self.tolerance_rad);
        let mut rows = Vec::with_capacity(2 * eval.q.len());
        for (j, (&qj, &cj)) in eval.q.iter().zip(&self.configuration).enumerate() {
            let a = jacobian.row(j).transpose();
            let offset = qj - a.dot(z);
            rows.push(Inequality {
                a: a.clone(),
                b: cj + tolerance - offset,
                penalty: Some(rho),
            });
            rows.push(Inequality {
                a: -a,
                b: offset - (cj - tolerance),
                penalty: Some(rho),
            });
        }
        EndRows {
            cones: Vec::new(),
            inequalities: rows,
        }
    }

    fn report(&self, _robot: &Robot, q: &[f64], report: &mut TrajectoryReport) {
        let excess = q
            .iter()
            .zip(&self.configuration)
            .map(|(a, c)| (a - c).abs() - self.tolerance_rad)
            .reduce(f64::max);
        if let Some(excess) = excess {
            report.via_configuration_excess_rad =
                worst(report.via_configuration_excess_rad, excess);
        }
    }

    fn holds(&self, report: &TrajectoryReport, tolerance: f64) -> bool {
        report
            .via_configuration_excess_rad
            .is_some_and(|e| e <= tolerance)
    }

    fn describe(&self, _eval: &EndEval) -> String {
        format!(
            "via_points[{}]: the joints pass beyond tolerance_rad {:.4} of the configuration",
            self.index, self.tolerance_rad
        )
    }
}
