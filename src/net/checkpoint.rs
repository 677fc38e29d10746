//! Checkpoints: a model directory holds `model.safetensors` (every
//! parameter and batch-norm statistic, f32) and `config.json`
//! ([`ModelConfig`]). Both are written atomically (temp file + rename).
//! Loading checks every tensor against the shapes the config implies and
//! names the offending tensor on a missing, extra, wrong-shaped, wrong-type
//! or non-finite entry; a corrupt file is a clear file error, and weights
//! that do not hash to the config's `weights_sha256` are refused.

use super::config::ModelConfig;
use super::models::Network;
use crate::{Error, Result};
use candle_core::{Device, Tensor};
use std::collections::BTreeMap;
use std::path::Path;

/// File name of the weights inside a model directory.
pub const WEIGHTS_FILE: &str = "model.safetensors";
/// File name of the configuration inside a model directory.
pub const CONFIG_FILE: &str = "config.json";

/// Tensors read from a safetensors file: name -> (shape, f32 data).
pub type TensorMap = BTreeMap<String, (Vec<usize>, Vec<f32>)>;

pub use crate::fsio::write_atomic;

/// Serialise named f32 tensors to a safetensors file, atomically.
pub fn write_tensors(path: &Path, tensors: &[(String, Tensor)]) -> Result<()> {
    write_atomic(path, &serialise_tensors(path, tensors)?)
}

/// The safetensors bytes of named f32 tensors (`path` names them in errors).
fn serialise_tensors(path: &Path, tensors: &[(String, Tensor)]) -> Result<Vec<u8>> {
    let mut raw: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::with_capacity(tensors.len());
    for (name, tensor) in tensors {
        let values: Vec<f32> = tensor
            .flatten_all()
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(|e| Error::Numerical(format!("tensor {name}: {e}")))?;
        let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        raw.push((name.clone(), tensor.dims().to_vec(), bytes));
    }
    let views = raw
        .iter()
        .map(|(name, shape, bytes)| {
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes)
                .map(|view| (name.clone(), view))
                .map_err(|e| Error::Numerical(format!("tensor {name}: {e}")))
        })
        .collect::<Result<Vec<_>>>()?;
    safetensors::tensor::serialize(views, None)
        .map_err(|e| Error::file(path, format!("cannot serialise: {e}")))
}

/// SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Read every tensor of a safetensors file as f32, checking the type and
/// that every value is finite.
pub fn read_tensors(path: &Path) -> Result<TensorMap> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
    parse_tensors(path, &bytes)
}

/// [`read_tensors`] of bytes already read from `path`.
fn parse_tensors(path: &Path, bytes: &[u8]) -> Result<TensorMap> {
    let file = safetensors::SafeTensors::deserialize(bytes)
        .map_err(|e| Error::file(path, format!("corrupt safetensors file: {e}")))?;
    let mut out = TensorMap::new();
    for (name, view) in file.tensors() {
        if view.dtype() != safetensors::Dtype::F32 {
            return Err(Error::file(
                path,
                format!(
                    "tensor {name:?}: expected dtype F32, found {:?}",
                    view.dtype()
                ),
            ));
        }
        let values: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::file(
                path,
                format!("tensor {name:?}: element {i} is not finite"),
            ));
        }
        out.insert(name, (view.shape().to_vec(), values));
    }
    Ok(out)
}

/// Save a network into `dir` (created if needed): weights, then the config
/// with the weights' SHA-256 (`weights_sha256`, checked at load).
pub fn save(network: &Network, dir: &Path) -> Result<()> {
    let tensors: Vec<(String, Tensor)> = network
        .named_vars()
        .into_iter()
        .map(|(name, var)| (name, var.as_tensor().clone()))
        .collect();
    let path = dir.join(WEIGHTS_FILE);
    let bytes = serialise_tensors(&path, &tensors)?;
    write_atomic(&path, &bytes)?;
    let mut config = network.config().clone();
    config.weights_sha256 = Some(sha256_hex(&bytes));
    let text = serde_json::to_string_pretty(&config)
        .map_err(|e| Error::Numerical(format!("cannot serialise config: {e}")))?;
    write_atomic(&dir.join(CONFIG_FILE), text.as_bytes())
}

/// Read and validate `config.json` of a model directory.
pub fn load_config(dir: &Path) -> Result<ModelConfig> {
    let path = dir.join(CONFIG_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    parse_config(&path, &text)
}

/// Parse and validate a model config's text; `path` names it in errors.
fn parse_config(path: &Path, text: &str) -> Result<ModelConfig> {
    let config: ModelConfig = serde_json::from_str(text)
        .map_err(|e| Error::file(path, format!("malformed model config: {e}")))?;
    config
        .validate()
        .map_err(|e| Error::file(path, e.to_string()))?;
    Ok(config)
}

/// Load a model directory onto `device`.
pub fn load(dir: &Path, device: &Device) -> Result<Network> {
    let config = load_config(dir)?;
    let path = dir.join(WEIGHTS_FILE);
    let bytes = std::fs::read(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    build(config, &path, &bytes, device)
}

/// Load a model held in memory (a config's text and its weights' bytes;
/// `dir` names them in errors) onto `device`, with the same checks as
/// [`load`].
pub fn load_bytes(dir: &Path, config: &str, weights: &[u8], device: &Device) -> Result<Network> {
    let config = parse_config(&dir.join(CONFIG_FILE), config)?;
    build(config, &dir.join(WEIGHTS_FILE), weights, device)
}

/// The network of `config` with the weights in `bytes` (read from `path`).
fn build(config: ModelConfig, path: &Path, bytes: &[u8], device: &Device) -> Result<Network> {
    let network = Network::new(config, 0, device)
        .map_err(|e| Error::Numerical(format!("cannot build network: {e}")))?;
    check_weights_checksum(network.config(), path, bytes)?;
    assign(&network, &parse_tensors(path, bytes)?, path)?;
    Ok(network)
}

/// The weights must hash to the config's `weights_sha256`: finite but
/// corrupted weights (a flipped bit) load otherwise and predict garbage.
/// A model saved before checksums were recorded loads with a warning.
fn check_weights_checksum(config: &ModelConfig, path: &Path, bytes: &[u8]) -> Result<()> {
    let Some(expected) = &config.weights_sha256 else {
        tracing::warn!(
            file = %path.display(),
            "the model config records no weights_sha256: corruption of the weights cannot be detected"
        );
        return Ok(());
    };
    let found = sha256_hex(bytes);
    if &found != expected {
        return Err(Error::file(
            path,
            format!(
                "the weights do not match the config's weights_sha256 (expected {expected}, found {found}): the file was changed or corrupted after training"
            ),
        ));
    }
    Ok(())
}

/// Copy `tensors` into the network's vars, requiring exactly the network's
/// names and shapes; `path` names the source in errors.
pub fn assign(network: &Network, tensors: &TensorMap, path: &Path) -> Result<()> {
    let vars = network.named_vars();
    for (name, var) in &vars {
        let (shape, values) = tensors
            .get(name)
            .ok_or_else(|| Error::file(path, format!("tensor {name:?} is missing")))?;
        if shape.as_slice() != var.dims() {
            return Err(Error::file(
                path,
                format!(
                    "tensor {name:?}: expected shape {:?}, found {shape:?}",
                    var.dims()
                ),
            ));
        }
        Tensor::from_slice(values, shape.as_slice(), network.device())
            .and_then(|t| var.set(&t))
            .map_err(|e| Error::file(path, format!("tensor {name:?}: {e}")))?;
    }
    if let Some(extra) = tensors
        .keys()
        .find(|k| !vars.iter().any(|(name, _)| name == *k))
    {
        return Err(Error::file(
            path,
            format!("unexpected tensor {extra:?} (not part of this architecture)"),
        ));
    }
    Ok(())
}
