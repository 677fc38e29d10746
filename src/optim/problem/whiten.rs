//! Whitening of the prior: `Σ + λI = L Lᵀ`, `w = μ + L z`, so that the
//! squared Mahalanobis distance is `|z|²` and every constraint is written
//! in the well-conditioned coordinates `z`.

use crate::promp::{psd, WeightDistribution};
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// Default regularisation of an ill-conditioned prior, relative to its
/// mean variance.
pub const DEFAULT_RELATIVE_LAMBDA: f64 = 1e-6;

/// A prior whose smallest eigenvalue is at least this times its largest is
/// used as stated by default (λ = 0): its optimum is exactly the
/// Mahalanobis-closest under it. Below, the whitened rows would span more
/// than four orders of magnitude and the default λ applies.
pub const WELL_CONDITIONED: f64 = 1e-8;

/// The affine map `z -> w = μ + L z` and its inverse.
#[derive(Clone, Debug)]
pub struct Whitening {
    mean: DVector<f64>,
    factor: DMatrix<f64>,
    inverse: DMatrix<f64>,
    lambda: f64,
}

impl Whitening {
    /// Factor `cov + lambda I`; `lambda` must be finite and >= 0 (0 only
    /// for a prior that is positive definite to the factorisation).
    pub fn new(dist: &WeightDistribution, lambda: f64) -> Result<Whitening> {
        if !lambda.is_finite() || lambda < 0.0 {
            return Err(Error::invalid(
                "options.lambda",
                format!("must be a finite number >= 0, got {lambda}"),
            ));
        }
        let n = dist.dim();
        let shifted = &dist.cov + DMatrix::identity(n, n) * lambda;
        let factor = psd::factor(&shifted);
        let inverse = factor.clone().try_inverse().ok_or_else(|| {
            Error::Numerical(format!(
                "prior covariance + {lambda:e} I is singular; increase options.lambda"
            ))
        })?;
        if !inverse.iter().all(|v| v.is_finite()) {
            return Err(Error::Numerical(
                "prior whitening is not finite; increase options.lambda".into(),
            ));
        }
        Ok(Whitening {
            mean: dist.mean.clone(),
            factor,
            inverse,
            lambda,
        })
    }

    /// The default `lambda`: 0 for a well-conditioned prior (every
    /// eigenvalue of its covariance at least [`WELL_CONDITIONED`] x the
    /// largest), else [`DEFAULT_RELATIVE_LAMBDA`] x the mean prior variance
    /// (at least 1e-12), which only matters in the (nearly) singular
    /// directions.
    pub fn default_lambda(dist: &WeightDistribution) -> f64 {
        let sym = (&dist.cov + dist.cov.transpose()) * 0.5;
        let eigenvalues = sym.symmetric_eigenvalues();
        if eigenvalues.min() >= WELL_CONDITIONED * eigenvalues.max() && eigenvalues.min() > 0.0 {
            return 0.0;
        }
        let n = dist.dim().max(1) as f64;
        (DEFAULT_RELATIVE_LAMBDA * dist.cov.trace() / n).max(1e-12)
    }

    /// The regularisation used.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// Dimension of `z` (= number of weights).
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// The factor `L` with `L Lᵀ = Σ + λI`.
    pub fn factor(&self) -> &DMatrix<f64> {
        &self.factor
    }

    /// Weights `μ + L z`.
    pub fn weights(&self, z: &DVector<f64>) -> DVector<f64> {
        &self.mean + &self.factor * z
    }

    /// Whitened coordinates `L⁻¹ (w - μ)`.
    pub fn whiten(&self, w: &DVector<f64>) -> DVector<f64> {
        &self.inverse * (w - &self.mean)
    }

    /// Mahalanobis distance `sqrt((w-μ)ᵀ(Σ+λI)⁻¹(w-μ))`.
    pub fn mahalanobis(&self, w: &DVector<f64>) -> f64 {
        self.whiten(w).norm()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::example_distribution;
    use crate::promp::{Basis, PrompConfig};

    #[test]
    fn the_default_leaves_a_well_conditioned_prior_as_stated_and_floors_a_singular_one() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 3).unwrap();
        let n = dist.dim();
        let mut pd = dist.clone();
        pd.cov += DMatrix::identity(n, n) * 1e-2;
        assert_eq!(Whitening::default_lambda(&pd), 0.0);
        let wh = Whitening::new(&pd, 0.0).unwrap();
        let rebuilt = wh.factor() * wh.factor().transpose();
        assert!((rebuilt - &pd.cov).amax() < 1e-10 * pd.cov.amax());
        // A rank-one prior keeps the regularisation.
        let v = DVector::from_fn(n, |i, _| 1.0 + i as f64);
        let mut singular = dist.clone();
        singular.cov = &v * v.transpose();
        let mean_variance = v.norm_squared() / n as f64;
        let lambda = Whitening::default_lambda(&singular);
        assert!((lambda - DEFAULT_RELATIVE_LAMBDA * mean_variance).abs() < 1e-9 * lambda);
    }

    #[test]
    fn whitening_round_trips_and_matches_the_direct_mahalanobis() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 3).unwrap();
        let lambda = Whitening::default_lambda(&dist);
        let wh = Whitening::new(&dist, lambda).unwrap();
        let l = wh.factor();
        let n = dist.dim();
        let rebuilt = l * l.transpose();
        let shifted = &dist.cov + DMatrix::identity(n, n) * lambda;
        assert!((rebuilt - &shifted).amax() < 1e-9 * shifted.amax());
        let z = DVector::from_fn(n, |i, _| ((i * 7 % 11) as f64 - 5.0) * 0.3);
        let w = wh.weights(&z);
        assert!((wh.whiten(&w) - &z).amax() < 1e-7);
        let direct = dist.mahalanobis_squared(&w, lambda).sqrt();
        assert!((wh.mahalanobis(&w) - z.norm()).abs() < 1e-6 * z.norm());
        assert!((direct - z.norm()).abs() < 1e-4 * z.norm());
    }

    #[test]
    fn negative_lambda_is_rejected_with_the_field() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 3).unwrap();
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            let e = Whitening::new(&dist, bad).unwrap_err();
            assert_eq!(e.field(), Some("options.lambda"));
        }
    }
}
