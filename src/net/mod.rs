//! The dPMP network in candle: preprocessing, encoder / decoder / per-joint
//! heads for the AE, VAE, cVAE and Direct architectures, the covariance
//! code decoded with tensor ops, checkpoints (safetensors + config.json)
//! and the inference API ([`Model`], [`Prediction`]).
//!
//! ```no_run
//! # fn main() -> dpmp::Result<()> {
//! let model = dpmp::net::Model::load(std::path::Path::new("models/default"))?;
//! let image = image::open("scene.png").map_err(|e| dpmp::Error::file("scene.png", e.to_string()))?;
//! let prediction = model.predict(&image, [300.0, 200.0, 340.0, 250.0], false)?;
//! assert_eq!(prediction.distribution.mean.len(), 56);
//! # Ok(()) }
//! ```

pub mod checkpoint;
pub mod config;
pub mod conv;
pub mod covariance;
pub mod decoder;
pub mod encoder;
pub mod heads;
pub mod models;
pub mod ops;
pub mod predict;
pub mod preprocess;
pub mod resize;
#[cfg(test)]
mod test_support;

pub use config::{Arch, ModelConfig, OutputNorm, Space, TaskPriorSettings};
pub use covariance::CovarianceDecoder;
pub use models::{Network, ParamGroup};
pub use predict::{candle_error, Model, Prediction};
pub use preprocess::{prepare, Prepared, PreprocessConfig};
