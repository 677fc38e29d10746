//! The final point of a trajectory distribution, as the evaluation and the
//! condition-only baseline both measure it: the TCP forward kinematics they
//! are given (or, for a task-space model, [`task_final_pose`]), the
//! per-joint marginal at the last phase sample, and the paper's quaternion
//! distance (Eq. 9).

use crate::promp::{Basis, WeightDistribution};
use nalgebra::{Isometry3, UnitQuaternion};

/// Forward kinematics of the TCP: joint positions to base-frame pose.
pub type TcpFk<'a> = &'a (dyn Fn(&[f64]) -> Isometry3<f64> + Sync);

/// A task-space model's final point as a pose (the quaternion normalised),
/// the [`TcpFk`] of a task-space evaluation. A prediction whose quaternion
/// has no direction (norm below 1e-6) scores as the identity rotation: its
/// orientation error is then as large as it is.
pub fn task_final_pose(row: &[f64]) -> Isometry3<f64> {
    crate::task_space::pose_of_row(row).unwrap_or_else(|_| {
        let p = |k: usize| row.get(k).copied().unwrap_or(0.0);
        Isometry3::translation(p(0), p(1), p(2))
    })
}

/// Per-joint mean and standard deviation at the final phase sample.
pub fn final_marginal(distribution: &WeightDistribution, basis: &Basis) -> (Vec<f64>, Vec<f64>) {
    let phi = basis.matrix().row(basis.n_samples() - 1).transpose();
    (0..distribution.n_joints)
        .map(|j| {
            let (mean, cov) = distribution.joint_block(j);
            let var = (phi.transpose() * &cov * &phi)[(0, 0)];
            (phi.dot(&mean), var.max(0.0).sqrt())
        })
        .unzip()
}

/// Eq. 9: `min(|q - q'|, |q + q'|)` over quaternion coordinates.
pub fn quaternion_distance(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let (a, b) = (a.coords, b.coords);
    (a - b).norm().min((a + b).norm())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_task_row_reads_as_its_pose_and_a_null_quaternion_as_identity() {
        let q = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        let c = q.coords * -2.0;
        let pose = task_final_pose(&[0.5, -0.1, 0.7, c[0], c[1], c[2], c[3]]);
        assert!(pose.rotation.angle_to(&q) < 1e-12);
        assert_eq!(
            pose.translation.vector,
            nalgebra::Vector3::new(0.5, -0.1, 0.7)
        );
        let null = task_final_pose(&[0.5, -0.1, 0.7, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(null.rotation, UnitQuaternion::identity());
        assert_eq!(null.translation.vector.x, 0.5);
    }
}
