//! The ProMP basis flags shared by the subcommands that fit weights.

use crate::promp::PrompConfig;
use crate::Result;

/// `--n-basis`, `--width`, `--n-samples` (the paper's basis by default).
#[derive(Clone, Debug, clap::Args)]
pub struct PrompArgs {
    /// Basis functions per joint.
    #[arg(long, default_value_t = 8)]
    pub n_basis: usize,
    /// Basis width h.
    #[arg(long, default_value_t = 0.07)]
    pub width: f64,
    /// Phase samples T.
    #[arg(long, default_value_t = 150)]
    pub n_samples: usize,
}

impl PrompArgs {
    /// The basis settings, validated (errors name the flag).
    pub fn config(&self) -> Result<PrompConfig> {
        let config = PrompConfig {
            n_basis: self.n_basis,
            width: self.width,
            n_samples: self.n_samples,
        };
        config.validate().map_err(super::as_flag_error)?;
        Ok(config)
    }
}
