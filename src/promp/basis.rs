//! The normalised Gaussian basis of the paper (Eq. 1–3), exactly as the
//! authors' code builds it: centres `c_i = i / (n_basis - 1)`,
//! `b_i(z) = exp(-(z - c_i)^2 / (2 h))`, `psi_i = b_i / sum_j b_j`, phases
//! `z_t = t / (T - 1)`.

use super::config::PrompConfig;
use crate::Result;
use nalgebra::{DMatrix, DVector};

/// Ridge added to `PhiᵀPhi` when fitting weights.
///
/// The authors' code adds 1e-12 to the normal equations for stability. The
/// fit here solves through the SVD of `Phi`, which is stable without it, so
/// the ridge only guards an exactly singular basis; at 1e-14 it moves
/// fitted trajectories by < 1e-10 rad, where 1e-12 would bias the weakest
/// basis direction (singular value² ~ 4e-8) by ~5e-9 rad.
pub const FIT_RIDGE: f64 = 1e-14;

/// The basis sampled on the phase grid, its phase derivative, and the
/// least-squares projector used for fitting.
#[derive(Clone, Debug)]
pub struct Basis {
    config: PrompConfig,
    phases: Vec<f64>,
    matrix: DMatrix<f64>,
    derivative: DMatrix<f64>,
    projector: DMatrix<f64>,
}

impl Basis {
    /// Build the basis for `config` (validated).
    pub fn new(config: &PrompConfig) -> Result<Basis> {
        config.validate()?;
        let t = config.n_samples;
        let phases = phase_grid(t);
        let nb = config.n_basis;
        let mut matrix = DMatrix::zeros(t, nb);
        let mut derivative = DMatrix::zeros(t, nb);
        for (row, &z) in phases.iter().enumerate() {
            let (psi, dpsi) = psi_and_derivative(config, z);
            matrix.row_mut(row).copy_from(&psi.transpose());
            derivative.row_mut(row).copy_from(&dpsi.transpose());
        }
        let projector = ridge_projector(&matrix)?;
        Ok(Basis {
            config: config.clone(),
            phases,
            matrix,
            derivative,
            projector,
        })
    }

    /// The settings this basis was built from.
    pub fn config(&self) -> &PrompConfig {
        &self.config
    }

    /// Number of basis functions per joint.
    pub fn n_basis(&self) -> usize {
        self.config.n_basis
    }

    /// Number of phase samples `T`.
    pub fn n_samples(&self) -> usize {
        self.config.n_samples
    }

    /// The phase grid `z_t = t / (T - 1)`.
    pub fn phases(&self) -> &[f64] {
        &self.phases
    }

    /// `T x n_basis` matrix, `Phi[t, i] = psi_i(z_t)`; rows sum to one.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.matrix
    }

    /// `T x n_basis` matrix of `d psi_i / dz` (divide by the duration for
    /// time derivatives).
    pub fn derivative(&self) -> &DMatrix<f64> {
        &self.derivative
    }

    /// `n_basis x T` ridge least-squares projector `(PhiᵀPhi + rI)⁻¹ Phiᵀ`.
    pub fn projector(&self) -> &DMatrix<f64> {
        &self.projector
    }

    /// `psi(z)` at any phase (not limited to the grid).
    pub fn row_at(&self, z: f64) -> DVector<f64> {
        psi_and_derivative(&self.config, z).0
    }

    /// `d psi / dz` at any phase.
    pub fn derivative_row_at(&self, z: f64) -> DVector<f64> {
        psi_and_derivative(&self.config, z).1
    }

    /// `d² psi / dz²` at any phase (divide by the duration squared for
    /// accelerations).
    pub fn second_derivative_row_at(&self, z: f64) -> DVector<f64> {
        let [_, _, d2, _] = psi_derivatives(&self.config, z);
        d2
    }

    /// `d³ psi / dz³` at any phase (divide by the duration cubed for jerks).
    pub fn third_derivative_row_at(&self, z: f64) -> DVector<f64> {
        let [_, _, _, d3] = psi_derivatives(&self.config, z);
        d3
    }

    /// `psi` and its first three phase derivatives at `z` (index = order).
    pub fn rows_at(&self, z: f64) -> [DVector<f64>; 4] {
        psi_derivatives(&self.config, z)
    }

    /// The same basis resampled on `n_samples` phases (dense verification).
    pub fn resampled(&self, n_samples: usize) -> Result<Basis> {
        Basis::new(&PrompConfig {
            n_samples,
            ..self.config.clone()
        })
    }
}

/// `t` phases evenly spaced over [0, 1], both ends included (`t >= 2`).
pub fn phase_grid(t: usize) -> Vec<f64> {
    (0..t).map(|k| k as f64 / (t - 1) as f64).collect()
}

/// Per-basis-function scratch values, on the stack for the usual basis sizes.
type Scratch = smallvec::SmallVec<[f64; 16]>;

/// Normalised basis and its phase derivative at `z`.
///
/// With `g_i = -(z - c_i) / h`, `b_i' = g_i b_i`, so
/// `psi_i' = psi_i (g_i - sum_j psi_j g_j)`. The Gaussians are evaluated
/// relative to the largest exponent so that the ratio never underflows.
fn psi_and_derivative(config: &PrompConfig, z: f64) -> (DVector<f64>, DVector<f64>) {
    let nb = config.n_basis;
    let h = config.width;
    let centres = (0..nb).map(|i| i as f64 / (nb - 1) as f64);
    // Stack buffers: this runs at every phase the continuous certificate
    // and the joint-peak search visit.
    let exponents: Scratch = centres
        .clone()
        .map(|c| -(z - c) * (z - c) / (2.0 * h))
        .collect();
    let top = exponents.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let b: Scratch = exponents.iter().map(|e| (e - top).exp()).collect();
    let sum: f64 = b.iter().sum();
    let psi = DVector::from_iterator(nb, b.iter().map(|v| v / sum));
    let g: Scratch = centres.map(|c| -(z - c) / h).collect();
    let mean_g: f64 = psi.iter().zip(&g).map(|(p, g)| p * g).sum();
    let dpsi = DVector::from_iterator(nb, psi.iter().zip(&g).map(|(p, g)| p * (g - mean_g)));
    (psi, dpsi)
}

/// `psi` and its first three phase derivatives at `z`, in one pass.
///
/// With `g_i = -(z - c_i) / h` (so `b_i' = g_i b_i`, `g_i' = -1/h`),
/// `ḡ = Σ psi_j g_j`, `S₁ = Σ psi_j' g_j` and `S₂ = Σ psi_j'' g_j`:
/// `psi_i'' = psi_i' (g_i - ḡ) - psi_i S₁`, and differentiating once more
/// (`ḡ' = S₁ - 1/h`; `S₁' = S₂` as `Σ_j psi_j' = 0`)
/// `psi_i''' = psi_i'' (g_i - ḡ) - 2 psi_i' S₁ - psi_i S₂`.
fn psi_derivatives(config: &PrompConfig, z: f64) -> [DVector<f64>; 4] {
    let (psi, dpsi) = psi_and_derivative(config, z);
    let nb = config.n_basis;
    let g: Scratch = (0..nb)
        .map(|i| -(z - i as f64 / (nb - 1) as f64) / config.width)
        .collect();
    let against_g = |v: &DVector<f64>| v.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>();
    let (mean_g, s1) = (against_g(&psi), against_g(&dpsi));
    let ddpsi = DVector::from_fn(nb, |i, _| dpsi[i] * (g[i] - mean_g) - psi[i] * s1);
    let s2 = against_g(&ddpsi);
    let dddpsi = DVector::from_fn(nb, |i, _| {
        ddpsi[i] * (g[i] - mean_g) - 2.0 * dpsi[i] * s1 - psi[i] * s2
    });
    [psi, dpsi, ddpsi, dddpsi]
}

/// `(PhiᵀPhi + rI)⁻¹ Phiᵀ`, computed from the SVD of `Phi` as
/// `V diag(s / (s² + r)) Uᵀ` so that the basis' poor conditioning (width
/// 0.07 overlaps heavily: cond(PhiᵀPhi) ~ 5e8) is not squared.
fn ridge_projector(phi: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    // A non-finite entry would make the SVD iterate for ever; the iteration
    // count is bounded besides (nalgebra's `svd` has no bound; its
    // tolerance, 5 eps, is kept so that the projector is unchanged).
    if !phi.iter().all(|v| v.is_finite()) {
        return Err(crate::Error::Numerical(
            "the basis has a non-finite value (width too narrow for its phases)".into(),
        ));
    }
    let svd = phi
        .clone()
        .try_svd(true, true, 5.0 * f64::EPSILON, 100_000)
        .ok_or_else(|| crate::Error::Numerical("basis SVD did not converge".into()))?;
    let (Some(u), Some(v_t)) = (svd.u.as_ref(), svd.v_t.as_ref()) else {
        return Err(crate::Error::Numerical("basis SVD did not converge".into()));
    };
    let gains = svd.singular_values.map(|s| s / (s * s + FIT_RIDGE));
    Ok(v_t.transpose() * DMatrix::from_diagonal(&gains) * u.transpose())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn basis() -> Basis {
        Basis::new(&PrompConfig::default()).unwrap()
    }

    #[test]
    fn the_second_derivative_matches_finite_differences_of_the_first() {
        let b = basis();
        let step = 1e-6;
        for k in 0..=40 {
            let z = k as f64 / 40.0;
            let fd = (b.derivative_row_at(z + step) - b.derivative_row_at(z - step)) / (2.0 * step);
            let exact = b.second_derivative_row_at(z);
            let scale = exact.amax().max(1.0);
            assert!((fd - &exact).amax() < 1e-5 * scale, "z {z}");
            // The rows sum to one, so the derivatives sum to zero.
            assert!(exact.sum().abs() < 1e-9 * scale);
        }
    }

    #[test]
    fn the_third_derivative_matches_finite_differences_of_the_second() {
        let b = basis();
        let step = 1e-5;
        for k in 0..=40 {
            let z = k as f64 / 40.0;
            let fd = (b.second_derivative_row_at(z + step) - b.second_derivative_row_at(z - step))
                / (2.0 * step);
            let rows = b.rows_at(z);
            let scale = rows[3].amax().max(1.0);
            assert!((fd - &rows[3]).amax() < 1e-5 * scale, "z {z}");
            assert!(rows[3].sum().abs() < 1e-9 * scale);
            assert_eq!(rows[2], b.second_derivative_row_at(z));
        }
    }

    #[test]
    fn rows_sum_to_one_and_derivative_rows_to_zero() {
        let b = basis();
        for t in 0..b.n_samples() {
            assert!((b.matrix().row(t).sum() - 1.0).abs() < 1e-14);
            assert!(b.derivative().row(t).sum().abs() < 1e-10);
        }
    }

    #[test]
    fn derivative_matches_central_differences() {
        let b = basis();
        let eps = 1e-6;
        for &z in &[0.0, 0.13, 0.5, 0.77, 1.0] {
            let fd = (b.row_at(z + eps) - b.row_at(z - eps)) / (2.0 * eps);
            let an = b.derivative_row_at(z);
            assert!((fd - an).amax() < 1e-6, "z={z}");
        }
    }

    #[test]
    fn grid_rows_equal_rows_at_phase() {
        let b = basis();
        for (t, &z) in b.phases().iter().enumerate() {
            let r = b.row_at(z);
            assert!((b.matrix().row(t).transpose() - r).amax() < 1e-15);
        }
        assert_eq!(b.phases()[0], 0.0);
        assert_eq!(b.phases()[149], 1.0);
    }

    #[test]
    fn basis_matches_the_paper_formula_at_a_point() {
        let b = basis();
        let z: f64 = 0.3;
        let raw: Vec<f64> = (0..8)
            .map(|i| (-(z - i as f64 / 7.0).powi(2) / (2.0 * 0.07)).exp())
            .collect();
        let s: f64 = raw.iter().sum();
        let r = b.row_at(z);
        for i in 0..8 {
            assert!((r[i] - raw[i] / s).abs() < 1e-15);
        }
    }

    #[test]
    fn invalid_settings_name_the_field() {
        let bad = PrompConfig {
            width: f64::NAN,
            ..Default::default()
        };
        assert_eq!(Basis::new(&bad).unwrap_err().field(), Some("width"));
        let bad = PrompConfig {
            n_basis: 1,
            ..Default::default()
        };
        assert_eq!(Basis::new(&bad).unwrap_err().field(), Some("n_basis"));
    }
}
