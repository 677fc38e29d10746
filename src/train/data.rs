//! Training data: the synthetic dataset on disk (`manifest.json`,
//! `images/*.png`, `targets/*.json`, read with [`crate::synth::dataset`])
//! turned into preprocessed samples, and mini-batches as tensors.
//!
//! Images go through [`crate::net::preprocess::prepare`] with
//! `mask_applied = true` (the dataset images already carry the white box),
//! the same function the inference API calls.

use crate::net::predict::stack_prepared;
use crate::net::preprocess::{self, Prepared, PreprocessConfig};
use crate::net::{candle_error, ModelConfig};
use crate::promp::{PrompConfig, WeightDistribution};
use crate::synth::dataset::{self, TargetEntry};
use crate::{Error, Result};
use candle_core::{Device, Tensor};
use rayon::prelude::*;
use sha2::Digest;
use std::path::{Path, PathBuf};

/// One preprocessed training example.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Target id.
    pub id: String,
    /// Plant configuration (cluster label).
    pub config: usize,
    /// Network input.
    pub prepared: Prepared,
    /// Ground-truth weight distribution (the record's, in the model's space).
    pub distribution: WeightDistribution,
    /// `n_joints * n_basis` target means (f32, joint-major).
    pub mean: Vec<f32>,
    /// `n_joints * n_basis * n_basis` per-joint covariance blocks (f32).
    pub cov_blocks: Vec<f32>,
}

/// A split of the dataset loaded into memory.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The dataset directory.
    pub dir: PathBuf,
    /// SHA-256 (hex) of `manifest.json`.
    pub manifest_sha256: String,
    /// The dataset's basis settings.
    pub promp: PrompConfig,
    /// The camera that took the images (intrinsics and gripper mount).
    pub camera: crate::perception::CameraModel,
    /// The robot of the demonstrations, when the dataset records it
    /// (imported datasets; generated ones are the shipped Panda's).
    pub robot: Option<crate::robot::RobotIdentity>,
    /// The loaded samples, in manifest split order.
    pub samples: Vec<Sample>,
}

/// SHA-256 (hex) of `DIR/manifest.json`.
pub fn manifest_sha256(dir: &Path) -> Result<String> {
    let path = dir.join("manifest.json");
    let bytes = std::fs::read(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    let hash = sha2::Sha256::digest(&bytes);
    Ok(hash.iter().map(|b| format!("{b:02x}")).collect())
}

/// The weights a model learns: which space, and (task space) the robot
/// whose kinematics derive them for datasets written before format 4.
#[derive(Clone, Copy)]
pub enum Targets<'a> {
    /// The joint-space distribution of each record.
    Joint,
    /// The task-space distribution ([`crate::task_space`]).
    Task(&'a crate::robot::Robot),
}

impl<'a> Targets<'a> {
    /// The targets of a model in `space` for `robot`.
    pub fn of(space: crate::net::Space, robot: &'a crate::robot::Robot) -> Targets<'a> {
        match space {
            crate::net::Space::Joint => Targets::Joint,
            crate::net::Space::Task => Targets::Task(robot),
        }
    }

    fn distribution(&self, record: &dataset::TargetRecord) -> Result<WeightDistribution> {
        match self {
            Targets::Joint => record.weight_distribution(),
            Targets::Task(robot) => record.task_space_distribution(robot),
        }
    }
}

/// Load and preprocess one split (`train`, `val`, `test` or `all`) with
/// the dataset loader of [`crate::synth::dataset`], the weights of
/// `targets`; images are decoded in parallel.
pub fn load_split(
    dir: &Path,
    split: &str,
    preprocess: &PreprocessConfig,
    targets: Targets,
) -> Result<Dataset> {
    let manifest = dataset::load_manifest(dir)?;
    let manifest_sha256 = manifest_sha256(dir)?;
    let entries = manifest.split(split)?;
    let samples = entries
        .par_iter()
        .map(|entry| load_sample(dir, entry, preprocess, targets))
        .collect::<Result<Vec<_>>>()?;
    Ok(Dataset {
        dir: dir.to_path_buf(),
        manifest_sha256,
        promp: manifest.promp.clone(),
        camera: manifest.camera_model(),
        robot: manifest.robot.clone(),
        samples,
    })
}

fn load_sample(
    dir: &Path,
    entry: &TargetEntry,
    preprocess: &PreprocessConfig,
    targets: Targets,
) -> Result<Sample> {
    let record = dataset::load_record(dir, entry)?;
    let image = dataset::load_image(dir, entry)?;
    let record_path = dir.join(&entry.record);
    let mut prepared = preprocess::prepare(&image, record.bbox, entry.mask_applied, preprocess)
        .map_err(|e| Error::file(&record_path, e.to_string()))?;
    prepared.depth_m = record.target_depth_m;
    let distribution = targets
        .distribution(&record)
        .map_err(|e| Error::file(&record_path, e.to_string()))?;
    let (mean, cov_blocks) = block_targets(&distribution);
    Ok(Sample {
        id: entry.id.clone(),
        config: entry.config,
        prepared,
        distribution,
        mean,
        cov_blocks,
    })
}

/// Per-joint f32 targets: means and the diagonal covariance blocks.
pub fn block_targets(distribution: &WeightDistribution) -> (Vec<f32>, Vec<f32>) {
    let mean = distribution.mean.iter().map(|&v| v as f32).collect();
    let mut blocks = Vec::with_capacity(distribution.n_joints * distribution.n_basis.pow(2));
    for j in 0..distribution.n_joints {
        let (_, cov) = distribution.joint_block(j);
        for r in 0..cov.nrows() {
            for c in 0..cov.ncols() {
                blocks.push(cov[(r, c)] as f32);
            }
        }
    }
    (mean, blocks)
}

/// One mini-batch as tensors.
#[derive(Clone, Debug)]
pub struct Batch {
    /// `(B, 3, S, S)` normalised images.
    pub images: Tensor,
    /// `(B, 2)` cVAE conditions.
    pub conditions: Tensor,
    /// `(B, J, n)` target means.
    pub mean: Tensor,
    /// `(B, J, n, n)` target covariance blocks.
    pub cov: Tensor,
}

/// Stack the samples at `indices` into a batch.
pub fn make_batch(
    samples: &[Sample],
    indices: &[usize],
    config: &ModelConfig,
    device: &Device,
) -> Result<Batch> {
    let prepared: Vec<Prepared> = indices
        .iter()
        .map(|&i| samples[i].prepared.clone())
        .collect();
    let (images, conditions) = stack_prepared(&prepared, config, device)?;
    let (mean, cov) = target_tensors(samples, indices, config, device)?;
    Ok(Batch {
        images,
        conditions,
        mean,
        cov,
    })
}

/// Target means `(B, J, n)` and covariance blocks `(B, J, n, n)`.
pub fn target_tensors(
    samples: &[Sample],
    indices: &[usize],
    config: &ModelConfig,
    device: &Device,
) -> Result<(Tensor, Tensor)> {
    let (j, n) = (config.n_joints, config.promp.n_basis);
    let mut mean = Vec::with_capacity(indices.len() * j * n);
    let mut cov = Vec::with_capacity(indices.len() * j * n * n);
    for (k, &i) in indices.iter().enumerate() {
        let s = &samples[i];
        if s.mean.len() != j * n || s.cov_blocks.len() != j * n * n {
            return Err(Error::invalid(
                format!("samples[{k}]"),
                format!(
                    "target {} has {} weights, the model expects {}",
                    s.id,
                    s.mean.len(),
                    j * n
                ),
            ));
        }
        mean.extend_from_slice(&s.mean);
        cov.extend_from_slice(&s.cov_blocks);
    }
    let b = indices.len();
    let mean = Tensor::from_vec(mean, (b, j, n), device).map_err(candle_error)?;
    let cov = Tensor::from_vec(cov, (b, j, n, n), device).map_err(candle_error)?;
    Ok((mean, cov))
}
