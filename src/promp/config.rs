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
        if !(2..=MAX_SAMPLES).contains(&self.n_samples) {
            return Err(Error::invalid(
                "n_samples",
                format!("must be in 2..={MAX_SAMPLES}, got {}", self.n_samples),
            ));
        }
        Ok(())
    }
}
