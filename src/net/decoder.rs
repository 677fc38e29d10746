//! The image decoder used by tp1 (reconstruction): linear layer to the
//! encoder's final feature map, then per block nearest-neighbour upsampling,
//! 3x3 conv and LeakyReLU, and a final 3x3 conv with tanh (images are
//! normalised to [-1, 1]).

use super::config::ModelConfig;
use super::conv::Conv3x3;
use candle_core::{Module, Result, Tensor};
use candle_nn::{Linear, VarBuilder};

/// The convolutional decoder (mirror of the encoder).
#[derive(Clone, Debug)]
pub struct Decoder {
    fc: Linear,
    ups: Vec<Conv3x3>,
    out: Conv3x3,
    channels: usize,
    side: usize,
    slope: f64,
}

impl Decoder {
    /// Build from the config; it reads the head feature vector (latent,
    /// plus the condition for the cVAE).
    pub fn new(config: &ModelConfig, vb: VarBuilder) -> Result<Decoder> {
        let side = config.encoded_side();
        let mut channels: Vec<usize> = config.encoder_channels.iter().rev().copied().collect();
        let first = channels[0];
        let fc = candle_nn::linear(config.feature_dim(), first * side * side, vb.pp("fc"))?;
        channels.push(channels[channels.len() - 1]);
        let mut ups = Vec::with_capacity(config.encoder_channels.len());
        for i in 0..config.encoder_channels.len() {
            ups.push(Conv3x3::new(
                channels[i],
                channels[i + 1],
                vb.pp(format!("up{i}")),
            )?);
        }
        let last = channels[channels.len() - 1];
        let out = Conv3x3::new(last, 3, vb.pp("out"))?;
        Ok(Decoder {
            fc,
            ups,
            out,
            channels: first,
            side,
            slope: config.leaky_slope,
        })
    }

    /// `(B, F)` features to `(B, 3, S, S)` reconstructed images in [-1, 1].
    pub fn forward(&self, features: &Tensor) -> Result<Tensor> {
        let batch = features.dim(0)?;
        let x = self.fc.forward(features)?;
        let mut x = super::ops::leaky_relu(&x, self.slope)?.reshape((
            batch,
            self.channels,
            self.side,
            self.side,
        ))?;
        for conv in &self.ups {
            x = super::ops::upsample2x(&x)?;
            x = super::ops::leaky_relu(&conv.forward(&x)?, self.slope)?;
        }
        self.out.forward(&x)?.tanh()
    }
}
