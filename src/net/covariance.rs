//! The paper's covariance code decoded with candle ops (differentiable):
//! a per-joint vector of `n (n + 1) / 2` numbers is laid out by
//! TensorFlow Probability's `fill_triangular` (lower) order
//! ([`crate::promp::codec::fill_triangular_index`]); its diagonal holds
//! `d` (the network predicts `log D`, so `D = exp(d)`) and the strictly
//! lower part the unit-lower-triangular `L`, giving `Sigma = L diag(D) L^T`.
//! Equal to `promp::codec::decode_covariance(code, DiagEncoding::Log)`.

use candle_core::{DType, Device, Result, Tensor};

/// Fixed scatter matrices mapping a code to `L` and `log D`.
#[derive(Clone, Debug)]
pub struct CovarianceDecoder {
    n: usize,
    off_diagonal: Tensor,
    diagonal: Tensor,
    identity: Tensor,
}

impl CovarianceDecoder {
    /// Build for `n x n` covariances (`n_basis`).
    pub fn new(n: usize, device: &Device) -> Result<CovarianceDecoder> {
        let len = n * (n + 1) / 2;
        let mut off = vec![0f32; len * n * n];
        let mut diag = vec![0f32; len * n];
        for (k, (row, col)) in crate::promp::codec::fill_triangular_index(n)
            .into_iter()
            .enumerate()
        {
            if row == col {
                diag[k * n + row] = 1.0;
            } else {
                off[k * n * n + row * n + col] = 1.0;
            }
        }
        Ok(CovarianceDecoder {
            n,
            off_diagonal: Tensor::from_vec(off, (len, n * n), device)?,
            diagonal: Tensor::from_vec(diag, (len, n), device)?,
            identity: Tensor::eye(n, DType::F32, device)?,
        })
    }

    /// `(..., len)` codes to `(..., n, n)` covariances.
    pub fn decode(&self, code: &Tensor) -> Result<Tensor> {
        let dims = code.dims().to_vec();
        let lead = &dims[..dims.len() - 1];
        let rows: usize = lead.iter().product();
        let flat = code.reshape((rows, dims[dims.len() - 1]))?;
        let lower = flat
            .matmul(&self.off_diagonal)?
            .reshape((rows, self.n, self.n))?
            .broadcast_add(&self.identity)?;
        let d = flat.matmul(&self.diagonal)?.exp()?.unsqueeze(1)?;
        let cov = lower
            .broadcast_mul(&d)?
            .matmul(&lower.transpose(1, 2)?.contiguous()?)?;
        let mut shape = lead.to_vec();
        shape.extend([self.n, self.n]);
        cov.reshape(shape)
    }
}
