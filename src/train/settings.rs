//! The settings of a training run (`dpmp train`'s flags): the data and
//! output folders, the architecture and its sizes, the phases' epochs and
//! learning rates, early stopping, the loss weights; validated before
//! anything is read or written.

use super::phases::Phase;
use crate::net::{Arch, ModelConfig, Space};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Network size settings (the architecture's free dimensions).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeSettings {
    /// Side of the square input image.
    pub input_size: usize,
    /// Encoder conv block widths.
    pub encoder_channels: Vec<usize>,
    /// Latent size.
    pub latent_dim: usize,
    /// Head hidden layer widths.
    pub head_hidden: Vec<usize>,
}

impl Default for ShapeSettings {
    fn default() -> Self {
        let c = ModelConfig::new("default", Arch::Cvae);
        ShapeSettings {
            input_size: c.preprocess.input_size,
            encoder_channels: c.encoder_channels,
            latent_dim: c.latent_dim,
            head_hidden: c.head_hidden,
        }
    }
}

/// Everything `dpmp train` takes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainSettings {
    /// Dataset directory.
    pub data: PathBuf,
    /// Output model directory.
    pub out: PathBuf,
    /// Architecture.
    pub arch: Arch,
    /// Run tp3 (latent tuning) after tp2.
    pub latent_tuning: bool,
    /// Condition the cVAE on the target's measured depth as well as the
    /// box centre (the dataset must have depth).
    pub depth_condition: bool,
    /// The space of the predicted weights (`--space`).
    pub space: Space,
    /// Seed of every random choice.
    pub seed: u64,
    /// Maximum epochs of tp1.
    pub epochs_tp1: usize,
    /// Maximum epochs of tp2 (and of the Direct model's single phase).
    pub epochs_tp2: usize,
    /// Maximum epochs of tp3.
    pub epochs_tp3: usize,
    /// Mini-batch size.
    pub batch: usize,
    /// Peak learning rate (cosine decay to `lr * lr_final_ratio`).
    pub lr: f64,
    /// Final learning rate as a fraction of `lr`.
    pub lr_final_ratio: f64,
    /// Covariance weight of Eq. 7 / Eq. 8.
    pub alpha: f64,
    /// KL weight of tp1 for variational encoders.
    pub kl_weight: f64,
    /// Weight of the task-space term (see [`super::tcp_loss`]) in the
    /// phases that train the heads or tune the latent; 0 leaves it out.
    pub tcp_weight: f64,
    /// Weight of the start term (per rad² of the mean's error at the first
    /// phase sample) in the same phases; 0 leaves it out.
    pub start_weight: f64,
    /// Dropout rate on the latent features while the heads train (tp2,
    /// Direct), so they cannot lean on a few latent coordinates of each
    /// training plant; 0 turns it off.
    pub latent_dropout: f64,
    /// Epochs without validation improvement before a phase stops.
    pub patience: usize,
    /// Continue from `out/train_state` if present.
    pub resume: bool,
    /// Show progress bars.
    pub progress: bool,
    /// Network size.
    pub shape: ShapeSettings,
    /// Stop (resumably) after this many epochs in this invocation; `None`
    /// runs to the end. Simulates an interruption in tests.
    pub stop_after_epochs: Option<usize>,
}

impl TrainSettings {
    /// The authors' reference values (batch 5, learning rate 1e-4).
    pub fn new(data: &Path, out: &Path, arch: Arch) -> TrainSettings {
        TrainSettings {
            data: data.to_path_buf(),
            out: out.to_path_buf(),
            arch,
            latent_tuning: false,
            depth_condition: false,
            space: Space::Joint,
            seed: 0,
            epochs_tp1: 30,
            epochs_tp2: 60,
            epochs_tp3: 20,
            batch: 5,
            lr: 1e-4,
            lr_final_ratio: 0.1,
            alpha: 1.0,
            kl_weight: 1e-3,
            tcp_weight: 0.0,
            start_weight: 0.0,
            latent_dropout: 0.0,
            patience: 10,
            resume: false,
            progress: true,
            shape: ShapeSettings::default(),
            stop_after_epochs: None,
        }
    }

    /// Check the settings; errors name the flag.
    pub fn validate(&self) -> Result<()> {
        if self.batch == 0 || self.batch > 4096 {
            return Err(Error::invalid("batch", "must be in 1..=4096"));
        }
        for (name, v) in [("lr", self.lr), ("lr_final_ratio", self.lr_final_ratio)] {
            if !(v.is_finite() && v > 0.0 && v <= 1.0) {
                return Err(Error::invalid(name, format!("must be in (0, 1], got {v}")));
            }
        }
        for (name, v) in [
            ("alpha", self.alpha),
            ("kl_weight", self.kl_weight),
            ("tcp_weight", self.tcp_weight),
            ("start_weight", self.start_weight),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(
                    name,
                    format!("must be finite and >= 0, got {v}"),
                ));
            }
        }
        if !(self.latent_dropout.is_finite() && (0.0..1.0).contains(&self.latent_dropout)) {
            return Err(Error::invalid(
                "latent_dropout",
                format!("must be in [0, 1), got {}", self.latent_dropout),
            ));
        }
        if self.space == Space::Task {
            for (name, v) in [
                ("tcp_weight", self.tcp_weight),
                ("start_weight", self.start_weight),
            ] {
                if v != 0.0 {
                    return Err(Error::invalid(
                        name,
                        "is a joint-space term; a task-space model trains on the paper's losses (Eq. 7 / Eq. 8) alone",
                    ));
                }
            }
        }
        if self.patience == 0 {
            return Err(Error::invalid("patience", "must be at least 1"));
        }
        if self.depth_condition && !self.arch.is_conditional() {
            return Err(Error::invalid(
                "depth_condition",
                "only the cvae architecture reads a condition",
            ));
        }
        if self.latent_tuning && self.arch == Arch::Direct {
            return Err(Error::invalid(
                "latent_tuning",
                "the direct model has no separate encoder to tune",
            ));
        }
        Ok(())
    }

    /// The phases this run trains, in order.
    pub fn phases(&self) -> Vec<Phase> {
        match (self.arch, self.latent_tuning) {
            (Arch::Direct, _) => vec![Phase::Direct],
            (_, false) => vec![Phase::Tp1, Phase::Tp2],
            (_, true) => vec![Phase::Tp1, Phase::Tp2, Phase::Tp3],
        }
    }

    pub(super) fn epochs(&self, phase: Phase) -> usize {
        match phase {
            Phase::Tp1 => self.epochs_tp1,
            Phase::Tp2 | Phase::Direct => self.epochs_tp2,
            Phase::Tp3 => self.epochs_tp3,
        }
    }

    /// Settings that must match for a resume (epoch counts may change, and
    /// a finished run without latent tuning may be extended by tp3: its
    /// tp1 and tp2 are exactly those of the run with latent tuning).
    pub(super) fn fingerprint(&self, manifest_sha256: &str) -> String {
        format!(
            "{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{:?}|{}{}",
            self.arch.as_str(),
            self.seed,
            self.batch,
            self.lr,
            self.alpha,
            self.kl_weight,
            self.tcp_weight,
            self.start_weight,
            self.latent_dropout,
            self.lr_final_ratio,
            self.shape,
            manifest_sha256,
            // Joint-space runs keep the fingerprint they had before spaces.
            if self.space == Space::Task {
                "|task"
            } else {
                ""
            }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_validation_names_the_flag() {
        let mut s = TrainSettings::new(Path::new("d"), Path::new("o"), Arch::Direct);
        s.latent_tuning = true;
        assert_eq!(s.validate().unwrap_err().field(), Some("latent_tuning"));
        let mut s = TrainSettings::new(Path::new("d"), Path::new("o"), Arch::Ae);
        s.lr = f64::NAN;
        assert_eq!(s.validate().unwrap_err().field(), Some("lr"));
        assert_eq!(s.phases().len(), 2);
    }
}
