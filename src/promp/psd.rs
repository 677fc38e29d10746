//! Symmetric positive semi-definite matrices: repair of indefinite input and
//! factorisations that never fail on rank-deficient covariances.
//!
//! Real priors are numerically rank-deficient (eigenvalues down to 1e-12)
//! and one published annotation is indefinite, so nothing downstream may
//! assume a clean Cholesky factorisation.

use nalgebra::DMatrix;

/// Relative size (to the largest eigenvalue) below which a negative
/// eigenvalue counts as rounding noise rather than indefiniteness.
pub const NEGATIVE_TOLERANCE: f64 = 1e-9;

/// `(A + Aᵀ) / 2`.
pub fn symmetrize(a: &DMatrix<f64>) -> DMatrix<f64> {
    (a + a.transpose()) * 0.5
}

/// Smallest eigenvalue of the symmetric part of `a`.
pub fn min_eigenvalue(a: &DMatrix<f64>) -> f64 {
    symmetrize(a)
        .symmetric_eigenvalues()
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
}

/// Repair a covariance that is not positive semi-definite by clipping its
/// eigenvalues to `floor` (>= 0).
///
/// Returns the (symmetrised) matrix, its smallest eigenvalue before repair,
/// and whether a repair happened. A matrix whose negative eigenvalues are
/// within [`NEGATIVE_TOLERANCE`] of its largest one is only symmetrised.
pub fn repair_covariance(cov: &DMatrix<f64>, floor: f64) -> (DMatrix<f64>, f64, bool) {
    let sym = symmetrize(cov);
    let eig = sym.clone().symmetric_eigen();
    let min = eig
        .eigenvalues
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    let scale = eig.eigenvalues.amax().max(f64::MIN_POSITIVE);
    if min >= -NEGATIVE_TOLERANCE * scale {
        return (sym, min, false);
    }
    let floor = floor.max(0.0);
    let clipped = eig.eigenvalues.map(|v| v.max(floor));
    let repaired =
        &eig.eigenvectors * DMatrix::from_diagonal(&clipped) * eig.eigenvectors.transpose();
    (symmetrize(&repaired), min, true)
}

/// A factor `L` with `L Lᵀ ≈ cov`, which exists for every symmetric input.
///
/// Tries Cholesky with a growing diagonal jitter (relative to the mean
/// diagonal), then falls back to the eigen-decomposition with negative
/// eigenvalues clipped to zero. Deterministic.
pub fn factor(cov: &DMatrix<f64>) -> DMatrix<f64> {
    let sym = symmetrize(cov);
    let n = sym.nrows();
    let scale = (sym.trace() / n.max(1) as f64).abs().max(1e-300);
    for jitter in [0.0, 1e-14, 1e-12, 1e-10] {
        let shifted = &sym + DMatrix::identity(n, n) * (jitter * scale);
        if let Some(chol) = shifted.cholesky() {
            return chol.l();
        }
    }
    let eig = sym.symmetric_eigen();
    let roots = eig.eigenvalues.map(|v| v.max(0.0).sqrt());
    eig.eigenvectors * DMatrix::from_diagonal(&roots)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indefinite_matrix_is_repaired_and_reported() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]); // eigenvalues 3, -1
        let (r, min, repaired) = repair_covariance(&a, 1e-6);
        assert!(repaired);
        assert!((min + 1.0).abs() < 1e-12);
        assert!(min_eigenvalue(&r) >= 1e-6 - 1e-12);
        // Clipping keeps the positive eigen-direction untouched.
        let v = nalgebra::DVector::from_vec(vec![1.0, 1.0]) / 2f64.sqrt();
        assert!(((v.transpose() * &r * &v)[0] - 3.0).abs() < 1e-9);
    }

    #[test]
    fn psd_matrix_is_left_alone() {
        let a = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 2.0]);
        let (r, _, repaired) = repair_covariance(&a, 0.0);
        assert!(!repaired);
        assert_eq!(r, a);
    }

    #[test]
    fn factor_of_rank_deficient_matrix_reproduces_it() {
        let v = DMatrix::from_row_slice(3, 1, &[1.0, -2.0, 0.5]);
        let a = &v * v.transpose(); // rank 1
        let l = factor(&a);
        assert!((&l * l.transpose() - &a).amax() < 1e-8);
        let b = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
        let l = factor(&b);
        assert!((&l * l.transpose() - &b).amax() < 1e-12);
    }
}
