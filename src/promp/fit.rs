//! Weights from a trajectory and trajectories from weights.

use super::basis::Basis;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Joint-major weights (`n_joints * n_basis`) of one trajectory.
///
/// `trajectory` is `L x n_joints` (rows are time samples, uniformly spaced
/// over the phase `[0, 1]`, any `L >= 2`). It is resampled onto the basis'
/// phase grid by linear interpolation, then fitted per joint by least
/// squares with the authors' `1e-12` ridge.
pub fn fit_weights(basis: &Basis, trajectory: &DMatrix<f64>) -> Result<nalgebra::DVector<f64>> {
    if trajectory.nrows() < 2 || trajectory.ncols() == 0 {
        return Err(Error::invalid(
            "trajectory",
            format!(
                "needs at least 2 samples of at least 1 joint, got {} x {}",
                trajectory.nrows(),
                trajectory.ncols()
            ),
        ));
    }
    if let Some(i) = trajectory.iter().position(|v| !v.is_finite()) {
        let (row, col) = (i % trajectory.nrows(), i / trajectory.nrows());
        return Err(Error::invalid(
            format!("trajectory[{row}][{col}]"),
            "must be a finite number",
        ));
    }
    let on_grid = resample(trajectory, basis.n_samples());
    let w = basis.projector() * on_grid; // n_basis x n_joints, column j = joint j
    Ok(nalgebra::DVector::from_column_slice(w.as_slice()))
}

/// Positions `T x n_joints` from joint-major weights.
pub fn trajectory_from_weights(basis: &Basis, weights: &[f64], n_joints: usize) -> DMatrix<f64> {
    basis.matrix() * weight_matrix(weights, basis.n_basis(), n_joints)
}

/// Velocities `T x n_joints` (rad/s) for a trajectory lasting `duration_s`.
pub fn velocities_from_weights(
    basis: &Basis,
    weights: &[f64],
    n_joints: usize,
    duration_s: f64,
) -> DMatrix<f64> {
    basis.derivative() * weight_matrix(weights, basis.n_basis(), n_joints) / duration_s
}

/// The `n_basis x n_joints` view of a joint-major weight vector.
pub fn weight_matrix(weights: &[f64], n_basis: usize, n_joints: usize) -> DMatrix<f64> {
    debug_assert_eq!(weights.len(), n_basis * n_joints);
    DMatrix::from_column_slice(n_basis, n_joints, weights)
}

/// Linear interpolation of `L` uniformly spaced rows onto `n` uniformly
/// spaced rows over the same interval.
pub fn resample(trajectory: &DMatrix<f64>, n: usize) -> DMatrix<f64> {
    let l = trajectory.nrows();
    if l == n {
        return trajectory.clone();
    }
    let mut out = DMatrix::zeros(n, trajectory.ncols());
    for k in 0..n {
        let s = k as f64 / (n - 1) as f64 * (l - 1) as f64;
        let i = (s.floor() as usize).min(l - 2);
        let f = s - i as f64;
        let row = trajectory.row(i) * (1.0 - f) + trajectory.row(i + 1) * f;
        out.row_mut(k).copy_from(&row);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;

    #[test]
    fn fit_then_reconstruct_is_exact_in_the_basis_span() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        // Moderate weights, like a smooth demonstration.
        let w: Vec<f64> = (0..56)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) * 0.3)
            .collect();
        let q = trajectory_from_weights(&basis, &w, 7);
        let fitted = fit_weights(&basis, &q).unwrap();
        let q2 = trajectory_from_weights(&basis, fitted.as_slice(), 7);
        assert!((q - q2).amax() < 1e-9);
    }

    #[test]
    fn resampling_a_linear_trajectory_is_exact() {
        let l = 37;
        let traj = DMatrix::from_fn(l, 2, |r, c| (c as f64 + 1.0) * r as f64 / (l - 1) as f64);
        let out = resample(&traj, 150);
        for k in 0..150 {
            let z = k as f64 / 149.0;
            assert!((out[(k, 0)] - z).abs() < 1e-12);
            assert!((out[(k, 1)] - 2.0 * z).abs() < 1e-12);
        }
    }

    #[test]
    fn fit_of_any_length_reproduces_a_smooth_curve() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let l = 400;
        let traj = DMatrix::from_fn(l, 1, |r, _| {
            let z = r as f64 / (l - 1) as f64;
            (std::f64::consts::PI * z).sin()
        });
        let w = fit_weights(&basis, &traj).unwrap();
        let q = trajectory_from_weights(&basis, w.as_slice(), 1);
        for (t, &z) in basis.phases().iter().enumerate() {
            assert!((q[(t, 0)] - (std::f64::consts::PI * z).sin()).abs() < 2e-3);
        }
    }

    #[test]
    fn velocities_match_finite_differences_of_positions() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let w: Vec<f64> = (0..16).map(|k| (k as f64 * 0.7).sin()).collect();
        let duration = 3.0;
        let q = trajectory_from_weights(&basis, &w, 2);
        let v = velocities_from_weights(&basis, &w, 2, duration);
        let dt = duration / 149.0;
        for t in 1..149 {
            for j in 0..2 {
                let fd = (q[(t + 1, j)] - q[(t - 1, j)]) / (2.0 * dt);
                assert!((fd - v[(t, j)]).abs() < 1e-2 * (1.0 + v[(t, j)].abs()));
            }
        }
    }

    #[test]
    fn nan_and_short_trajectories_are_rejected_with_the_field() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let mut traj = DMatrix::zeros(10, 7);
        traj[(3, 2)] = f64::NAN;
        let e = fit_weights(&basis, &traj).unwrap_err();
        assert_eq!(e.field(), Some("trajectory[3][2]"));
        assert!(fit_weights(&basis, &DMatrix::zeros(1, 7)).is_err());
    }
}
