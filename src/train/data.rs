//! Training data: the synthetic dataset on disk (`manifest.json`,
//! `images/*.png`, `targets/*.json`) read into preprocessed samples, and
//! mini-batches as tensors.
//!
//! Images go through [`crate::net::preprocess::prepare`] with
//! `mask_applied = true` (the dataset images already carry the white box),
//! the same function the inference API calls.

use crate::net::predict::stack_prepared;
use crate::net::preprocess::{self, Prepared, PreprocessConfig};
use crate::net::{candle_error, ModelConfig};
use crate::promp::{PrompConfig, WeightDistribution};
use crate::{Error, Result};
use candle_core::{Device, Tensor};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Deserialize;
use sha2::Digest;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The subset of `manifest.json` training reads.
#[derive(Clone, Debug, Deserialize)]
pub struct Manifest {
    /// `"dpmp-dataset/1"`.
    pub format: String,
    /// Basis settings of every weight vector in the dataset.
    pub promp: PrompConfig,
    /// Target ids per split (`train`, `val`, `test`).
    pub splits: BTreeMap<String, Vec<String>>,
    /// Every target with its files.
    pub targets: Vec<TargetEntry>,
}

/// One target of the manifest.
#[derive(Clone, Debug, Deserialize)]
pub struct TargetEntry {
    /// `c0003_b02`.
    pub id: String,
    /// Plant configuration index (the latent-space cluster label).
    pub config: usize,
    /// Image path relative to the dataset directory.
    pub image: String,
    /// Record path relative to the dataset directory.
    pub record: String,
}

/// The subset of a target record training and evaluation read.
#[derive(Clone, Debug, Deserialize)]
pub struct TargetRecord {
    /// Target box in image pixels.
    #[serde(rename = "box")]
    pub target_box: [f64; 4],
    /// The demonstrations' weight distribution (full covariance).
    pub distribution: RecordDistribution,
}

/// `distribution` of a target record.
#[derive(Clone, Debug, Deserialize)]
pub struct RecordDistribution {
    /// Joint-major mean weights.
    pub mean: Vec<f64>,
    /// Covariance rows.
    pub cov: Vec<Vec<f64>>,
}

/// One preprocessed training example.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Target id.
    pub id: String,
    /// Plant configuration (cluster label).
    pub config: usize,
    /// Network input.
    pub prepared: Prepared,
    /// Ground-truth weight distribution (as in the record).
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
    /// The loaded samples, in manifest split order.
    pub samples: Vec<Sample>,
}

/// Read `DIR/manifest.json` and its SHA-256.
pub fn read_manifest(dir: &Path) -> Result<(Manifest, String)> {
    let path = dir.join("manifest.json");
    let bytes = std::fs::read(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    let manifest: Manifest = serde_json::from_slice(&bytes)
        .map_err(|e| Error::file(&path, format!("malformed manifest: {e}")))?;
    if manifest.format != "dpmp-dataset/1" {
        return Err(Error::file(
            &path,
            format!(
                "format: expected \"dpmp-dataset/1\", got {:?}",
                manifest.format
            ),
        ));
    }
    let hash = sha2::Sha256::digest(&bytes);
    let hex = hash.iter().map(|b| format!("{b:02x}")).collect();
    Ok((manifest, hex))
}

/// The entries of a split (`train`, `val`, `test`, or `all`).
pub fn split_entries<'a>(manifest: &'a Manifest, split: &str) -> Result<Vec<&'a TargetEntry>> {
    if split == "all" {
        return Ok(manifest.targets.iter().collect());
    }
    let ids = manifest.splits.get(split).ok_or_else(|| {
        Error::invalid(
            "split",
            format!("no split {split:?} (train, val, test, all)"),
        )
    })?;
    ids.iter()
        .map(|id| {
            manifest
                .targets
                .iter()
                .find(|t| &t.id == id)
                .ok_or_else(|| {
                    Error::invalid(format!("splits.{split}"), format!("unknown target {id:?}"))
                })
        })
        .collect()
}

/// Load and preprocess one split (images decoded in parallel).
pub fn load_split(dir: &Path, split: &str, preprocess: &PreprocessConfig) -> Result<Dataset> {
    let (manifest, manifest_sha256) = read_manifest(dir)?;
    let entries = split_entries(&manifest, split)?;
    let promp = manifest.promp.clone();
    let samples = entries
        .par_iter()
        .map(|entry| load_sample(dir, entry, &promp, preprocess))
        .collect::<Result<Vec<_>>>()?;
    Ok(Dataset {
        dir: dir.to_path_buf(),
        manifest_sha256,
        promp,
        samples,
    })
}

fn load_sample(
    dir: &Path,
    entry: &TargetEntry,
    promp: &PrompConfig,
    preprocess: &PreprocessConfig,
) -> Result<Sample> {
    let record_path = dir.join(&entry.record);
    let text = std::fs::read_to_string(&record_path)
        .map_err(|e| Error::file(&record_path, e.to_string()))?;
    let record: TargetRecord = serde_json::from_str(&text)
        .map_err(|e| Error::file(&record_path, format!("malformed record: {e}")))?;
    let image_path = dir.join(&entry.image);
    let image = image::open(&image_path)
        .map_err(|e| Error::file(&image_path, e.to_string()))?
        .to_rgb8();
    let prepared = preprocess::prepare(&image, record.target_box, true, preprocess)
        .map_err(|e| Error::file(&record_path, e.to_string()))?;
    let distribution = record_distribution(&record.distribution, promp)
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

fn record_distribution(d: &RecordDistribution, promp: &PrompConfig) -> Result<WeightDistribution> {
    let n = d.mean.len();
    if n == 0 || n % promp.n_basis != 0 {
        return Err(Error::invalid(
            "distribution.mean",
            format!("length {n} is not a multiple of n_basis {}", promp.n_basis),
        ));
    }
    crate::error::ensure_finite("distribution.mean", &d.mean)?;
    if d.cov.len() != n {
        return Err(Error::invalid(
            "distribution.cov",
            format!("expected {n} rows"),
        ));
    }
    for (i, row) in d.cov.iter().enumerate() {
        crate::error::ensure_len(&format!("distribution.cov[{i}]"), row, n)?;
        crate::error::ensure_finite(&format!("distribution.cov[{i}]"), row)?;
    }
    let cov = DMatrix::from_fn(n, n, |r, c| d.cov[r][c]);
    WeightDistribution::new(
        DVector::from_vec(d.mean.clone()),
        cov,
        n / promp.n_basis,
        promp.n_basis,
    )
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
