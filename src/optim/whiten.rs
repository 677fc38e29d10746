//! Whitening of the prior: `Σ + λI = L Lᵀ`, `w = μ + L z`, so that the
//! squared Mahalanobis distance is `|z|²` and every constraint is written
//! in the well-conditioned coordinates `z`.

use crate::promp::{psd, WeightDistribution};
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// Default regularisation relative to the mean prior variance.
pub const DEFAULT_RELATIVE_LAMBDA: f64 = 1e-6;

/// The affine map `z -> w = μ + L z` and its inverse.
#[derive(Clone, Debug)]
pub struct Whitening {
    mean: DVector<f64>,
    factor: DMatrix<f64>,
    inverse: DMatrix<f64>,
    lambda: f64,
}

impl Whitening {
    /// Factor `cov + lambda I`; `lambda` must be finite and > 0.
    pub fn new(dist: &WeightDistribution, lambda: f64) -> Result<Whitening> {
        if !lambda.is_finite() || lambda <= 0.0 {
            return Err(Error::invalid(
                "options.lambda",
                format!("must be a finite number > 0, got {lambda}"),
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

    /// `lambda` = [`DEFAULT_RELATIVE_LAMBDA`] x the mean prior variance
    /// (at least 1e-12).
    pub fn default_lambda(dist: &WeightDistribution) -> f64 {
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
    fn non_positive_lambda_is_rejected_with_the_field() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 3).unwrap();
        for bad in [0.0, -1.0, f64::NAN] {
            let e = Whitening::new(&dist, bad).unwrap_err();
            assert_eq!(e.field(), Some("options.lambda"));
        }
    }
}
