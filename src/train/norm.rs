//! The heads' output normalisation learnt from the training targets: per
//! joint and output, the mean and standard deviation of the target weight
//! means and of the covariance codes (`encode_covariance(.., Log)` of each
//! joint block). The heads then predict standardised values.

use super::data::Sample;
use crate::net::OutputNorm;
use crate::promp::codec::{encode_covariance, DiagEncoding};
use crate::Result;

/// Standard deviations below this are replaced by 1 (constant outputs).
const MIN_STD: f64 = 1e-6;

/// Compute the normalisation from training samples (at least one).
pub fn output_norm(samples: &[Sample], n_joints: usize, n_basis: usize) -> Result<OutputNorm> {
    let code_len = n_basis * (n_basis + 1) / 2;
    let width = n_basis + code_len;
    let mut rows: Vec<Vec<f64>> = Vec::with_capacity(samples.len());
    for sample in samples {
        let mut row = Vec::with_capacity(n_joints * width);
        for j in 0..n_joints {
            let (mean, cov) = sample.distribution.joint_block(j);
            row.extend(mean.iter());
            let code = encode_covariance(&cov, DiagEncoding::Log)
                .map_err(|e| e.within(&format!("targets.{}.joint{j}", sample.id)))?;
            row.extend(code);
        }
        rows.push(row);
    }
    Ok(standardise(&rows, n_joints * width))
}

fn standardise(rows: &[Vec<f64>], len: usize) -> OutputNorm {
    if rows.is_empty() {
        return OutputNorm::identity(len);
    }
    let n = rows.len() as f64;
    let mut offset = Vec::with_capacity(len);
    let mut scale = Vec::with_capacity(len);
    for k in 0..len {
        let mean = rows.iter().map(|r| r[k]).sum::<f64>() / n;
        let var = rows.iter().map(|r| (r[k] - mean).powi(2)).sum::<f64>() / n;
        let std = var.sqrt();
        offset.push(mean as f32);
        scale.push(if std > MIN_STD { std as f32 } else { 1.0 });
    }
    OutputNorm { offset, scale }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standardise_gives_mean_and_std_with_constant_floor() {
        let rows = vec![vec![1.0, 5.0], vec![3.0, 5.0]];
        let norm = standardise(&rows, 2);
        assert_eq!(norm.offset, vec![2.0, 5.0]);
        assert_eq!(norm.scale, vec![1.0, 1.0]);
        let rows = vec![vec![0.0], vec![4.0]];
        assert_eq!(standardise(&rows, 1).scale, vec![2.0]);
    }
}
