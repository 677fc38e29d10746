//! The four architectures (AE, VAE, cVAE, Direct) as one [`Network`]:
//! encoder, optional decoder, per-joint heads, all parameters in one
//! [`VarMap`] under the prefixes `encoder.`, `decoder.` and `heads.`.
//! Parameters are initialised deterministically from a seed (ChaCha), not
//! from candle's unseeded CPU generator.

use super::config::ModelConfig;
use super::decoder::Decoder;
use super::encoder::{Encoded, Encoder};
use super::heads::{HeadOutput, Heads};
use candle_core::{DType, Device, Result, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Which parameter group a training phase updates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamGroup {
    /// `encoder.*`
    Encoder,
    /// `decoder.*`
    Decoder,
    /// `heads.*`
    Heads,
}

impl ParamGroup {
    /// The var-map prefix of the group.
    pub fn prefix(self) -> &'static str {
        match self {
            ParamGroup::Encoder => "encoder.",
            ParamGroup::Decoder => "decoder.",
            ParamGroup::Heads => "heads.",
        }
    }
}

/// A dPMP network of any architecture.
#[derive(Clone)]
pub struct Network {
    config: ModelConfig,
    varmap: VarMap,
    encoder: Encoder,
    decoder: Option<Decoder>,
    heads: Heads,
    device: Device,
}

impl std::fmt::Debug for Network {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Network")
            .field("name", &self.config.name)
            .field("arch", &self.config.arch)
            .field("tensors", &self.named_vars().len())
            .finish()
    }
}

impl Network {
    /// Build the network for a (validated) config, initialised from `seed`.
    pub fn new(config: ModelConfig, seed: u64, device: &Device) -> Result<Network> {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
        let encoder = Encoder::new(&config, vb.pp("encoder"))?;
        let decoder = if config.arch.has_decoder() {
            Some(Decoder::new(&config, vb.pp("decoder"))?)
        } else {
            None
        };
        let heads = Heads::new(&config, vb.pp("heads"), device)?;
        let network = Network {
            config,
            varmap,
            encoder,
            decoder,
            heads,
            device: device.clone(),
        };
        network.initialise(seed)?;
        Ok(network)
    }

    /// The configuration the network was built from.
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// The device tensors live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Every parameter and batch-norm statistic, by name.
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }

    /// Sorted `(name, var)` pairs (deterministic order).
    pub fn named_vars(&self) -> Vec<(String, Var)> {
        let data = self
            .varmap
            .data()
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let mut vars: Vec<(String, Var)> =
            data.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        vars
    }

    /// The trainable parameters of the given groups (batch-norm running
    /// statistics excluded), in name order.
    pub fn trainable(&self, groups: &[ParamGroup]) -> Vec<(String, Var)> {
        self.named_vars()
            .into_iter()
            .filter(|(name, _)| {
                groups.iter().any(|g| name.starts_with(g.prefix())) && !is_running_stat(name)
            })
            .collect()
    }

    /// Encode normalised images `(B, 3, S, S)`.
    pub fn encode(&self, images: &Tensor, train: bool) -> Result<Encoded> {
        self.encoder.forward(images, train)
    }

    /// The vector the heads and decoder read: latent, plus the condition
    /// `(B, 2)` for the cVAE.
    pub fn features(&self, latent: &Tensor, condition: &Tensor) -> Result<Tensor> {
        if self.config.arch.is_conditional() {
            Tensor::cat(&[latent, condition], 1)
        } else {
            Ok(latent.clone())
        }
    }

    /// Weight means and covariance codes from features.
    pub fn heads(&self, features: &Tensor) -> Result<HeadOutput> {
        self.heads.forward(features)
    }

    /// Reconstructed images from features (architectures with a decoder).
    pub fn decode(&self, features: &Tensor) -> Result<Option<Tensor>> {
        match &self.decoder {
            Some(decoder) => decoder.forward(features).map(Some),
            None => Ok(None),
        }
    }

    /// Inference: images and conditions to (latent, head output), batch-norm
    /// in evaluation mode and the latent mean for variational encoders.
    pub fn infer(&self, images: &Tensor, condition: &Tensor) -> Result<(Tensor, HeadOutput)> {
        let encoded = self.encode(images, false)?;
        let features = self.features(&encoded.mu, condition)?;
        let out = self.heads(&features)?;
        Ok((encoded.mu, out))
    }

    /// Re-draw every parameter from a ChaCha stream seeded by `seed`, in
    /// name order: weights uniform in `+-1/sqrt(fan_in)`, biases zero,
    /// batch-norm scale one, running statistics (0, 1).
    pub fn initialise(&self, seed: u64) -> Result<()> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for (name, var) in self.named_vars() {
            let dims = var.dims().to_vec();
            let count: usize = dims.iter().product();
            let values: Vec<f32> = if name.ends_with("running_var") {
                vec![1.0; count]
            } else if name.ends_with("bias") || name.ends_with("running_mean") {
                vec![0.0; count]
            } else if dims.len() == 1 {
                vec![1.0; count]
            } else {
                let fan_in: usize = dims[1..].iter().product();
                let bound = 1.0 / (fan_in as f32).sqrt();
                (0..count).map(|_| rng.gen_range(-bound..bound)).collect()
            };
            var.set(&Tensor::from_vec(values, dims, &self.device)?)?;
        }
        Ok(())
    }
}

/// Whether a var is a batch-norm running statistic (not trained by Adam).
pub fn is_running_stat(name: &str) -> bool {
    name.ends_with("running_mean") || name.ends_with("running_var")
}
