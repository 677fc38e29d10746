//! The paper's per-joint annotation format: a folder per joint `J1..J7`,
//! each with `K.json` = `{"mean_weights": [[w1], ..., [w8]], "L": [36
//! numbers], "configuration": K}` (the covariance code of [`super::codec`]
//! with the diagonal stored as is).
//!
//! Importing joins the per-joint blocks into one block-diagonal prior and
//! repairs covariances that are not positive semi-definite, reporting the
//! repair as a warning.

use super::codec::{decode_covariance, encode_covariance, DiagEncoding};
use super::distribution::WeightDistribution;
use super::psd::repair_covariance;
use crate::{error::ensure_finite, Error, Result};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Repaired eigenvalues are clipped to this fraction of the block's
/// largest eigenvalue.
pub const REPAIR_FLOOR_RELATIVE: f64 = 1e-9;

/// One joint's weight distribution in the paper's format.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointAnnotation {
    /// Mean weights; files store them as a column (`[[w1], [w2], ...]`),
    /// a flat list is accepted too.
    #[serde(deserialize_with = "flat_or_column")]
    pub mean_weights: Vec<f64>,
    /// The `n(n+1)/2`-number covariance code (raw diagonal).
    #[serde(rename = "L", deserialize_with = "covariance_code")]
    pub l: Vec<f64>,
}

/// A prior over all joints, with what the import had to repair.
#[derive(Clone, Debug)]
pub struct Prior {
    /// The (repaired) block-diagonal weight distribution.
    pub distribution: WeightDistribution,
    /// Smallest eigenvalue over all joint covariances, before repair.
    pub min_eigenvalue: f64,
    /// Whether any covariance had to be repaired.
    pub repaired: bool,
    /// Human-readable notes on every repair.
    pub warnings: Vec<String>,
}

fn flat_or_column<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Vec<f64>, D::Error> {
    use serde::de::DeserializeSeed;
    crate::strict_json::AtMost {
        max: super::config::MAX_BASIS,
        item: ScalarOrSingleton,
    }
    .deserialize(d)
}

/// The covariance code of at most `MAX_BASIS` weights.
fn covariance_code<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Vec<f64>, D::Error> {
    use serde::de::DeserializeSeed;
    const MAX: usize = super::config::MAX_BASIS * (super::config::MAX_BASIS + 1) / 2;
    crate::strict_json::AtMost::<std::marker::PhantomData<f64>>::items(MAX).deserialize(d)
}

/// One mean weight: a number, or a one-number row (`[w]`).
#[derive(Clone, Copy)]
struct ScalarOrSingleton;

impl<'de> serde::de::DeserializeSeed<'de> for ScalarOrSingleton {
    type Value = f64;

    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> std::result::Result<f64, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> serde::de::Visitor<'de> for ScalarOrSingleton {
    type Value = f64;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a number or a one-number row [w]")
    }

    fn visit_f64<E>(self, v: f64) -> std::result::Result<f64, E> {
        Ok(v)
    }

    fn visit_i64<E>(self, v: i64) -> std::result::Result<f64, E> {
        Ok(v as f64)
    }

    fn visit_u64<E>(self, v: u64) -> std::result::Result<f64, E> {
        Ok(v as f64)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(
        self,
        mut seq: A,
    ) -> std::result::Result<f64, A::Error> {
        use serde::de::Error as _;
        let first: Option<f64> = seq.next_element()?;
        match (first, seq.next_element::<serde::de::IgnoredAny>()?) {
            (Some(v), None) => Ok(v),
            (None, _) => Err(A::Error::custom("expected a single number per row, got 0")),
            (Some(_), Some(_)) => Err(A::Error::custom(
                "expected a single number per row, got more",
            )),
        }
    }
}

/// Per-joint annotations (raw diagonal) of a distribution's diagonal blocks.
pub fn joints_from_distribution(dist: &WeightDistribution) -> Result<Vec<JointAnnotation>> {
    (0..dist.n_joints)
        .map(|j| {
            let (mean, cov) = dist.joint_block(j);
            Ok(JointAnnotation {
                mean_weights: mean.as_slice().to_vec(),
                l: encode_covariance(&cov, DiagEncoding::Raw)
                    .map_err(|e| e.within(&format!("joints[{j}]")))?,
            })
        })
        .collect()
}

/// Decode, validate and repair per-joint annotations into one prior.
/// Errors name `[j].mean_weights` or `[j].L`.
pub fn prior_from_joints(joints: &[JointAnnotation], n_basis: usize) -> Result<Prior> {
    if joints.is_empty() {
        return Err(Error::invalid(
            "annotation",
            "needs one entry per joint, got none",
        ));
    }
    let code_len = n_basis * (n_basis + 1) / 2;
    let mut means = Vec::with_capacity(joints.len());
    let mut covs = Vec::with_capacity(joints.len());
    let mut min_eigenvalue = f64::INFINITY;
    let mut warnings = Vec::new();
    for (j, joint) in joints.iter().enumerate() {
        let field = format!("[{j}]");
        if joint.mean_weights.len() != n_basis {
            return Err(Error::invalid(
                format!("{field}.mean_weights"),
                format!(
                    "expected {n_basis} numbers, got {}",
                    joint.mean_weights.len()
                ),
            ));
        }
        ensure_finite(&format!("{field}.mean_weights"), &joint.mean_weights)?;
        if joint.l.len() != code_len {
            return Err(Error::invalid(
                format!("{field}.L"),
                format!("expected {code_len} numbers, got {}", joint.l.len()),
            ));
        }
        let cov = decode_covariance(&joint.l, DiagEncoding::Raw)
            .map_err(|e| rename_code_field(e, &field))?;
        let scale = cov.symmetric_eigenvalues().amax();
        let (cov, min_eig, repaired) = repair_covariance(&cov, REPAIR_FLOOR_RELATIVE * scale);
        min_eigenvalue = min_eigenvalue.min(min_eig);
        if repaired {
            warnings.push(format!(
                "joint {} covariance is not positive semi-definite (min eigenvalue {min_eig:.3e}); eigenvalues clipped to {:.3e}",
                j + 1,
                REPAIR_FLOOR_RELATIVE * scale
            ));
        }
        means.push(DVector::from_vec(joint.mean_weights.clone()));
        covs.push(cov);
    }
    Ok(Prior {
        distribution: WeightDistribution::from_joint_blocks(&means, &covs)?,
        min_eigenvalue,
        repaired: !warnings.is_empty(),
        warnings,
    })
}

fn rename_code_field(e: Error, joint_field: &str) -> Error {
    match e {
        Error::Invalid { field, message } => Error::Invalid {
            field: format!("{joint_field}.{field}"),
            message,
        },
        other => other,
    }
}

/// Number of joint folders `J1, J2, ...` present in `dir`.
fn count_joint_dirs(dir: &Path) -> usize {
    (1..)
        .take_while(|j| dir.join(format!("J{j}")).is_dir())
        .count()
}

/// Load target `index` from an annotation folder (`dir/J1/index.json`, ...).
/// Errors name the file and the field inside it.
pub fn load_dir(dir: &Path, index: usize) -> Result<Prior> {
    let joints = read_joints(dir, index)?;
    let n_basis = joints[0].mean_weights.len();
    prior_from_joints(&joints, n_basis).map_err(|e| match e {
        Error::Invalid { field, message } => {
            let (joint, rest) = split_joint_field(&field);
            let path = dir
                .join(format!("J{}", joint + 1))
                .join(format!("{index}.json"));
            Error::file(path, format!("invalid {rest}: {message}"))
        }
        other => other,
    })
}

/// The raw per-joint annotations of target `index` (`dir/J1/index.json`,
/// ...), parsed but neither decoded nor repaired. Errors name the file.
pub fn read_joints(dir: &Path, index: usize) -> Result<Vec<JointAnnotation>> {
    let n_joints = count_joint_dirs(dir);
    if n_joints == 0 {
        return Err(Error::file(dir, "no joint folders J1, J2, ... found"));
    }
    (1..=n_joints)
        .map(|j| {
            let path = dir.join(format!("J{j}")).join(format!("{index}.json"));
            let text =
                std::fs::read_to_string(&path).map_err(|e| Error::file(&path, e.to_string()))?;
            serde_json::from_str(&text)
                .map_err(|e| Error::file(&path, format!("malformed annotation: {e}")))
        })
        .collect()
}

/// `"[3].L[5]"` -> `(3, "L[5]")`.
fn split_joint_field(field: &str) -> (usize, &str) {
    let joint = field
        .strip_prefix('[')
        .and_then(|s| s.split(']').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let rest = field.split_once("].").map(|(_, r)| r).unwrap_or(field);
    (joint, rest)
}

/// Write target `index` in the paper's layout (`dir/J{j}/{index}.json`,
/// mean weights as a column, `configuration` = index). Each file is written
/// to a temporary name and renamed, so no partial file is left behind.
pub fn write_dir(dir: &Path, index: usize, joints: &[JointAnnotation]) -> Result<()> {
    for (j, joint) in joints.iter().enumerate() {
        let folder = dir.join(format!("J{}", j + 1));
        std::fs::create_dir_all(&folder).map_err(|e| Error::write(&folder, e.to_string()))?;
        let column: Vec<[f64; 1]> = joint.mean_weights.iter().map(|&w| [w]).collect();
        let value =
            serde_json::json!({"mean_weights": column, "L": joint.l, "configuration": index});
        write_atomic(
            &folder.join(format!("{index}.json")),
            value.to_string().as_bytes(),
        )?;
    }
    Ok(())
}

pub use crate::fsio::write_atomic;

/// Convenience: the covariance matrix of one joint annotation (raw code).
pub fn joint_covariance(joint: &JointAnnotation) -> Result<DMatrix<f64>> {
    decode_covariance(&joint.l, DiagEncoding::Raw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::codec::fill_triangular_index;

    fn joint(seed: f64, negative_pivot: bool) -> JointAnnotation {
        let mut l: Vec<f64> = (0..36)
            .map(|k| ((k as f64 + seed) * 0.37).sin() * 0.5)
            .collect();
        for (k, (r, c)) in fill_triangular_index(8).into_iter().enumerate() {
            if r == c {
                l[k] = if negative_pivot && r == 3 {
                    -2.0
                } else {
                    0.1 + 0.05 * r as f64
                };
            }
        }
        JointAnnotation {
            mean_weights: (0..8).map(|i| seed + i as f64).collect(),
            l,
        }
    }

    #[test]
    fn folder_round_trip_with_repair_warning() {
        let dir = tempfile::tempdir().unwrap();
        let joints: Vec<_> = (0..7).map(|j| joint(j as f64, j == 4)).collect();
        write_dir(dir.path(), 3, &joints).unwrap();
        let text = std::fs::read_to_string(dir.path().join("J1/3.json")).unwrap();
        assert!(text.contains("\"mean_weights\":[[0.0],[1.0]"));
        let prior = load_dir(dir.path(), 3).unwrap();
        assert_eq!(prior.distribution.dim(), 56);
        assert!(prior.repaired);
        assert!(prior.min_eigenvalue < 0.0);
        assert_eq!(prior.warnings.len(), 1);
        assert!(prior.warnings[0].starts_with("joint 5"));
        assert!(crate::promp::psd::min_eigenvalue(&prior.distribution.cov) > -1e-9);
        // Untouched joints decode exactly.
        let (m, c) = prior.distribution.joint_block(0);
        assert_eq!(m.as_slice(), joints[0].mean_weights.as_slice());
        assert!((c - joint_covariance(&joints[0]).unwrap()).amax() < 1e-12);
    }

    #[test]
    fn errors_name_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let mut joints: Vec<_> = (0..7).map(|j| joint(j as f64, false)).collect();
        joints[2].l.pop();
        write_dir(dir.path(), 0, &joints).unwrap();
        let msg = load_dir(dir.path(), 0).unwrap_err().to_string();
        assert!(
            msg.contains("J3/0.json") && msg.contains("invalid L"),
            "{msg}"
        );
        std::fs::write(dir.path().join("J6/0.json"), "{\"mean_weights\": [1, 2").unwrap();
        let msg = load_dir(dir.path(), 0).unwrap_err().to_string();
        assert!(
            msg.contains("J6/0.json") || msg.contains("J3/0.json"),
            "{msg}"
        );
        let msg = load_dir(dir.path(), 9).unwrap_err().to_string();
        assert!(msg.contains("J1/9.json"), "{msg}");
    }

    #[test]
    fn nan_weights_are_rejected() {
        let mut joints: Vec<_> = (0..7).map(|j| joint(j as f64, false)).collect();
        joints[6].mean_weights[2] = f64::NAN;
        assert_eq!(
            prior_from_joints(&joints, 8).unwrap_err().field(),
            Some("[6].mean_weights[2]")
        );
    }
}
