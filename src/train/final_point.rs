//! The final point of a trajectory distribution, as the evaluation and the
//! condition-only baseline both measure it: the TCP forward kinematics they
//! are given, the per-joint marginal at the last phase sample, and the
//! paper's quaternion distance (Eq. 9).

use crate::promp::{Basis, WeightDistribution};
use nalgebra::{Isometry3, UnitQuaternion};

/// Forward kinematics of the TCP: joint positions to base-frame pose.
pub type TcpFk<'a> = &'a (dyn Fn(&[f64]) -> Isometry3<f64> + Sync);

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
