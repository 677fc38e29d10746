//! The training driver behind `dpmp train`: loads the dataset, builds the
//! model config (output normalisation from the training targets), runs the
//! phases with Adam, a cosine learning-rate schedule and early stopping on
//! the validation split, logs every epoch, checkpoints after every epoch
//! (resumable with identical results), and writes the best model.

use super::adam::{Adam, AdamParams};
use super::data::{load_split, Dataset, Targets};
use super::log::{plot_loss_curves, EpochRecord, MetricsLog};
use super::losses::TrajectoryOperator;
use super::norm::output_norm;
use super::phases::{LossWeights, Phase, PhaseContext, Split};
use super::settings::TrainSettings;
use super::tcp_loss::TcpLoss;
use crate::net::checkpoint::{self, read_tensors, write_atomic, write_tensors};
use crate::net::config::{DatasetInfo, TrainingSummary};
use crate::net::{candle_error, ModelConfig, Network};
use crate::promp::Basis;
use crate::{Error, Result};
use candle_core::{Device, Tensor};
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What a training run produced.
#[derive(Clone, Debug, Serialize)]
pub struct TrainOutcome {
    /// The model directory written.
    pub out: PathBuf,
    /// The training record stored in its config.
    pub summary: TrainingSummary,
}

/// Resume bookkeeping written after every epoch to `out/train_state/`.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct ResumeState {
    fingerprint: String,
    phase_index: usize,
    next_epoch: usize,
    #[serde(with = "infinity_as_null")]
    best_val: f64,
    bad_epochs: usize,
    adam_steps: u64,
    seconds: f64,
    epochs: BTreeMap<String, usize>,
    best_val_loss: BTreeMap<String, f64>,
    tag: String,
}

const STATE_DIR: &str = "train_state";

/// JSON has no infinity: "no best loss yet" (`f64::INFINITY`) is `null`.
mod infinity_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

/// The loss operators of a run.
#[derive(Clone, Copy)]
struct Losses<'a> {
    op: &'a TrajectoryOperator,
    tcp: Option<&'a TcpLoss>,
}

/// Train a model for the shipped Panda as the settings say; the best
/// weights end in `settings.out`.
pub fn train(settings: &TrainSettings) -> Result<TrainOutcome> {
    train_for(settings, &crate::robot::Robot::panda()?)
}

/// Train a model for `robot` (the robot of the dataset's demonstrations:
/// the task-space term uses its kinematics and the model records its
/// identity, so planning with another robot is refused).
pub fn train_for(settings: &TrainSettings, robot: &crate::robot::Robot) -> Result<TrainOutcome> {
    settings.validate()?;
    let device = Device::Cpu;
    let targets = Targets::of(settings.space, robot);
    let train_set = load_split(
        &settings.data,
        "train",
        &default_preprocess(settings),
        targets,
    )?;
    let val_set = load_split(
        &settings.data,
        "val",
        &default_preprocess(settings),
        targets,
    )?;
    check_splits(settings, &train_set, &val_set)?;
    if let Some(identity) = &train_set.robot {
        let name = format!("dataset {}", settings.data.display());
        identity.check(robot, &name)?;
    }
    let mut config = build_config(settings, &train_set, val_set.samples.len())?;
    if settings.space == crate::net::Space::Joint && config.n_joints != robot.dof() {
        return Err(Error::invalid(
            "robot",
            format!(
                "the dataset has {} joints, robot '{}' has {}",
                config.n_joints,
                robot.name(),
                robot.dof()
            ),
        ));
    }
    config.robot = Some(robot.identity());
    let network = Network::new(config, settings.seed, &device).map_err(candle_error)?;
    let basis = Basis::new(&network.config().promp)?;
    let op = TrajectoryOperator::new(&basis, &device).map_err(candle_error)?;
    let tcp = if settings.tcp_weight > 0.0 {
        Some(TcpLoss::new(robot, &basis, &device).map_err(candle_error)?)
    } else {
        None
    };
    let losses = Losses {
        op: &op,
        tcp: tcp.as_ref(),
    };
    let mut run = Run::start(settings, &network, &train_set.manifest_sha256)?;
    let phases = settings.phases();
    for (index, &phase) in phases.iter().enumerate().skip(run.state.phase_index) {
        if !run.phase(index, phase, losses, &train_set, &val_set)? {
            break;
        }
    }
    run.finish()
}

/// Training needs a target in train and one in val (early stopping and
/// the heads' phase are judged on val); say so before anything is written.
fn check_splits(settings: &TrainSettings, train: &Dataset, val: &Dataset) -> Result<()> {
    let (n_train, n_val) = (train.samples.len(), val.samples.len());
    if n_train == 0 || n_val == 0 {
        return Err(Error::invalid(
            "data",
            format!(
                "{} has {n_train} train and {n_val} val targets: training needs at least 1 in each (the splits are by plant; `dpmp data generate` needs about 10 configurations for the default 10 % val fraction, `data import` a --val-fraction that leaves a plant for val)",
                settings.data.display()
            ),
        ));
    }
    Ok(())
}

fn default_preprocess(settings: &TrainSettings) -> crate::net::PreprocessConfig {
    crate::net::PreprocessConfig {
        input_size: settings.shape.input_size,
        ..Default::default()
    }
}

fn build_config(settings: &TrainSettings, train: &Dataset, n_val: usize) -> Result<ModelConfig> {
    let name = settings
        .out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model".into());
    let mut config = ModelConfig::new(&name, settings.arch);
    config.latent_tuning = settings.latent_tuning;
    config.space = settings.space;
    config.depth_condition = settings.depth_condition;
    if settings.depth_condition {
        if let Some(s) = train.samples.iter().find(|s| s.prepared.depth_m.is_none()) {
            return Err(Error::invalid(
                "depth_condition",
                format!(
                    "target {} of {} has no measured depth: generate the data with depth (dpmp-dataset/2)",
                    s.id,
                    settings.data.display()
                ),
            ));
        }
    }
    config.latent_dim = settings.shape.latent_dim;
    config.encoder_channels = settings.shape.encoder_channels.clone();
    config.head_hidden = settings.shape.head_hidden.clone();
    config.preprocess = default_preprocess(settings);
    config.promp = train.promp.clone();
    let n_weights = train.samples[0].distribution.mean.len();
    config.n_joints = n_weights / config.promp.n_basis;
    config.output_norm = output_norm(&train.samples, config.n_joints, config.promp.n_basis)?;
    config.camera = Some(train.camera);
    config.dataset = Some(DatasetInfo {
        dir: settings.data.display().to_string(),
        manifest_sha256: train.manifest_sha256.clone(),
        n_train: train.samples.len(),
        n_val,
    });
    config.validate()?;
    Ok(config)
}

/// Mutable state of one training run.
struct Run<'a> {
    settings: &'a TrainSettings,
    network: &'a Network,
    state: ResumeState,
    log: MetricsLog,
    started: Instant,
    seconds_before: f64,
    pending_adam: Option<(checkpoint::TensorMap, u64)>,
    best: Vec<(String, Tensor)>,
    epochs_run: usize,
}

impl<'a> Run<'a> {
    fn start(settings: &'a TrainSettings, network: &'a Network, manifest: &str) -> Result<Run<'a>> {
        let fingerprint = settings.fingerprint(manifest);
        std::fs::create_dir_all(&settings.out)
            .map_err(|e| Error::file(&settings.out, e.to_string()))?;
        let state_dir = settings.out.join(STATE_DIR);
        let state_path = state_dir.join("state.json");
        let resumed = settings.resume && state_path.exists();
        let log = MetricsLog::open(&settings.out, !resumed)?;
        let mut run = Run {
            settings,
            network,
            state: ResumeState {
                fingerprint: fingerprint.clone(),
                phase_index: 0,
                next_epoch: 0,
                best_val: f64::INFINITY,
                bad_epochs: 0,
                adam_steps: 0,
                seconds: 0.0,
                epochs: BTreeMap::new(),
                best_val_loss: BTreeMap::new(),
                tag: String::new(),
            },
            log,
            started: Instant::now(),
            seconds_before: 0.0,
            pending_adam: None,
            best: snapshot(network)?,
            epochs_run: 0,
        };
        if resumed {
            let state: ResumeState = crate::fsio::read_json(&state_path)?;
            if state.fingerprint != fingerprint {
                return Err(Error::invalid(
                    "resume",
                    format!(
                        "{} was written with other settings or data; rerun without --resume",
                        state_path.display()
                    ),
                ));
            }
            check_resumable_phases(&state, &settings.phases(), &state_path)?;
            let current = state_dir.join(format!("current-{}.safetensors", state.tag));
            checkpoint::assign(network, &read_tensors(&current)?, &current)?;
            let best_path = state_dir.join(format!("best-{}.safetensors", state.tag));
            let best = read_tensors(&best_path)?;
            run.best = best
                .iter()
                .map(|(name, (shape, values))| {
                    Tensor::from_slice(values, shape.as_slice(), network.device())
                        .map(|t| (name.clone(), t))
                        .map_err(candle_error)
                })
                .collect::<Result<Vec<_>>>()?;
            let adam_path = state_dir.join(format!("adam-{}.safetensors", state.tag));
            run.pending_adam = Some((read_tensors(&adam_path)?, state.adam_steps));
            run.seconds_before = state.seconds;
            run.state = state;
        }
        Ok(run)
    }

    fn seconds(&self) -> f64 {
        self.seconds_before + self.started.elapsed().as_secs_f64()
    }

    /// Run (the rest of) one phase; `false` when stopped early by
    /// `stop_after_epochs`.
    fn phase(
        &mut self,
        index: usize,
        phase: Phase,
        losses: Losses,
        train: &Dataset,
        val: &Dataset,
    ) -> Result<bool> {
        let s = self.settings;
        let net = self.network;
        let cache = if phase == Phase::Tp2 {
            Some((
                PhaseContext::encode_all(net, &train.samples)?,
                PhaseContext::encode_all(net, &val.samples)?,
            ))
        } else {
            None
        };
        let ctx = PhaseContext {
            network: net,
            op: losses.op,
            tcp: losses.tcp,
            weights: LossWeights {
                alpha: s.alpha,
                kl_weight: s.kl_weight,
                tcp_weight: s.tcp_weight,
                start_weight: s.start_weight,
                latent_dropout: s.latent_dropout,
            },
            train: &train.samples,
            val: &val.samples,
            cache,
        };
        let mut adam = Adam::new(
            net.trainable(phase.groups()),
            AdamParams {
                lr: s.lr,
                ..Default::default()
            },
        )
        .map_err(candle_error)?;
        if self.state.phase_index == index && self.state.next_epoch > 0 {
            if let Some((map, steps)) = self.pending_adam.take() {
                adam.restore(&map, steps)?;
            }
        } else {
            self.state.phase_index = index;
            self.state.next_epoch = 0;
            self.state.best_val = f64::INFINITY;
            self.state.bad_epochs = 0;
        }
        let epochs = s.epochs(phase);
        let bar = progress_bar(s.progress, epochs, phase);
        bar.set_position(self.state.next_epoch as u64);
        while self.state.next_epoch < epochs && self.state.bad_epochs < s.patience {
            if s.stop_after_epochs
                .is_some_and(|max| self.epochs_run >= max)
            {
                bar.abandon();
                return Ok(false);
            }
            self.epochs_run += 1;
            let epoch = self.state.next_epoch;
            let record = self.epoch(&ctx, &mut adam, phase, epoch, epochs)?;
            bar.set_message(format!(
                "train {:.3e} val {:.3e}",
                record.train_loss, record.val_loss
            ));
            bar.inc(1);
            self.log.append(&record)?;
            self.state.next_epoch += 1;
            self.state
                .epochs
                .insert(phase.name().into(), self.state.next_epoch);
            self.state.adam_steps = adam.steps();
            self.save_state(&adam)?;
        }
        bar.finish();
        restore(net, &self.best)?;
        self.state
            .best_val_loss
            .insert(phase.name().into(), self.state.best_val);
        self.state.phase_index = index + 1;
        self.state.next_epoch = 0;
        self.state.best_val = f64::INFINITY;
        self.state.bad_epochs = 0;
        self.save_state(&adam)?;
        plot_loss_curves(&self.log.records()?, &s.out.join("loss_curves.png"))?;
        Ok(true)
    }

    fn epoch(
        &mut self,
        ctx: &PhaseContext,
        adam: &mut Adam,
        phase: Phase,
        epoch: usize,
        epochs: usize,
    ) -> Result<EpochRecord> {
        let s = self.settings;
        let t0 = Instant::now();
        let lr = cosine_lr(s.lr, s.lr * s.lr_final_ratio, epoch, epochs);
        adam.set_lr(lr);
        let mut rng = epoch_rng(s.seed, phase, epoch);
        let mut order: Vec<usize> = (0..ctx.train.len()).collect();
        order.shuffle(&mut rng);
        let mut total = 0.0;
        for chunk in order.chunks(s.batch) {
            let loss = ctx.train_loss(phase, chunk, &mut rng)?;
            let grads = loss.backward().map_err(candle_error)?;
            adam.step(&grads).map_err(candle_error)?;
            let value = f64::from(loss.to_scalar::<f32>().map_err(candle_error)?);
            if !value.is_finite() {
                return Err(Error::Numerical(format!(
                    "{} epoch {epoch}: training loss is {value}; lower --lr",
                    phase.name()
                )));
            }
            total += value * chunk.len() as f64;
        }
        let train_loss = total / ctx.train.len() as f64;
        let val_split = if ctx.val.is_empty() {
            Split::Train
        } else {
            Split::Val
        };
        let val_loss = ctx.eval_loss(phase, val_split)?;
        let improved = val_loss < self.state.best_val;
        if improved {
            self.state.best_val = val_loss;
            self.state.bad_epochs = 0;
            self.best = snapshot(self.network)?;
        } else {
            self.state.bad_epochs += 1;
        }
        Ok(EpochRecord {
            phase: phase.name().into(),
            epoch,
            lr,
            train_loss,
            val_loss,
            improved,
            seconds: t0.elapsed().as_secs_f64(),
        })
    }

    fn summary(&self) -> TrainingSummary {
        let mut best = self.state.best_val_loss.clone();
        if let Some(phase) = self.settings.phases().get(self.state.phase_index) {
            if self.state.best_val.is_finite() {
                best.insert(phase.name().into(), self.state.best_val);
            }
        }
        TrainingSummary {
            seed: self.settings.seed,
            epochs: self.state.epochs.clone(),
            best_val_loss: best,
            batch: self.settings.batch,
            lr: self.settings.lr,
            alpha: self.settings.alpha,
            kl_weight: self.settings.kl_weight,
            tcp_weight: self.settings.tcp_weight,
            start_weight: self.settings.start_weight,
            latent_dropout: self.settings.latent_dropout,
            seconds: self.seconds(),
        }
    }

    /// Write the best weights so far (in `self.best`) as the model directory.
    fn save_model(&self) -> Result<()> {
        let mut config = self.network.config().clone();
        config.training = Some(self.summary());
        write_tensors(
            &self.settings.out.join(checkpoint::WEIGHTS_FILE),
            &self.best,
        )?;
        let text = serde_json::to_string_pretty(&config)
            .map_err(|e| Error::Numerical(format!("cannot serialise config: {e}")))?;
        write_atomic(
            &self.settings.out.join(checkpoint::CONFIG_FILE),
            text.as_bytes(),
        )
    }

    fn save_state(&mut self, adam: &Adam) -> Result<()> {
        let dir = self.settings.out.join(STATE_DIR);
        let old_tag = self.state.tag.clone();
        let tag = format!("p{}e{}", self.state.phase_index, self.state.next_epoch);
        let current = snapshot(self.network)?;
        write_tensors(&dir.join(format!("current-{tag}.safetensors")), &current)?;
        write_tensors(&dir.join(format!("best-{tag}.safetensors")), &self.best)?;
        write_tensors(&dir.join(format!("adam-{tag}.safetensors")), &adam.state())?;
        self.state.tag = tag.clone();
        self.state.seconds = self.seconds();
        let text = serde_json::to_string_pretty(&self.state)
            .map_err(|e| Error::Numerical(format!("cannot serialise state: {e}")))?;
        write_atomic(&dir.join("state.json"), text.as_bytes())?;
        if !old_tag.is_empty() && old_tag != tag {
            for kind in ["current", "best", "adam"] {
                let _ = std::fs::remove_file(dir.join(format!("{kind}-{old_tag}.safetensors")));
            }
        }
        Ok(())
    }

    fn finish(self) -> Result<TrainOutcome> {
        self.save_model()?;
        Ok(TrainOutcome {
            out: self.settings.out.clone(),
            summary: self.summary(),
        })
    }
}

/// A resumed state must only hold phases this run trains (a tp3 run cannot
/// be resumed without `--latent-tuning`).
fn check_resumable_phases(state: &ResumeState, phases: &[Phase], path: &Path) -> Result<()> {
    let names: Vec<&str> = phases.iter().map(|p| p.name()).collect();
    if let Some(extra) = state.epochs.keys().find(|k| !names.contains(&k.as_str())) {
        return Err(Error::invalid(
            "resume",
            format!(
                "{} already trained phase {extra}, which these settings do not run (--latent-tuning?)",
                path.display()
            ),
        ));
    }
    if state.phase_index > phases.len() {
        return Err(Error::invalid(
            "resume",
            format!("{} is past the phases of these settings", path.display()),
        ));
    }
    Ok(())
}

fn progress_bar(show: bool, epochs: usize, phase: Phase) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(epochs as u64);
    let style = ProgressStyle::with_template("{prefix:>6} [{bar:30}] {pos}/{len} {elapsed} {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_prefix(phase.name());
    bar
}

/// Cosine decay from `hi` (epoch 0) to `lo` (last epoch).
pub fn cosine_lr(hi: f64, lo: f64, epoch: usize, epochs: usize) -> f64 {
    if epochs <= 1 {
        return hi;
    }
    let x = epoch as f64 / (epochs - 1) as f64;
    lo + 0.5 * (hi - lo) * (1.0 + (std::f64::consts::PI * x).cos())
}

/// The random stream of one epoch of one phase (shuffling and noise).
pub fn epoch_rng(seed: u64, phase: Phase, epoch: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(phase.id() << 32 | epoch as u64);
    rng
}

fn snapshot(network: &Network) -> Result<Vec<(String, Tensor)>> {
    network
        .named_vars()
        .into_iter()
        .map(|(name, var)| {
            var.as_tensor()
                .copy()
                .map(|t| (name, t))
                .map_err(candle_error)
        })
        .collect()
}

fn restore(network: &Network, tensors: &[(String, Tensor)]) -> Result<()> {
    let vars = network.named_vars();
    for (name, tensor) in tensors {
        let var = vars
            .iter()
            .find(|(n, _)| n == name)
            .ok_or_else(|| Error::Numerical(format!("snapshot has unknown tensor {name}")))?;
        var.1.set(tensor).map_err(candle_error)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_schedule_ends_where_it_should() {
        assert_eq!(cosine_lr(1.0, 0.1, 0, 10), 1.0);
        assert!((cosine_lr(1.0, 0.1, 9, 10) - 0.1).abs() < 1e-12);
        assert!((cosine_lr(1.0, 0.0, 5, 11) - 0.5).abs() < 1e-12);
    }
}
