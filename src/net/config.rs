//! The model configuration written next to the weights as `config.json`:
//! architecture, ProMP settings, preprocessing, the output normalisation
//! learnt from the training targets, the dataset it was trained on and the
//! code version. Everything needed to rebuild the network before loading
//! its tensors, validated on load.

use super::preprocess::PreprocessConfig;
use crate::promp::PrompConfig;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// The format tag written into every `config.json`.
pub const MODEL_FORMAT: &str = "dpmp-model/1";

/// Which network maps the image to the weight distribution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Arch {
    /// Auto-encoder: encoder trained on reconstruction, then MLP heads.
    Ae,
    /// Variational auto-encoder (mu, log sigma^2, reparameterisation).
    Vae,
    /// Conditional VAE: latent concatenated with the normalised box centre.
    Cvae,
    /// CNN straight to the weight distribution, trained end to end.
    Direct,
}

impl Arch {
    /// Parse `ae | vae | cvae | direct`.
    pub fn parse(text: &str) -> Result<Arch> {
        match text {
            "ae" => Ok(Arch::Ae),
            "vae" => Ok(Arch::Vae),
            "cvae" => Ok(Arch::Cvae),
            "direct" => Ok(Arch::Direct),
            other => Err(Error::invalid(
                "arch",
                format!("expected ae, vae, cvae or direct, got {other:?}"),
            )),
        }
    }

    /// The lowercase name (`"cvae"`).
    pub fn as_str(self) -> &'static str {
        match self {
            Arch::Ae => "ae",
            Arch::Vae => "vae",
            Arch::Cvae => "cvae",
            Arch::Direct => "direct",
        }
    }

    /// Whether the encoder is variational (mu and log-variance).
    pub fn is_variational(self) -> bool {
        matches!(self, Arch::Vae | Arch::Cvae)
    }

    /// Whether the architecture has an image decoder (trained in tp1).
    pub fn has_decoder(self) -> bool {
        !matches!(self, Arch::Direct)
    }

    /// Whether the heads (and decoder) see the box-centre condition.
    pub fn is_conditional(self) -> bool {
        matches!(self, Arch::Cvae)
    }
}

/// What the network's weights describe: joint angles, or the TCP pose
/// (position and quaternion, [`crate::task_space`]). A task-space model's
/// seven "joints" are the seven task dimensions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Space {
    /// Joint-space trajectories (rad): the optimiser's prior directly.
    #[default]
    Joint,
    /// Task-space trajectories: x, y, z (m), qx, qy, qz, qw.
    Task,
}

impl Space {
    /// Parse `joint | task`.
    pub fn parse(text: &str) -> Result<Space> {
        match text {
            "joint" => Ok(Space::Joint),
            "task" => Ok(Space::Task),
            other => Err(Error::invalid(
                "space",
                format!("expected joint or task, got {other:?}"),
            )),
        }
    }

    /// The lowercase name.
    pub fn as_str(self) -> &'static str {
        match self {
            Space::Joint => "joint",
            Space::Task => "task",
        }
    }

    /// Whether this is joint space (the default, not written to configs).
    pub fn is_joint(&self) -> bool {
        *self == Space::Joint
    }
}

/// How a task-space model's distribution becomes the optimiser's
/// joint-space prior ([`crate::task_space::joint_prior`]); recorded in the
/// model's `config.json` as `task_prior` (absent: 64 draws).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskPriorSettings {
    /// `draws` (default) or `linearised`.
    #[serde(default)]
    pub propagation: crate::task_space::Propagation,
    /// Draws tracked, the mean included (2..=1024; draws only).
    #[serde(default = "default_task_draws")]
    pub draws: usize,
}

fn default_task_draws() -> usize {
    crate::task_space::JointPriorOptions::default().draws
}

impl Default for TaskPriorSettings {
    fn default() -> Self {
        TaskPriorSettings {
            propagation: crate::task_space::Propagation::Draws,
            draws: default_task_draws(),
        }
    }
}

impl TaskPriorSettings {
    /// The tracking options these settings give.
    pub fn options(&self) -> crate::task_space::JointPriorOptions {
        crate::task_space::JointPriorOptions {
            propagation: self.propagation,
            draws: self.draws,
            ..Default::default()
        }
    }
}

/// Per-output affine map from the heads' raw outputs to weight means and
/// covariance codes: `value = raw * scale + offset`, one entry per joint and
/// output (`n_joints x (n_basis + n_basis (n_basis + 1) / 2)`, joint-major).
/// Computed from the training targets so that the heads work in a
/// well-scaled space; fixed (not trained).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputNorm {
    /// Added after scaling.
    pub offset: Vec<f32>,
    /// Multiplies the raw head output; strictly positive.
    pub scale: Vec<f32>,
}

impl OutputNorm {
    /// The identity map for `len` outputs.
    pub fn identity(len: usize) -> OutputNorm {
        OutputNorm {
            offset: vec![0.0; len],
            scale: vec![1.0; len],
        }
    }

    fn validate(&self, len: usize) -> Result<()> {
        for (name, values) in [("offset", &self.offset), ("scale", &self.scale)] {
            if values.len() != len {
                return Err(Error::invalid(
                    format!("output_norm.{name}"),
                    format!("expected {len} numbers, got {}", values.len()),
                ));
            }
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(Error::invalid(
                    format!("output_norm.{name}[{i}]"),
                    "must be a finite number",
                ));
            }
        }
        if let Some(i) = self.scale.iter().position(|&s| s <= 0.0) {
            return Err(Error::invalid(
                format!("output_norm.scale[{i}]"),
                "must be positive",
            ));
        }
        Ok(())
    }
}

/// Where the training data came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// The dataset directory as given on the command line.
    pub dir: String,
    /// SHA-256 of its `manifest.json` (hex).
    pub manifest_sha256: String,
    /// Number of training and validation targets.
    pub n_train: usize,
    /// Number of validation targets.
    pub n_val: usize,
}

/// How the model was trained (recorded for reproduction).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    /// Seed of every random choice (init, shuffling, noise).
    pub seed: u64,
    /// Completed epochs per phase, e.g. `{"tp1": 40, "tp2": 60}`.
    pub epochs: std::collections::BTreeMap<String, usize>,
    /// Best validation loss per phase.
    pub best_val_loss: std::collections::BTreeMap<String, f64>,
    /// Mini-batch size.
    pub batch: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Weight of the covariance terms in Eq. 7 and Eq. 8.
    pub alpha: f64,
    /// Weight of the KL term in tp1 (variational encoders).
    pub kl_weight: f64,
    /// Weight of the task-space (final TCP) term in tp2, tp3 and Direct
    /// (0 in models trained before the term existed).
    #[serde(default)]
    pub tcp_weight: f64,
    /// Weight of the start term (per rad²; 0 in older models).
    #[serde(default)]
    pub start_weight: f64,
    /// Dropout rate on the latent the heads read, in training only.
    #[serde(default)]
    pub latent_dropout: f64,
    /// Wall-clock training time in seconds.
    pub seconds: f64,
}

/// Everything needed to rebuild a network before loading its weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// Always [`MODEL_FORMAT`].
    pub format: String,
    /// Display name (the model directory's name by default).
    pub name: String,
    /// Network architecture.
    pub arch: Arch,
    /// Whether the encoder was latent-tuned (tp3, the paper's "l-" prefix).
    pub latent_tuning: bool,
    /// The space of the predicted weights (configs without it: joint).
    #[serde(default, skip_serializing_if = "Space::is_joint")]
    pub space: Space,
    /// A task-space model's joint-space prior settings (absent: the
    /// defaults).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_prior: Option<TaskPriorSettings>,
    /// Latent vector size (the paper: 256).
    pub latent_dim: usize,
    /// Output channels of each encoder conv block (each halves the size).
    pub encoder_channels: Vec<usize>,
    /// Hidden layer widths of each per-joint MLP head.
    pub head_hidden: Vec<usize>,
    /// Negative slope of every LeakyReLU.
    pub leaky_slope: f64,
    /// Number of joints (7 for the Panda).
    pub n_joints: usize,
    /// ProMP basis settings of the predicted weights.
    pub promp: PrompConfig,
    /// Image preprocessing (identical in training and serving).
    pub preprocess: PreprocessConfig,
    /// Affine map of the head outputs (see [`OutputNorm`]).
    pub output_norm: OutputNorm,
    /// The dataset the weights were trained on, if any.
    pub dataset: Option<DatasetInfo>,
    /// The camera of the training images (intrinsics and gripper mount):
    /// planning back-projects depth through it. Configs without it mean
    /// the synthetic generator's default camera.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<crate::perception::CameraModel>,
    /// The cVAE condition includes the target's depth (beside the box
    /// centre); such a model needs depth (or a 3-D target) to predict.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub depth_condition: bool,
    /// The robot the model was trained for (its demonstrations' robot).
    /// Configs without it were trained for the shipped Panda.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<crate::robot::RobotIdentity>,
    /// SHA-256 (hex) of `model.safetensors`, written by the trainer and
    /// checked at load; absent in models saved before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights_sha256: Option<String>,
    /// Crate version that wrote the file.
    pub code_version: String,
    /// Training record, if trained.
    pub training: Option<TrainingSummary>,
}

impl ModelConfig {
    /// A default-sized configuration for `arch` with identity output
    /// normalisation (training replaces it).
    pub fn new(name: &str, arch: Arch) -> ModelConfig {
        let promp = PrompConfig::default();
        let mut config = ModelConfig {
            format: MODEL_FORMAT.to_string(),
            name: name.to_string(),
            arch,
            latent_tuning: false,
            space: Space::Joint,
            task_prior: None,
            latent_dim: 256,
            encoder_channels: vec![8, 16, 32, 32],
            head_hidden: vec![256, 128, 64, 32],
            leaky_slope: 0.2,
            n_joints: 7,
            promp,
            preprocess: PreprocessConfig::default(),
            output_norm: OutputNorm::identity(0),
            dataset: None,
            camera: None,
            depth_condition: false,
            robot: None,
            weights_sha256: None,
            code_version: env!("CARGO_PKG_VERSION").to_string(),
            training: None,
        };
        config.output_norm = OutputNorm::identity(config.n_joints * config.head_outputs());
        config
    }

    /// The camera of the training images ([`ModelConfig::camera`], or the
    /// synthetic generator's default).
    pub fn camera_model(&self) -> crate::perception::CameraModel {
        self.camera.unwrap_or_default()
    }

    /// Covariance code length per joint, `n (n + 1) / 2`.
    pub fn code_len(&self) -> usize {
        self.promp.n_basis * (self.promp.n_basis + 1) / 2
    }

    /// Outputs of one joint head: `n_basis` means plus the covariance code.
    pub fn head_outputs(&self) -> usize {
        self.promp.n_basis + self.code_len()
    }

    /// Size of the cVAE condition: the box centre, and the depth when
    /// [`ModelConfig::depth_condition`].
    pub fn condition_dim(&self) -> usize {
        2 + usize::from(self.depth_condition)
    }

    /// Size of the vector the heads read: latent plus the cVAE condition.
    pub fn feature_dim(&self) -> usize {
        self.latent_dim
            + if self.arch.is_conditional() {
                self.condition_dim()
            } else {
                0
            }
    }

    /// Side of the feature map after the encoder's conv blocks.
    pub fn encoded_side(&self) -> usize {
        self.preprocess.input_size >> self.encoder_channels.len()
    }

    /// `Ok` when `robot` is the robot this model was trained for (configs
    /// without a record: the shipped Panda); otherwise an error (field
    /// `robot`) saying which robot it was trained for.
    pub fn check_robot(&self, robot: &crate::robot::Robot) -> Result<()> {
        let what = format!("model '{}'", self.name);
        match &self.robot {
            Some(identity) => identity.check(robot, &what),
            None => crate::robot::Robot::panda()?.identity().check(robot, &what),
        }
    }

    /// Check every field; errors name the field.
    pub fn validate(&self) -> Result<()> {
        if let Some(camera) = &self.camera {
            camera.validate("camera")?;
        }
        if self.depth_condition && !self.arch.is_conditional() {
            return Err(Error::invalid(
                "depth_condition",
                "only a conditional architecture (cvae) reads a condition",
            ));
        }
        if self.space == Space::Task && self.n_joints != crate::task_space::TASK_DIMS {
            return Err(Error::invalid(
                "n_joints",
                format!(
                    "a task-space model predicts {} dimensions, got {}",
                    crate::task_space::TASK_DIMS,
                    self.n_joints
                ),
            ));
        }
        if let Some(t) = &self.task_prior {
            if self.space != Space::Task {
                return Err(Error::invalid(
                    "task_prior",
                    "only a task-space model (space: task) has a task-space prior",
                ));
            }
            check_range("task_prior.draws", t.draws, 2, 1024)?;
        }
        if self.format != MODEL_FORMAT {
            return Err(Error::invalid(
                "format",
                format!("expected {MODEL_FORMAT:?}, got {:?}", self.format),
            ));
        }
        self.promp.validate().map_err(|e| e.within("promp"))?;
        self.preprocess
            .validate()
            .map_err(|e| e.within("preprocess"))?;
        check_range("latent_dim", self.latent_dim, 1, 4096)?;
        check_range("n_joints", self.n_joints, 1, 16)?;
        check_range("encoder_channels.len", self.encoder_channels.len(), 1, 6)?;
        for (i, &c) in self.encoder_channels.iter().enumerate() {
            check_range(&format!("encoder_channels[{i}]"), c, 1, 512)?;
        }
        check_range("head_hidden.len", self.head_hidden.len(), 0, 8)?;
        for (i, &h) in self.head_hidden.iter().enumerate() {
            check_range(&format!("head_hidden[{i}]"), h, 1, 4096)?;
        }
        let side = self.preprocess.input_size;
        if !side.is_multiple_of(1 << self.encoder_channels.len()) || self.encoded_side() == 0 {
            return Err(Error::invalid(
                "preprocess.input_size",
                format!(
                    "{side} must be divisible by 2^{} (one halving per encoder block)",
                    self.encoder_channels.len()
                ),
            ));
        }
        if !(self.leaky_slope.is_finite() && (0.0..1.0).contains(&self.leaky_slope)) {
            return Err(Error::invalid("leaky_slope", "must be in [0, 1)"));
        }
        if self.latent_tuning && self.arch == Arch::Direct {
            return Err(Error::invalid(
                "latent_tuning",
                "the direct model has no separate encoder to tune",
            ));
        }
        self.output_norm
            .validate(self.n_joints * self.head_outputs())
    }
}

fn check_range(field: &str, value: usize, lo: usize, hi: usize) -> Result<()> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("must be in {lo}..={hi}, got {value}"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_condition_adds_one_feature_and_needs_a_conditional_model() {
        let mut config = ModelConfig::new("d", Arch::Cvae);
        config.depth_condition = true;
        assert_eq!((config.condition_dim(), config.feature_dim()), (3, 259));
        config.validate().unwrap();
        let mut ae = ModelConfig::new("d", Arch::Ae);
        ae.depth_condition = true;
        assert_eq!(ae.validate().unwrap_err().field(), Some("depth_condition"));
        // Configs written before the field load as box-only models.
        let mut json = serde_json::to_value(ModelConfig::new("old", Arch::Cvae)).unwrap();
        json.as_object_mut().unwrap().remove("depth_condition");
        let old: ModelConfig = serde_json::from_value(json).unwrap();
        assert!(!old.depth_condition && old.camera.is_none());
        assert_eq!(
            old.camera_model(),
            crate::perception::CameraModel::default()
        );
    }

    #[test]
    fn the_depth_condition_is_normalised_and_required() {
        let p = crate::net::preprocess::Prepared {
            pixels: Vec::new(),
            condition: [0.25, 0.5],
            depth_m: Some(0.55),
        };
        let v = p.condition_values(true).unwrap();
        assert_eq!(v.len(), 3);
        assert!((v[2] - 1.0).abs() < 1e-6);
        assert_eq!(p.condition_values(false).unwrap(), vec![0.25, 0.5]);
        let none = crate::net::preprocess::Prepared { depth_m: None, ..p };
        let e = none.condition_values(true).unwrap_err();
        assert_eq!(e.field(), Some("depth"));
    }

    #[test]
    fn default_config_is_valid_and_round_trips() {
        let config = ModelConfig::new("x", Arch::Cvae);
        config.validate().unwrap();
        assert_eq!(config.head_outputs(), 44);
        assert_eq!(config.feature_dim(), 258);
        assert_eq!(config.encoded_side(), 8);
        let text = serde_json::to_string(&config).unwrap();
        let back: ModelConfig = serde_json::from_str(&text).unwrap();
        assert_eq!(back, config);
    }

    #[test]
    fn invalid_fields_are_named() {
        let mut config = ModelConfig::new("x", Arch::Ae);
        config.encoder_channels = vec![8; 8];
        assert_eq!(
            config.validate().unwrap_err().field(),
            Some("encoder_channels.len")
        );
        let mut config = ModelConfig::new("x", Arch::Ae);
        config.output_norm.scale[3] = 0.0;
        assert_eq!(
            config.validate().unwrap_err().field(),
            Some("output_norm.scale[3]")
        );
        let mut config = ModelConfig::new("x", Arch::Direct);
        config.latent_tuning = true;
        assert_eq!(
            config.validate().unwrap_err().field(),
            Some("latent_tuning")
        );
        let mut config = ModelConfig::new("x", Arch::Cvae);
        config.task_prior = Some(TaskPriorSettings::default());
        assert_eq!(config.validate().unwrap_err().field(), Some("task_prior"));
        config.space = Space::Task;
        config.validate().unwrap();
        config.task_prior = Some(TaskPriorSettings {
            draws: 1,
            ..TaskPriorSettings::default()
        });
        assert_eq!(
            config.validate().unwrap_err().field(),
            Some("task_prior.draws")
        );
        let linear: TaskPriorSettings =
            serde_json::from_str(r#"{"propagation": "linearised"}"#).unwrap();
        assert_eq!(linear.draws, 64);
        assert!(serde_json::from_str::<TaskPriorSettings>(r#"{"method": "x"}"#).is_err());
        assert!(Arch::parse("gan").is_err());
        assert_eq!(Arch::parse("cvae").unwrap(), Arch::Cvae);
    }
}
