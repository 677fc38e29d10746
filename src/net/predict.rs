//! The inference API: [`Model::load`] a model directory (or take the
//! embedded [`Model::shipped`]), then
//! [`Model::predict`] an image (any size) and target box into the 56-dim
//! ProMP weight prior (block-diagonal covariance) and the latent vector.

use super::checkpoint;
use super::config::ModelConfig;
use super::heads::HeadOutput;
use super::models::Network;
use super::preprocess::{self, Prepared};
use crate::promp::codec::{decode_covariance, DiagEncoding};
use crate::promp::WeightDistribution;
use crate::{Error, Result};
use candle_core::{Device, Tensor};
use nalgebra::{DMatrix, DVector};
use std::path::Path;

/// A loaded network ready for inference (CPU). `Send + Sync`.
#[derive(Clone, Debug)]
pub struct Model {
    network: Network,
    /// Where it was loaded from: a folder, `shipped` or `in memory`.
    source: String,
}

/// What the network predicts for one image.
#[derive(Clone, Debug)]
pub struct Prediction {
    /// Joint-major weight distribution (`n_joints * n_basis` mean,
    /// block-diagonal covariance, one block per joint).
    pub distribution: WeightDistribution,
    /// The latent vector (the encoder mean).
    pub latent: Vec<f32>,
}

/// Where the shipped model's files live in the repository; the binary
/// carries a copy of them ([`Model::shipped`]).
pub const SHIPPED_MODEL_DIR: &str = "models/default";

/// [`Model::source`] of the embedded shipped model.
pub const SHIPPED_SOURCE: &str = "shipped";

/// The shipped model's config, embedded at build time.
const SHIPPED_CONFIG: &str = include_str!("../../models/default/config.json");
/// The shipped model's weights, embedded at build time.
const SHIPPED_WEIGHTS: &[u8] = include_bytes!("../../models/default/model.safetensors");

impl Model {
    /// Load `dir/model.safetensors` and `dir/config.json` onto the CPU.
    pub fn load(dir: &Path) -> Result<Model> {
        Ok(Model {
            network: checkpoint::load(dir, &Device::Cpu)?,
            source: dir.display().to_string(),
        })
    }

    /// The shipped model (`models/default` of the source tree), embedded in
    /// the binary like the Panda, so it is found from any working folder.
    pub fn shipped() -> Result<Model> {
        let dir = Path::new(SHIPPED_MODEL_DIR);
        Ok(Model {
            network: checkpoint::load_bytes(dir, SHIPPED_CONFIG, SHIPPED_WEIGHTS, &Device::Cpu)?,
            source: SHIPPED_SOURCE.to_string(),
        })
    }

    /// `dir` when given (it must load), else the shipped model.
    pub fn load_or_shipped(dir: Option<&Path>) -> Result<Model> {
        match dir {
            Some(dir) => Model::load(dir),
            None => Model::shipped(),
        }
    }

    /// Wrap an in-memory network (e.g. right after training).
    pub fn from_network(network: Network) -> Model {
        Model {
            network,
            source: "in memory".to_string(),
        }
    }

    /// Where the model came from: its folder, [`SHIPPED_SOURCE`] for the
    /// embedded one, or `in memory`.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        &self.network.config().name
    }

    /// The model's configuration.
    pub fn config(&self) -> &ModelConfig {
        self.network.config()
    }

    /// The underlying network.
    pub fn network(&self) -> &Network {
        &self.network
    }

    /// Preprocess exactly as in training (see [`preprocess::prepare`]).
    pub fn preprocess(
        &self,
        image: &image::DynamicImage,
        target_box: [f64; 4],
        mask_applied: bool,
    ) -> Result<Prepared> {
        let config = &self.config().preprocess;
        match image.as_rgb8() {
            Some(rgb) => preprocess::prepare(rgb, target_box, mask_applied, config),
            None => preprocess::prepare(&image.to_rgb8(), target_box, mask_applied, config),
        }
    }

    /// Predict the weight prior for an image and its target box
    /// `[x1, y1, x2, y2]` in that image's pixels. `mask_applied` says the
    /// caller already painted the box white.
    pub fn predict(
        &self,
        image: &image::DynamicImage,
        target_box: [f64; 4],
        mask_applied: bool,
    ) -> Result<Prediction> {
        self.predict_with_depth(image, target_box, mask_applied, None)
    }

    /// [`Model::predict`] with the target's depth (m, camera z of the berry
    /// centre) for a model conditioned on it; a depth-conditioned model
    /// without one is an error naming the depth input.
    pub fn predict_with_depth(
        &self,
        image: &image::DynamicImage,
        target_box: [f64; 4],
        mask_applied: bool,
        depth_m: Option<f64>,
    ) -> Result<Prediction> {
        let mut prepared = self.preprocess(image, target_box, mask_applied)?;
        prepared.depth_m = depth_m;
        let mut out = self.predict_prepared(std::slice::from_ref(&prepared))?;
        out.pop()
            .ok_or_else(|| Error::Numerical("empty prediction batch".into()))
    }

    /// The raw network outputs of a non-empty batch: latent `(B, latent)` and
    /// the heads' means and covariance codes.
    pub fn infer_batch(&self, batch: &[Prepared]) -> Result<(Tensor, HeadOutput)> {
        let (images, conditions) = stack_prepared(batch, self.config(), self.network.device())?;
        self.network
            .infer(&images, &conditions)
            .map_err(candle_error)
    }

    /// Predict a batch of preprocessed inputs.
    pub fn predict_prepared(&self, batch: &[Prepared]) -> Result<Vec<Prediction>> {
        if batch.is_empty() {
            return Ok(Vec::new());
        }
        let (latent, out) = self.infer_batch(batch)?;
        predictions_from_outputs(&latent, &out)
    }
}

/// Stack preprocessed inputs into `(B, 3, S, S)` images and `(B, C)`
/// conditions (`C` = [`ModelConfig::condition_dim`]).
pub fn stack_prepared(
    batch: &[Prepared],
    config: &ModelConfig,
    device: &Device,
) -> Result<(Tensor, Tensor)> {
    let side = config.preprocess.input_size;
    let expected = 3 * side * side;
    let mut pixels = Vec::with_capacity(batch.len() * expected);
    let dim = config.condition_dim();
    let mut conditions = Vec::with_capacity(batch.len() * dim);
    for (i, p) in batch.iter().enumerate() {
        if p.pixels.len() != expected {
            return Err(Error::invalid(
                format!("batch[{i}].pixels"),
                format!("expected {expected} values, got {}", p.pixels.len()),
            ));
        }
        pixels.extend_from_slice(&p.pixels);
        conditions.extend(p.condition_values(config.depth_condition)?);
    }
    let images = Tensor::from_vec(pixels, (batch.len(), 3, side, side), device);
    let conditions = Tensor::from_vec(conditions, (batch.len(), dim), device);
    Ok((
        images.map_err(candle_error)?,
        conditions.map_err(candle_error)?,
    ))
}

/// Convert raw batch outputs to predictions.
pub fn predictions_from_outputs(latent: &Tensor, out: &HeadOutput) -> Result<Vec<Prediction>> {
    let latent = latent.to_vec2::<f32>().map_err(candle_error)?;
    let means = out.mean.to_vec3::<f32>().map_err(candle_error)?;
    let codes = out.code.to_vec3::<f32>().map_err(candle_error)?;
    latent
        .into_iter()
        .zip(means.iter().zip(&codes))
        .map(|(latent, (mean, code))| {
            Ok(Prediction {
                distribution: distribution_from_outputs(mean, code)?,
                latent,
            })
        })
        .collect()
}

/// Per-joint means and log-diagonal codes to a block-diagonal distribution
/// (decoded in f64 by [`crate::promp::codec`]).
pub fn distribution_from_outputs(
    means: &[Vec<f32>],
    codes: &[Vec<f32>],
) -> Result<WeightDistribution> {
    let mut mean_blocks = Vec::with_capacity(means.len());
    let mut cov_blocks = Vec::with_capacity(means.len());
    for (j, (mean, code)) in means.iter().zip(codes).enumerate() {
        let mean: Vec<f64> = mean.iter().map(|&v| f64::from(v)).collect();
        let code: Vec<f64> = code.iter().map(|&v| f64::from(v)).collect();
        crate::error::ensure_finite(&format!("prediction.joint{j}.mean"), &mean)?;
        crate::error::ensure_finite(&format!("prediction.joint{j}.code"), &code)?;
        let cov: DMatrix<f64> = decode_covariance(&code, DiagEncoding::Log)?;
        mean_blocks.push(DVector::from_vec(mean));
        cov_blocks.push(cov);
    }
    WeightDistribution::from_joint_blocks(&mean_blocks, &cov_blocks)
}

/// Map a candle error to the crate error.
pub fn candle_error(e: candle_core::Error) -> Error {
    Error::Numerical(format!("tensor computation failed: {e}"))
}
