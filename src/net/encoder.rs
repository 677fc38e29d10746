//! The image encoder: conv blocks (3x3 conv, LeakyReLU, 2x2 max-pool,
//! batch-norm; the paper's order), flatten, then one linear layer to the
//! latent vector (two, mu and log-variance, for variational encoders).

use super::config::ModelConfig;
use super::conv::Conv3x3;
use candle_core::{Module, ModuleT, Result, Tensor};
use candle_nn::{BatchNorm, Linear, VarBuilder};

/// One encoder block: conv 3x3 (same padding), LeakyReLU, max-pool 2, batch-norm.
#[derive(Clone, Debug)]
pub struct ConvBlock {
    conv: Conv3x3,
    norm: BatchNorm,
    slope: f64,
}

impl ConvBlock {
    /// Build a block reading `inputs` channels and writing `outputs`.
    pub fn new(inputs: usize, outputs: usize, slope: f64, vb: VarBuilder) -> Result<ConvBlock> {
        Ok(ConvBlock {
            conv: Conv3x3::new(inputs, outputs, vb.pp("conv"))?,
            norm: candle_nn::batch_norm(outputs, 1e-5, vb.pp("bn"))?,
            slope,
        })
    }

    /// `(B, C, H, W) -> (B, C', H/2, W/2)`; `train` selects batch statistics.
    pub fn forward(&self, x: &Tensor, train: bool) -> Result<Tensor> {
        let x = self.conv.forward(x)?;
        let x = super::ops::leaky_relu(&x, self.slope)?;
        let x = x.max_pool2d(2)?;
        self.norm.forward_t(&x, train)
    }
}

/// Encoder output: the latent mean and, for variational encoders, its
/// log-variance.
#[derive(Clone, Debug)]
pub struct Encoded {
    /// `(B, latent_dim)`; the latent vector of deterministic encoders.
    pub mu: Tensor,
    /// `(B, latent_dim)` log sigma^2, variational encoders only.
    pub logvar: Option<Tensor>,
}

/// The convolutional encoder.
#[derive(Clone, Debug)]
pub struct Encoder {
    blocks: Vec<ConvBlock>,
    mu: Linear,
    logvar: Option<Linear>,
}

impl Encoder {
    /// Build from the config under the var-builder prefix given.
    pub fn new(config: &ModelConfig, vb: VarBuilder) -> Result<Encoder> {
        let mut blocks = Vec::with_capacity(config.encoder_channels.len());
        let mut inputs = 3;
        for (i, &outputs) in config.encoder_channels.iter().enumerate() {
            blocks.push(ConvBlock::new(
                inputs,
                outputs,
                config.leaky_slope,
                vb.pp(format!("block{i}")),
            )?);
            inputs = outputs;
        }
        let side = config.encoded_side();
        let flat = inputs * side * side;
        let mu = candle_nn::linear(flat, config.latent_dim, vb.pp("mu"))?;
        let logvar = if config.arch.is_variational() {
            Some(candle_nn::linear(flat, config.latent_dim, vb.pp("logvar"))?)
        } else {
            None
        };
        Ok(Encoder { blocks, mu, logvar })
    }

    /// `(B, 3, S, S)` normalised images to the latent distribution.
    pub fn forward(&self, images: &Tensor, train: bool) -> Result<Encoded> {
        let mut x = images.clone();
        for block in &self.blocks {
            x = block.forward(&x, train)?;
        }
        let flat = x.flatten_from(1)?;
        let mu = self.mu.forward(&flat)?;
        let logvar = match &self.logvar {
            Some(layer) => Some(layer.forward(&flat)?.clamp(-20f32, 10f32)?),
            None => None,
        };
        Ok(Encoded { mu, logvar })
    }
}
