//! The per-joint MLP head: ONE type, instantiated once per joint. Each reads
//! the feature vector (latent, plus the condition for the cVAE) and writes
//! `n_basis` weight means and the `n_basis (n_basis + 1) / 2` covariance
//! code (log-diagonal), through the fixed output normalisation of the
//! model config.

use super::config::ModelConfig;
use candle_core::{Device, Module, Result, Tensor};
use candle_nn::{Linear, VarBuilder};

/// One joint's MLP: dense layers with LeakyReLU between them.
#[derive(Clone, Debug)]
pub struct JointHead {
    layers: Vec<Linear>,
    slope: f64,
}

impl JointHead {
    /// Build `inputs -> hidden... -> outputs`.
    pub fn new(
        inputs: usize,
        hidden: &[usize],
        outputs: usize,
        slope: f64,
        vb: VarBuilder,
    ) -> Result<JointHead> {
        let mut layers = Vec::with_capacity(hidden.len() + 1);
        let mut width = inputs;
        for (i, &h) in hidden.iter().chain(std::iter::once(&outputs)).enumerate() {
            layers.push(candle_nn::linear(width, h, vb.pp(format!("fc{i}")))?);
            width = h;
        }
        Ok(JointHead { layers, slope })
    }

    /// `(B, inputs) -> (B, outputs)` raw (normalised) outputs.
    pub fn forward(&self, features: &Tensor) -> Result<Tensor> {
        let mut x = features.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(&x)?;
            if i < last {
                x = super::ops::leaky_relu(&x, self.slope)?;
            }
        }
        Ok(x)
    }
}

/// The heads' output in weight space.
#[derive(Clone, Debug)]
pub struct HeadOutput {
    /// `(B, n_joints, n_basis)` weight means.
    pub mean: Tensor,
    /// `(B, n_joints, code_len)` covariance codes (log-diagonal).
    pub code: Tensor,
}

/// All joint heads plus the fixed output normalisation.
#[derive(Clone, Debug)]
pub struct Heads {
    joints: Vec<JointHead>,
    offset: Tensor,
    scale: Tensor,
    n_basis: usize,
    code_len: usize,
}

impl Heads {
    /// Build one head per joint under `joint{j}`.
    pub fn new(config: &ModelConfig, vb: VarBuilder, device: &Device) -> Result<Heads> {
        let outputs = config.head_outputs();
        let joints = (0..config.n_joints)
            .map(|j| {
                JointHead::new(
                    config.feature_dim(),
                    &config.head_hidden,
                    outputs,
                    config.leaky_slope,
                    vb.pp(format!("joint{j}")),
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let shape = (config.n_joints, outputs);
        Ok(Heads {
            joints,
            offset: Tensor::from_slice(&config.output_norm.offset, shape, device)?,
            scale: Tensor::from_slice(&config.output_norm.scale, shape, device)?,
            n_basis: config.promp.n_basis,
            code_len: config.code_len(),
        })
    }

    /// `(B, F)` features to weight means and covariance codes.
    pub fn forward(&self, features: &Tensor) -> Result<HeadOutput> {
        let raw = self
            .joints
            .iter()
            .map(|head| head.forward(features))
            .collect::<Result<Vec<_>>>()?;
        let out = Tensor::stack(&raw, 1)?
            .broadcast_mul(&self.scale)?
            .broadcast_add(&self.offset)?;
        Ok(HeadOutput {
            mean: out.narrow(2, 0, self.n_basis)?,
            code: out.narrow(2, self.n_basis, self.code_len)?,
        })
    }
}
