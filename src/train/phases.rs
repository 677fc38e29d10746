//! The training phases and their losses:
//!
//! - `tp1`: encoder + decoder on image reconstruction (+ KL for VAE/cVAE);
//! - `tp2`: heads only on Eq. 7, encoder frozen — its outputs are computed
//!   once per phase (evaluation mode) and cached, variational latents
//!   re-sampled every batch;
//! - `tp3`: latent tuning, encoder only on Eq. 8 with the heads frozen;
//! - `direct`: encoder + heads end to end on Eq. 7 (the Direct baseline).

use super::data::{make_batch, target_tensors, Sample};
use super::losses::TrajectoryOperator;
use super::tcp_loss::TcpLoss;
use crate::net::{candle_error, Network, ParamGroup};
use crate::Result;
use candle_core::{Device, Tensor};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// A training phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Reconstruction.
    Tp1,
    /// Heads on Eq. 7.
    Tp2,
    /// Latent tuning on Eq. 8.
    Tp3,
    /// End to end on Eq. 7.
    Direct,
}

impl Phase {
    /// `tp1`, `tp2`, `tp3`, `direct`.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Tp1 => "tp1",
            Phase::Tp2 => "tp2",
            Phase::Tp3 => "tp3",
            Phase::Direct => "direct",
        }
    }

    /// The parameter groups the phase trains.
    pub fn groups(self) -> &'static [ParamGroup] {
        match self {
            Phase::Tp1 => &[ParamGroup::Encoder, ParamGroup::Decoder],
            Phase::Tp2 => &[ParamGroup::Heads],
            Phase::Tp3 => &[ParamGroup::Encoder],
            Phase::Direct => &[ParamGroup::Encoder, ParamGroup::Heads],
        }
    }

    /// Small stable number used to derive per-epoch random streams.
    pub fn id(self) -> u64 {
        match self {
            Phase::Tp1 => 1,
            Phase::Tp2 => 2,
            Phase::Tp3 => 3,
            Phase::Direct => 4,
        }
    }
}

/// Loss weights shared by the phases.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossWeights {
    /// Covariance weight in Eq. 7 / Eq. 8.
    pub alpha: f64,
    /// KL weight in tp1 (variational encoders).
    pub kl_weight: f64,
    /// Weight of the task-space term ([`super::tcp_loss`]).
    pub tcp_weight: f64,
    /// Weight of the start term ([`TrajectoryOperator::start_loss`], per rad²).
    pub start_weight: f64,
    /// Dropout rate on the latent the heads read (training batches of tp2
    /// and Direct only).
    pub latent_dropout: f64,
}

/// Encoder outputs cached for tp2 (the encoder is frozen there).
#[derive(Clone, Debug)]
pub struct LatentCache {
    mu: Tensor,
    logvar: Option<Tensor>,
}

/// Everything a phase step reads.
pub struct PhaseContext<'a> {
    /// The network being trained.
    pub network: &'a Network,
    /// The trajectory-loss operator of the model's basis.
    pub op: &'a TrajectoryOperator,
    /// The task-space term, when its weight is positive.
    pub tcp: Option<&'a TcpLoss>,
    /// Loss weights.
    pub weights: LossWeights,
    /// Training samples.
    pub train: &'a [Sample],
    /// Validation samples.
    pub val: &'a [Sample],
    /// tp2 only: cached encoder outputs of the train and val samples.
    pub cache: Option<(LatentCache, LatentCache)>,
}

/// Which sample set a loss is computed on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// The training samples.
    Train,
    /// The validation samples.
    Val,
}

/// Batch size used for evaluation-mode passes.
const EVAL_BATCH: usize = 16;

impl<'a> PhaseContext<'a> {
    fn device(&self) -> &Device {
        self.network.device()
    }

    /// Encode every sample in evaluation mode (for the tp2 cache).
    pub fn encode_all(network: &Network, samples: &[Sample]) -> Result<LatentCache> {
        let mut mus = Vec::new();
        let mut logvars = Vec::new();
        let indices: Vec<usize> = (0..samples.len()).collect();
        for chunk in indices.chunks(EVAL_BATCH) {
            let batch = make_batch(samples, chunk, network.config(), network.device())?;
            let enc = network.encode(&batch.images, false).map_err(candle_error)?;
            // Detached: tp2 must not back-propagate into the frozen encoder
            // (that would redo the encoder's backward pass on every image at
            // every step).
            mus.push(enc.mu.detach());
            if let Some(lv) = enc.logvar {
                logvars.push(lv.detach());
            }
        }
        let mu = Tensor::cat(&mus, 0).map_err(candle_error)?;
        let logvar = if logvars.is_empty() {
            None
        } else {
            Some(Tensor::cat(&logvars, 0).map_err(candle_error)?)
        };
        Ok(LatentCache { mu, logvar })
    }

    /// The training loss of one batch (train mode, sampled latents).
    pub fn train_loss(
        &self,
        phase: Phase,
        indices: &[usize],
        rng: &mut ChaCha8Rng,
    ) -> Result<Tensor> {
        self.loss(phase, Split::Train, indices, Some(rng), true)
    }

    fn samples(&self, split: Split) -> &'a [Sample] {
        match split {
            Split::Train => self.train,
            Split::Val => self.val,
        }
    }

    /// Mean loss over a whole split in evaluation mode (latent means).
    pub fn eval_loss(&self, phase: Phase, split: Split) -> Result<f64> {
        let samples = self.samples(split);
        if samples.is_empty() {
            return Ok(f64::NAN);
        }
        let indices: Vec<usize> = (0..samples.len()).collect();
        let mut total = 0.0;
        for chunk in indices.chunks(EVAL_BATCH) {
            let loss = self.loss(phase, split, chunk, None, false)?;
            let value = loss.to_scalar::<f32>().map_err(candle_error)?;
            total += f64::from(value) * chunk.len() as f64;
        }
        Ok(total / samples.len() as f64)
    }

    fn loss(
        &self,
        phase: Phase,
        split: Split,
        indices: &[usize],
        rng: Option<&mut ChaCha8Rng>,
        train: bool,
    ) -> Result<Tensor> {
        match phase {
            Phase::Tp2 => self.heads_loss(split, indices, rng),
            _ => self.end_to_end_loss(phase, self.samples(split), indices, rng, train),
        }
    }

    fn end_to_end_loss(
        &self,
        phase: Phase,
        samples: &[Sample],
        indices: &[usize],
        rng: Option<&mut ChaCha8Rng>,
        train: bool,
    ) -> Result<Tensor> {
        let net = self.network;
        let mut rng = rng;
        let batch = make_batch(samples, indices, net.config(), self.device())?;
        let enc = net.encode(&batch.images, train).map_err(candle_error)?;
        let mut z = sample_latent(&enc.mu, enc.logvar.as_ref(), rng.as_deref_mut())?;
        if phase == Phase::Direct {
            z = drop_latent(&z, self.weights.latent_dropout, rng)?;
        }
        let features = net.features(&z, &batch.conditions).map_err(candle_error)?;
        let w = self.weights;
        let loss = match phase {
            Phase::Tp1 => {
                let recon = net
                    .decode(&features)
                    .map_err(candle_error)?
                    .ok_or_else(|| crate::Error::invalid("arch", "tp1 needs a decoder"))?;
                let mut loss = super::losses::reconstruction_loss(&recon, &batch.images);
                if let (Some(lv), true) = (&enc.logvar, w.kl_weight > 0.0) {
                    let kl = super::losses::kl_loss(&enc.mu, lv);
                    loss = loss.and_then(|l| kl.and_then(|k| l + (k * w.kl_weight)?));
                }
                loss
            }
            Phase::Tp3 => {
                let out = net.heads(&features).map_err(candle_error)?;
                let eq8 = self
                    .op
                    .final_step_loss(&out, &batch.mean, &batch.cov, w.alpha)
                    .map(|l| l.total);
                eq8.and_then(|l| self.with_extra_terms(l, &out, &batch.mean))
            }
            Phase::Direct | Phase::Tp2 => {
                let out = net.heads(&features).map_err(candle_error)?;
                let eq7 = self
                    .op
                    .trajectory_loss(&out, &batch.mean, &batch.cov, w.alpha)
                    .map(|l| l.total);
                eq7.and_then(|l| self.with_extra_terms(l, &out, &batch.mean))
            }
        };
        loss.map_err(candle_error)
    }

    /// `loss + tcp_weight * TCP term + start_weight * start term`, each
    /// when its weight is positive.
    fn with_extra_terms(
        &self,
        loss: Tensor,
        out: &crate::net::heads::HeadOutput,
        target_mean: &Tensor,
    ) -> candle_core::Result<Tensor> {
        let w = self.weights;
        let loss = match self.tcp {
            Some(tcp) if w.tcp_weight > 0.0 => {
                (loss + (tcp.loss(&out.mean, target_mean)? * w.tcp_weight)?)?
            }
            _ => loss,
        };
        if w.start_weight > 0.0 {
            loss + (self.op.start_loss(out, target_mean)? * w.start_weight)?
        } else {
            Ok(loss)
        }
    }

    fn heads_loss(
        &self,
        split: Split,
        indices: &[usize],
        rng: Option<&mut ChaCha8Rng>,
    ) -> Result<Tensor> {
        let (train_cache, val_cache) = self
            .cache
            .as_ref()
            .ok_or_else(|| crate::Error::Numerical("tp2 needs the latent cache".into()))?;
        let cache = match split {
            Split::Train => train_cache,
            Split::Val => val_cache,
        };
        let samples = self.samples(split);
        let net = self.network;
        let idx: Vec<u32> = indices.iter().map(|&i| i as u32).collect();
        let idx = Tensor::new(idx.as_slice(), self.device()).map_err(candle_error)?;
        let mu = cache.mu.index_select(&idx, 0).map_err(candle_error)?;
        let logvar = match &cache.logvar {
            Some(lv) => Some(lv.index_select(&idx, 0).map_err(candle_error)?),
            None => None,
        };
        let mut rng = rng;
        let z = sample_latent(&mu, logvar.as_ref(), rng.as_deref_mut())?;
        let z = drop_latent(&z, self.weights.latent_dropout, rng)?;
        let conditions = condition_tensor(samples, indices, net.config(), self.device())?;
        let features = net.features(&z, &conditions).map_err(candle_error)?;
        let out = net.heads(&features).map_err(candle_error)?;
        let (mean, cov) = target_tensors(samples, indices, net.config(), self.device())?;
        self.op
            .trajectory_loss(&out, &mean, &cov, self.weights.alpha)
            .and_then(|l| self.with_extra_terms(l.total, &out, &mean))
            .map_err(candle_error)
    }
}

fn condition_tensor(
    samples: &[Sample],
    indices: &[usize],
    config: &crate::net::ModelConfig,
    device: &Device,
) -> Result<Tensor> {
    let mut values = Vec::with_capacity(indices.len() * config.condition_dim());
    for &i in indices {
        values.extend(
            samples[i]
                .prepared
                .condition_values(config.depth_condition)?,
        );
    }
    Tensor::from_vec(values, (indices.len(), config.condition_dim()), device).map_err(candle_error)
}

/// Inverted dropout on whole latent coordinates: each entry is zeroed with
/// probability `rate` (drawn from `rng`) and the rest scaled by
/// `1 / (1 - rate)`; the latent unchanged without an rng (evaluation) or
/// at rate 0.
pub fn drop_latent(z: &Tensor, rate: f64, rng: Option<&mut ChaCha8Rng>) -> Result<Tensor> {
    let Some(rng) = rng.filter(|_| rate > 0.0) else {
        return Ok(z.clone());
    };
    let keep = (1.0 / (1.0 - rate)) as f32;
    let mask: Vec<f32> = (0..z.elem_count())
        .map(|_| if rng.gen_bool(rate) { 0.0 } else { keep })
        .collect();
    let mask = Tensor::from_vec(mask, z.dims(), z.device()).map_err(candle_error)?;
    (z * mask).map_err(candle_error)
}

/// Reparameterisation: `mu + exp(logvar / 2) * eps` with `eps ~ N(0, I)`
/// drawn from `rng`; the mean when there is no rng or no log-variance.
pub fn sample_latent(
    mu: &Tensor,
    logvar: Option<&Tensor>,
    rng: Option<&mut ChaCha8Rng>,
) -> Result<Tensor> {
    let (Some(lv), Some(rng)) = (logvar, rng) else {
        return Ok(mu.clone());
    };
    let count = mu.elem_count();
    let noise: Vec<f32> = (0..count).map(|_| rng.sample(StandardNormal)).collect();
    let eps = Tensor::from_vec(noise, mu.dims(), mu.device()).map_err(candle_error)?;
    let std = (lv * 0.5).and_then(|t| t.exp()).map_err(candle_error)?;
    (mu + (std * eps).map_err(candle_error)?).map_err(candle_error)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn latent_dropout_zeroes_about_its_rate_and_rescales_the_rest() {
        let z = Tensor::ones((50, 40), candle_core::DType::F32, &Device::Cpu).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let dropped = drop_latent(&z, 0.25, Some(&mut rng)).unwrap();
        let values: Vec<f32> = dropped.flatten_all().unwrap().to_vec1().unwrap();
        let zeros = values.iter().filter(|&&v| v == 0.0).count() as f64 / values.len() as f64;
        assert!((zeros - 0.25).abs() < 0.04, "dropped fraction {zeros}");
        assert!(values
            .iter()
            .all(|&v| v == 0.0 || (v - 1.0 / 0.75).abs() < 1e-6));
        // Evaluation (no rng) and rate 0 leave the latent alone.
        let same = drop_latent(&z, 0.25, None).unwrap();
        assert_eq!(same.to_vec2::<f32>().unwrap(), z.to_vec2::<f32>().unwrap());
        let same = drop_latent(&z, 0.0, Some(&mut rng)).unwrap();
        assert_eq!(same.to_vec2::<f32>().unwrap(), z.to_vec2::<f32>().unwrap());
    }
}
