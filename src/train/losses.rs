//! Training losses, built from candle ops so they differentiate:
//!
//! - image reconstruction (mean squared error over pixels) and the VAE's KL
//!   divergence to `N(0, I)` (mean over latent dimensions);
//! - the paper's Eq. 7 trajectory loss, per joint `j`:
//!   `mean_t (Phi (mu_hat_j - mu_j))_t^2 + alpha * mean_{t,s} (Phi (Sigma_hat_j - Sigma_j) Phi^T)_{ts}^2`,
//!   summed over joints and averaged over the batch;
//! - the paper's Eq. 8 final-step loss (latent tuning): the same two terms
//!   at the last phase sample only (`phi_T^T (mu_hat - mu)` squared plus
//!   `alpha` times the squared error of the final-time variance).
//!
//! Predicted covariances come from the heads' 36-number codes through
//! [`CovarianceDecoder`] (log-diagonal).

use crate::net::heads::HeadOutput;
use crate::net::CovarianceDecoder;
use crate::promp::Basis;
use candle_core::{Device, Result, Tensor};

/// The fixed tensors the trajectory losses need.
#[derive(Clone, Debug)]
pub struct TrajectoryOperator {
    phi: Tensor,
    phi_t: Tensor,
    first: Tensor,
    last: Tensor,
    decoder: CovarianceDecoder,
}

/// A loss with its per-joint parts (each `(n_joints,)`, batch-averaged).
#[derive(Clone, Debug)]
pub struct JointLoss {
    /// Scalar objective: `sum_j mean_j + alpha * cov_j`.
    pub total: Tensor,
    /// Mean-trajectory term per joint.
    pub mean: Tensor,
    /// Covariance term per joint (before `alpha`).
    pub cov: Tensor,
}

impl TrajectoryOperator {
    /// Build from a ProMP basis (T x n_basis).
    pub fn new(basis: &Basis, device: &Device) -> Result<TrajectoryOperator> {
        let matrix = basis.matrix();
        let (t, n) = (matrix.nrows(), matrix.ncols());
        let mut rows = Vec::with_capacity(t * n);
        for r in 0..t {
            for c in 0..n {
                rows.push(matrix[(r, c)] as f32);
            }
        }
        let phi = Tensor::from_vec(rows, (t, n), device)?;
        let first = phi.narrow(0, 0, 1)?.t()?.contiguous()?;
        let last = phi.narrow(0, t - 1, 1)?.t()?.contiguous()?;
        Ok(TrajectoryOperator {
            first,
            phi_t: phi.t()?.contiguous()?,
            phi,
            last,
            decoder: CovarianceDecoder::new(n, device)?,
        })
    }

    /// Decode the heads' codes `(B, J, len)` to covariances `(B, J, n, n)`.
    pub fn covariance(&self, code: &Tensor) -> Result<Tensor> {
        self.decoder.decode(code)
    }

    /// Eq. 7 between the heads' output and target means `(B, J, n)` and
    /// covariance blocks `(B, J, n, n)`.
    pub fn trajectory_loss(
        &self,
        pred: &HeadOutput,
        target_mean: &Tensor,
        target_cov: &Tensor,
        alpha: f64,
    ) -> Result<JointLoss> {
        let (b, j, n) = target_mean.dims3()?;
        let t = self.phi.dim(0)?;
        let dm = (&pred.mean - target_mean)?.reshape((b * j, n))?;
        let mean = dm
            .matmul(&self.phi_t)?
            .sqr()?
            .mean(1)?
            .reshape((b, j))?
            .mean(0)?;
        let dc = (self.covariance(&pred.code)? - target_cov)?.reshape((b * j * n, n))?;
        // (Phi D Phi^T)^T = Phi D^T Phi^T: two plain matmuls with Phi^T.
        let half = dc
            .matmul(&self.phi_t)?
            .reshape((b * j, n, t))?
            .transpose(1, 2)?
            .contiguous()?
            .reshape((b * j * t, n))?;
        let traj = half.matmul(&self.phi_t)?;
        let cov = traj
            .sqr()?
            .reshape((b * j, t * t))?
            .mean(1)?
            .reshape((b, j))?
            .mean(0)?;
        combine(mean, cov, alpha)
    }

    /// Eq. 8: the final-step loss.
    pub fn final_step_loss(
        &self,
        pred: &HeadOutput,
        target_mean: &Tensor,
        target_cov: &Tensor,
        alpha: f64,
    ) -> Result<JointLoss> {
        let (b, j, n) = target_mean.dims3()?;
        let dm = (&pred.mean - target_mean)?.reshape((b * j, n))?;
        let mean = dm.matmul(&self.last)?.sqr()?.reshape((b, j))?.mean(0)?;
        let dc = (self.covariance(&pred.code)? - target_cov)?.reshape((b * j * n, n))?;
        let var = dc
            .matmul(&self.last)?
            .reshape((b * j, n))?
            .matmul(&self.last)?
            .reshape((b, j))?;
        let cov = var.sqr()?.mean(0)?;
        combine(mean, cov, alpha)
    }
}

impl TrajectoryOperator {
    /// The start term: squared error of the mean at the first phase
    /// sample, summed over joints and averaged over the batch (rad²). Eq. 7
    /// weighs the start like any other of the 150 samples; a prior whose
    /// start is off from the robot's makes the optimiser bend the whole
    /// motion (docs/experiments.md).
    pub fn start_loss(&self, pred: &HeadOutput, target_mean: &Tensor) -> Result<Tensor> {
        let (b, j, n) = target_mean.dims3()?;
        let dm = (&pred.mean - target_mean)?.reshape((b * j, n))?;
        dm.matmul(&self.first)?
            .sqr()?
            .reshape((b, j))?
            .sum(1)?
            .mean_all()
    }
}

fn combine(mean: Tensor, cov: Tensor, alpha: f64) -> Result<JointLoss> {
    let total = (mean.sum_all()? + (cov.sum_all()? * alpha)?)?;
    Ok(JointLoss { total, mean, cov })
}

/// Mean squared error between reconstructed and input images.
pub fn reconstruction_loss(reconstruction: &Tensor, images: &Tensor) -> Result<Tensor> {
    (reconstruction - images)?.sqr()?.mean_all()
}

/// KL divergence of `N(mu, exp(logvar))` to `N(0, I)`, averaged over the
/// batch and the latent dimensions.
pub fn kl_loss(mu: &Tensor, logvar: &Tensor) -> Result<Tensor> {
    let inner = ((logvar + 1.0)? - mu.sqr()?)?.sub(&logvar.exp()?)?;
    inner.mean_all()? * -0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;

    #[test]
    fn the_start_term_is_the_squared_start_offset_summed_over_joints() {
        // Constant weight offsets c_j shift a normalised basis' trajectory
        // by c_j at every sample, the first included.
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let op = TrajectoryOperator::new(&basis, &Device::Cpu).unwrap();
        let n = basis.n_basis();
        let offsets = [0.1f32, -0.2, 0.05];
        let target = Tensor::zeros((2, 3, n), candle_core::DType::F32, &Device::Cpu).unwrap();
        let shifted: Vec<f32> = (0..2)
            .flat_map(|_| offsets.iter().flat_map(|&c| vec![c; n]))
            .collect();
        let pred = HeadOutput {
            mean: Tensor::from_vec(shifted, (2, 3, n), &Device::Cpu).unwrap(),
            code: Tensor::zeros(
                (2, 3, n * (n + 1) / 2),
                candle_core::DType::F32,
                &Device::Cpu,
            )
            .unwrap(),
        };
        let value = op
            .start_loss(&pred, &target)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        let want: f32 = offsets.iter().map(|c| c * c).sum();
        assert!(
            (value - want).abs() < 1e-5 * want.max(1.0),
            "{value} vs {want}"
        );
    }
}
