//! ProMP settings shared by fitting, the network and the optimiser.

use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// Basis settings: the authors' code uses 8 basis functions of width 0.07
/// on 150 phase samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrompConfig {
    /// Number of basis functions per joint.
    #[serde(default = "default_n_basis")]
    pub n_basis: usize,
    /// Width `h` of each Gaussian, `exp(-(z - c)^2 / (2 h))`, in phase units.
    #[serde(default = "default_width")]
    pub width: f64,
    /// Number of phase samples `T` on `[0, 1]`.
    #[serde(default = "default_n_samples")]
    pub n_samples: usize,
}

fn default_n_basis() -> usize {
    8
}
fn default_width() -> f64 {
    0.07
}
fn default_n_samples() -> usize {
    150
}

/// Largest accepted number of basis functions per joint.
pub const MAX_BASIS: usize = 64;
/// Largest accepted number of phase samples.
pub const MAX_SAMPLES: usize = 10_000;

impl Default for PrompConfig {
    fn default() -> Self {
        PrompConfig {
            n_basis: default_n_basis(),
            width: default_width(),
            n_samples: default_n_samples(),
        }
    }
}

impl PrompConfig {
    /// Check ranges; errors name `n_basis`, `width` or `n_samples`.
    pub fn validate(&self) -> Result<()> {
        if !(2..=MAX_BASIS).contains(&self.n_basis) {
            return Err(Error::invalid(
                "n_basis",
                format!("must be in 2..={MAX_BASIS}, got {}", self.n_basis),
            ));
        }
        if !self.width.is_finite() || self.width <= 0.0 || self.width > 10.0 {
            return Err(Error::invalid(
                "width",
                format!("must be a finite number in (0, 10], got {}", self.width),
            ));
        }
        let narrowest = self.narrowest_width();
        if self.width < narrowest {
            return Err(Error::invalid(
                "width",
                format!(
                    "must be at least {narrowest:.3e} with {} basis functions (each Gaussian's standard deviation at least a quarter of the spacing of their centres, so that they overlap), got {}",
                    self.n_basis, self.width
                ),
            ));
        }
        if !(2..=MAX_SAMPLES).contains(&self.n_samples) {
            return Err(Error::invalid(
                "n_samples",
                format!("must be in 2..={MAX_SAMPLES}, got {}", self.n_samples),
            ));
        }
        let fewest = self.fewest_samples();
        if self.n_samples < fewest {
            return Err(Error::invalid(
                "n_samples",
                format!(
                    "must be at least {fewest} for width {} (one phase sample per Gaussian standard deviation, so that the samples see every basis function's rise and fall), got {}",
                    self.width, self.n_samples
                ),
            ));
        }
        Ok(())
    }

    /// The smallest accepted `width` for `n_basis` functions: standard
    /// deviation `sqrt(width)` at least a quarter of the centre spacing
    /// `1 / (n_basis - 1)`. Narrower Gaussians leave phases where every
    /// basis function underflows (the normalised basis is then NaN) and
    /// motions that jump between samples.
    pub fn narrowest_width(&self) -> f64 {
        let spacing = 1.0 / (self.n_basis.max(2) - 1) as f64;
        (spacing / 4.0).powi(2)
    }

    /// The fewest accepted phase samples for `width`: one per standard
    /// deviation of the Gaussians.
    pub fn fewest_samples(&self) -> usize {
        let sigma = self.width.max(f64::MIN_POSITIVE).sqrt();
        ((1.0 / sigma).ceil() as usize + 1).max(2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussians_must_overlap_and_the_samples_must_see_them() {
        assert!(PrompConfig::default().validate().is_ok());
        // The probe's widths: the subnormal one hung the basis' SVD.
        for width in [5e-324, 1e-6] {
            let c = PrompConfig {
                width,
                ..Default::default()
            };
            assert_eq!(c.validate().unwrap_err().field(), Some("width"), "{width}");
        }
        let c = PrompConfig {
            n_basis: 8,
            ..Default::default()
        };
        let at_min = PrompConfig {
            width: c.narrowest_width(),
            n_samples: 2000,
            ..c.clone()
        };
        assert!(at_min.validate().is_ok());
        let few = PrompConfig {
            n_samples: 3,
            ..Default::default()
        };
        assert_eq!(few.validate().unwrap_err().field(), Some("n_samples"));
        // Every accepted width gives a finite, normalised basis.
        for n_basis in [2, 8, 64] {
            let mut c = PrompConfig {
                n_basis,
                ..Default::default()
            };
            c.width = c.narrowest_width();
            c.n_samples = c.fewest_samples().max(150);
            c.validate().unwrap();
            let basis = crate::promp::Basis::new(&c).unwrap();
            assert!(basis.matrix().iter().all(|v| v.is_finite()), "{n_basis}");
        }
    }
}
