//! `dpmp train`: train a dPMP network on a generated dataset.

use crate::net::Arch;
use crate::train::{train_for, TrainSettings};
use std::path::PathBuf;

/// Arguments of `dpmp train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Dataset directory (with manifest.json).
    #[arg(long)]
    pub data: PathBuf,
    /// Architecture: ae, vae, cvae or direct.
    #[arg(long)]
    pub arch: String,
    /// The space of the predicted trajectories: joint (angles) or task (the
    /// TCP's position and quaternion; the paper's second space). A
    /// task-space model plans through IK-tracked draws.
    #[arg(long, default_value = "joint")]
    pub space: String,
    /// Run tp3 (domain-specific latent tuning) after tp2.
    #[arg(long)]
    pub latent_tuning: bool,
    /// Condition the cVAE on the target's measured depth (needs a dataset
    /// with depth); such a model needs depth to plan.
    #[arg(long)]
    pub depth_condition: bool,
    /// Output model directory (e.g. models/NAME).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of initialisation, shuffling and noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Maximum epochs of tp1 (reconstruction) [default: 30].
    #[arg(long)]
    pub epochs_tp1: Option<usize>,
    /// Maximum epochs of tp2 (heads; also the Direct model's only phase)
    /// [default: 60].
    #[arg(long)]
    pub epochs_tp2: Option<usize>,
    /// Maximum epochs of tp3 (latent tuning) [default: 20].
    #[arg(long)]
    pub epochs_tp3: Option<usize>,
    /// Mini-batch size (the authors: 5) [default: 5].
    #[arg(long)]
    pub batch: Option<usize>,
    /// Peak learning rate (the authors: 1e-4), cosine-decayed per phase
    /// [default: 0.0001].
    #[arg(long)]
    pub lr: Option<f64>,
    /// Covariance weight alpha of Eq. 7 / Eq. 8 [default: 1].
    #[arg(long)]
    pub alpha: Option<f64>,
    /// KL weight of tp1 for VAE / cVAE [default: 0.001].
    #[arg(long)]
    pub kl_weight: Option<f64>,
    /// Weight of the task-space loss term (1 cm of final TCP error costs
    /// 1); 0 (default) trains on the joint-space losses alone.
    #[arg(long)]
    pub tcp_weight: Option<f64>,
    /// Weight of the start term: per rad² of the mean's error at the
    /// first phase sample (0, default, leaves it to Eq. 7).
    #[arg(long)]
    pub start_weight: Option<f64>,
    /// Dropout rate on the latent while the heads train (0 = off)
    /// [default: 0].
    #[arg(long)]
    pub latent_dropout: Option<f64>,
    /// Epochs without validation improvement before a phase stops
    /// [default: 10].
    #[arg(long)]
    pub patience: Option<usize>,
    /// Latent size.
    #[arg(long)]
    pub latent_dim: Option<usize>,
    /// Continue an interrupted run from OUT/train_state.
    #[arg(long)]
    pub resume: bool,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// The robot of the dataset's demonstrations (recorded in the model).
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

impl TrainArgs {
    /// The training settings these flags describe.
    pub fn settings(&self) -> crate::Result<TrainSettings> {
        let mut s = TrainSettings::new(&self.data, &self.out, Arch::parse(&self.arch)?);
        s.latent_tuning = self.latent_tuning;
        s.depth_condition = self.depth_condition;
        s.space = crate::net::Space::parse(&self.space)?;
        s.seed = self.seed;
        s.epochs_tp1 = self.epochs_tp1.unwrap_or(s.epochs_tp1);
        s.epochs_tp2 = self.epochs_tp2.unwrap_or(s.epochs_tp2);
        s.epochs_tp3 = self.epochs_tp3.unwrap_or(s.epochs_tp3);
        s.batch = self.batch.unwrap_or(s.batch);
        s.lr = self.lr.unwrap_or(s.lr);
        s.alpha = self.alpha.unwrap_or(s.alpha);
        s.kl_weight = self.kl_weight.unwrap_or(s.kl_weight);
        s.tcp_weight = self.tcp_weight.unwrap_or(s.tcp_weight);
        s.start_weight = self.start_weight.unwrap_or(s.start_weight);
        s.latent_dropout = self.latent_dropout.unwrap_or(s.latent_dropout);
        s.patience = self.patience.unwrap_or(s.patience);
        s.shape.latent_dim = self.latent_dim.unwrap_or(s.shape.latent_dim);
        s.resume = self.resume;
        s.progress = !self.quiet;
        s.validate()?;
        Ok(s)
    }
}

/// Run `dpmp train`; prints the training record as JSON.
pub fn run(args: TrainArgs) -> crate::Result<()> {
    let outcome = train_for(&args.settings()?, &args.robot.load()?)?;
    crate::cli::print_json(&outcome)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The defaults written in the help are the training settings'.
    #[test]
    fn the_help_states_the_training_defaults() {
        use clap::CommandFactory;
        let help = crate::cli::Cli::command()
            .find_subcommand_mut("train")
            .unwrap()
            .render_long_help()
            .to_string();
        let s = TrainSettings::new(Path::new("d"), Path::new("o"), Arch::Ae);
        let s = &s;
        for (flag, value) in [
            ("tp1 (reconstruction)", s.epochs_tp1.to_string()),
            ("only phase)", s.epochs_tp2.to_string()),
            ("tp3 (latent tuning)", s.epochs_tp3.to_string()),
            ("(the authors: 5)", s.batch.to_string()),
            ("cosine-decayed per phase", s.lr.to_string()),
            ("Eq. 7 / Eq. 8", s.alpha.to_string()),
            ("VAE / cVAE", s.kl_weight.to_string()),
            ("(0 = off)", s.latent_dropout.to_string()),
            ("before a phase stops", s.patience.to_string()),
        ] {
            let at = help
                .find(flag)
                .unwrap_or_else(|| panic!("{flag} not in the help"));
            let window: String = help[at..].chars().take(120).collect();
            assert!(
                window.contains(&format!("[default: {value}]")),
                "{flag}: default {value} not stated: {window}"
            );
        }
    }
}
