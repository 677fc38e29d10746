//! Gaussian distributions over joint-major ProMP weights.

use super::basis::Basis;
use super::fit::weight_matrix;
use super::psd;
use crate::{error::ensure_finite, Error, Result};
use nalgebra::{DMatrix, DVector};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// `N(mean, cov)` over the `n_joints * n_basis` joint-major weights; the
/// covariance may couple joints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightDistribution {
    /// Mean weights, joint-major.
    pub mean: DVector<f64>,
    /// Full weight covariance.
    pub cov: DMatrix<f64>,
    /// Number of joints.
    pub n_joints: usize,
    /// Basis functions per joint.
    pub n_basis: usize,
}

/// The rows of `m` as nested vectors: the JSON form of a covariance
/// (`cov`) and of a `T x n_joints` trajectory.
pub fn matrix_rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// A weight distribution as plain arrays (`{"mean": [...], "cov": [[...]]}`,
/// joint-major): the form datasets store and the optimiser's full prior
/// takes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DistributionJson {
    /// Mean (n_joints * n_basis).
    pub mean: Vec<f64>,
    /// Covariance rows.
    pub cov: Vec<Vec<f64>>,
}

impl From<&WeightDistribution> for DistributionJson {
    fn from(dist: &WeightDistribution) -> Self {
        DistributionJson {
            mean: dist.mean.as_slice().to_vec(),
            cov: matrix_rows(&dist.cov),
        }
    }
}

impl WeightDistribution {
    /// An error naming `basis` unless it has this distribution's number of
    /// basis functions.
    pub fn check_basis(&self, basis: &Basis) -> Result<()> {
        if basis.n_basis() != self.n_basis {
            return Err(Error::invalid(
                "basis",
                format!(
                    "basis has {} functions, distribution {}",
                    basis.n_basis(),
                    self.n_basis
                ),
            ));
        }
        Ok(())
    }

    /// Check shapes, finiteness and symmetry (to a relative 1e-8).
    pub fn new(
        mean: DVector<f64>,
        cov: DMatrix<f64>,
        n_joints: usize,
        n_basis: usize,
    ) -> Result<Self> {
        let n = n_joints * n_basis;
        if n == 0 {
            return Err(Error::invalid(
                "mean",
                "needs at least one joint and one basis function",
            ));
        }
        if mean.len() != n {
            return Err(Error::invalid(
                "mean",
                format!(
                    "expected {n} numbers ({n_joints} joints x {n_basis} basis functions), got {}",
                    mean.len()
                ),
            ));
        }
        if cov.nrows() != n || cov.ncols() != n {
            return Err(Error::invalid(
                "cov",
                format!(
                    "expected a {n} x {n} matrix, got {} x {}",
                    cov.nrows(),
                    cov.ncols()
                ),
            ));
        }
        ensure_finite("mean", mean.as_slice())?;
        for r in 0..n {
            for c in 0..n {
                if !cov[(r, c)].is_finite() {
                    return Err(Error::invalid(
                        format!("cov[{r}][{c}]"),
                        "must be a finite number",
                    ));
                }
            }
        }
        let scale = cov.amax().max(1e-300);
        for r in 0..n {
            for c in 0..r {
                if (cov[(r, c)] - cov[(c, r)]).abs() > 1e-8 * scale {
                    return Err(Error::invalid(
                        format!("cov[{r}][{c}]"),
                        format!(
                            "covariance must be symmetric: {} != cov[{c}][{r}] = {}",
                            cov[(r, c)],
                            cov[(c, r)]
                        ),
                    ));
                }
            }
        }
        Ok(WeightDistribution {
            mean,
            cov: psd::symmetrize(&cov),
            n_joints,
            n_basis,
        })
    }

    /// Sample mean and unbiased sample covariance of demonstration weights.
    pub fn from_demonstrations(
        weights: &[DVector<f64>],
        n_joints: usize,
        n_basis: usize,
    ) -> Result<Self> {
        let n = n_joints * n_basis;
        if weights.len() < 2 {
            return Err(Error::invalid(
                "demonstrations",
                format!("need at least 2 demonstrations, got {}", weights.len()),
            ));
        }
        for (k, w) in weights.iter().enumerate() {
            if w.len() != n {
                return Err(Error::invalid(
                    format!("demonstrations[{k}]"),
                    format!("expected {n} weights, got {}", w.len()),
                ));
            }
            ensure_finite(&format!("demonstrations[{k}]"), w.as_slice())?;
        }
        let count = weights.len() as f64;
        let mean = weights.iter().fold(DVector::zeros(n), |acc, w| acc + w) / count;
        let mut cov = DMatrix::zeros(n, n);
        for w in weights {
            let d = w - &mean;
            cov.ger(1.0, &d, &d, 1.0);
        }
        cov /= count - 1.0;
        WeightDistribution::new(mean, cov, n_joints, n_basis)
    }

    /// Block-diagonal distribution from per-joint means and covariances.
    pub fn from_joint_blocks(means: &[DVector<f64>], covs: &[DMatrix<f64>]) -> Result<Self> {
        let n_joints = means.len();
        if n_joints == 0 || covs.len() != n_joints {
            return Err(Error::invalid(
                "joints",
                format!(
                    "need one mean and one covariance per joint, got {} and {}",
                    means.len(),
                    covs.len()
                ),
            ));
        }
        let nb = means[0].len();
        let mut mean = DVector::zeros(n_joints * nb);
        let mut cov = DMatrix::zeros(n_joints * nb, n_joints * nb);
        for (j, (m, c)) in means.iter().zip(covs).enumerate() {
            if m.len() != nb || c.nrows() != nb || c.ncols() != nb {
                return Err(Error::invalid(
                    format!("joints[{j}]"),
                    format!("expected {nb} means and a {nb} x {nb} covariance"),
                ));
            }
            mean.rows_mut(j * nb, nb).copy_from(m);
            cov.view_mut((j * nb, j * nb), (nb, nb)).copy_from(c);
        }
        WeightDistribution::new(mean, cov, n_joints, nb)
    }

    /// Dimension `n_joints * n_basis`.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Mean and covariance block of one joint.
    pub fn joint_block(&self, joint: usize) -> (DVector<f64>, DMatrix<f64>) {
        let nb = self.n_basis;
        let m = self.mean.rows(joint * nb, nb).into_owned();
        let c = self
            .cov
            .view((joint * nb, joint * nb), (nb, nb))
            .into_owned();
        (m, c)
    }

    /// The same distribution with the cross-joint covariances dropped.
    pub fn block_diagonal(&self) -> Self {
        let mut cov = DMatrix::zeros(self.dim(), self.dim());
        let nb = self.n_basis;
        for j in 0..self.n_joints {
            let block = self.cov.view((j * nb, j * nb), (nb, nb));
            cov.view_mut((j * nb, j * nb), (nb, nb)).copy_from(&block);
        }
        WeightDistribution {
            cov,
            ..self.clone()
        }
    }

    /// Mean trajectory `T x n_joints`.
    pub fn trajectory_mean(&self, basis: &Basis) -> DMatrix<f64> {
        basis.matrix() * weight_matrix(self.mean.as_slice(), self.n_basis, self.n_joints)
    }

    /// Per-time marginal standard deviation `T x n_joints` (paper Eq. 5):
    /// `sqrt(diag(Sigma_q + Psi_tᵀ Sigma_w Psi_t))` with
    /// `Sigma_q = obs_noise_var * I`.
    pub fn trajectory_std(&self, basis: &Basis, obs_noise_var: f64) -> DMatrix<f64> {
        let nb = self.n_basis;
        let phi = basis.matrix();
        let mut std = DMatrix::zeros(basis.n_samples(), self.n_joints);
        for j in 0..self.n_joints {
            let block = self.cov.view((j * nb, j * nb), (nb, nb));
            let projected = phi * block; // T x nb
            for t in 0..basis.n_samples() {
                let var = projected.row(t).dot(&phi.row(t)) + obs_noise_var;
                std[(t, j)] = var.max(0.0).sqrt();
            }
        }
        std
    }

    /// Mean and covariance of the joint positions at phase `z` (Eq. 5).
    pub fn marginal(
        &self,
        basis: &Basis,
        z: f64,
        obs_noise_var: f64,
    ) -> (DVector<f64>, DMatrix<f64>) {
        let h = observation_matrix(&basis.row_at(z), self.n_joints);
        let mean = &h * &self.mean;
        let cov = &h * &self.cov * h.transpose()
            + DMatrix::identity(self.n_joints, self.n_joints) * obs_noise_var;
        (mean, cov)
    }

    /// Covariance of the whole trajectory (paper Eq. 6), joint-major:
    /// entry `(j * T + t, k * T + s)` couples joint `j` at `t` with joint
    /// `k` at `s`.
    pub fn trajectory_covariance(&self, basis: &Basis) -> DMatrix<f64> {
        let (nb, t, nj) = (self.n_basis, basis.n_samples(), self.n_joints);
        let phi = basis.matrix();
        let mut out = DMatrix::zeros(nj * t, nj * t);
        for j in 0..nj {
            for k in 0..nj {
                let block = self.cov.view((j * nb, k * nb), (nb, nb));
                out.view_mut((j * t, k * t), (t, t))
                    .copy_from(&(phi * block * phi.transpose()));
            }
        }
        out
    }

    /// `n` draws (Cholesky with jitter; never fails on rank-deficient or
    /// slightly indefinite covariances). Deterministic for a seeded `rng`.
    pub fn sample(&self, rng: &mut impl rand::Rng, n: usize) -> Vec<DVector<f64>> {
        let l = psd::factor(&self.cov);
        (0..n)
            .map(|_| {
                let z = DVector::from_iterator(
                    self.dim(),
                    (0..self.dim()).map(|_| StandardNormal.sample(rng)),
                );
                &self.mean + &l * z
            })
            .collect()
    }

    /// Squared Mahalanobis distance of `w` from the mean under
    /// `cov + lambda I` (pseudo-inverse when singular).
    pub fn mahalanobis_squared(&self, w: &DVector<f64>, lambda: f64) -> f64 {
        let n = self.dim();
        let shifted = &self.cov + DMatrix::identity(n, n) * lambda;
        let d = w - &self.mean;
        match shifted.clone().cholesky() {
            Some(chol) => d.dot(&chol.solve(&d)),
            None => {
                let pinv = shifted
                    .pseudo_inverse(1e-12)
                    .unwrap_or_else(|_| DMatrix::zeros(n, n));
                d.dot(&(pinv * &d))
            }
        }
    }
}

/// `n_joints x (n_joints * n_basis)` matrix that reads joint positions off
/// joint-major weights at one phase: block-diagonal copies of `psiᵀ`.
pub fn observation_matrix(psi: &DVector<f64>, n_joints: usize) -> DMatrix<f64> {
    let nb = psi.len();
    let mut h = DMatrix::zeros(n_joints, n_joints * nb);
    for j in 0..n_joints {
        h.view_mut((j, j * nb), (1, nb)).copy_from(&psi.transpose());
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;
    use rand::SeedableRng;

    fn random_spd(n: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let a = DMatrix::from_fn(n, n, |_, _| rand::Rng::gen_range(&mut rng, -1.0..1.0));
        &a * a.transpose() + DMatrix::identity(n, n) * 0.1
    }

    #[test]
    fn sample_moments_match_within_statistical_tolerance() {
        let n = 6;
        let cov = random_spd(n, 1);
        let mean = DVector::from_fn(n, |i, _| i as f64 - 2.0);
        let d = WeightDistribution::new(mean.clone(), cov.clone(), 2, 3).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
        let draws = d.sample(&mut rng, 100_000);
        let est = WeightDistribution::from_demonstrations(&draws, 2, 3).unwrap();
        // Standard error of a mean ~ sigma / sqrt(N); allow 5 of them.
        for i in 0..n {
            let se = (cov[(i, i)] / 1e5).sqrt();
            assert!((est.mean[i] - mean[i]).abs() < 5.0 * se, "mean {i}");
            for j in 0..n {
                let se = ((cov[(i, i)] * cov[(j, j)] + cov[(i, j)].powi(2)) / 1e5).sqrt();
                assert!(
                    (est.cov[(i, j)] - cov[(i, j)]).abs() < 5.0 * se,
                    "cov {i},{j}"
                );
            }
        }
    }

    #[test]
    fn sampling_a_rank_deficient_covariance_stays_in_its_range() {
        let v = DVector::from_vec(vec![1.0, 2.0, -1.0, 0.5]);
        let cov = &v * v.transpose();
        let d = WeightDistribution::new(DVector::zeros(4), cov, 2, 2).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for s in d.sample(&mut rng, 100) {
            // Every draw is a multiple of v (up to the tiny jitter).
            let t = s.dot(&v) / v.dot(&v);
            assert!((&s - &v * t).amax() < 1e-5);
        }
    }

    #[test]
    fn trajectory_std_equals_the_diagonal_of_the_full_covariance() {
        let basis = Basis::new(&PrompConfig {
            n_samples: 20,
            ..Default::default()
        })
        .unwrap();
        let d = WeightDistribution::new(DVector::zeros(16), random_spd(16, 2), 2, 8).unwrap();
        let full = d.trajectory_covariance(&basis);
        let std = d.trajectory_std(&basis, 0.0);
        for j in 0..2 {
            for t in 0..20 {
                assert!((std[(t, j)].powi(2) - full[(j * 20 + t, j * 20 + t)]).abs() < 1e-10);
            }
        }
        let (_, marg) = d.marginal(&basis, basis.phases()[7], 0.01);
        assert!((marg[(1, 1)] - std[(7, 1)].powi(2) - 0.01).abs() < 1e-10);
        assert!((marg[(0, 1)] - full[(7, 20 + 7)]).abs() < 1e-10);
    }

    #[test]
    fn shape_and_value_errors_name_the_field() {
        let e =
            WeightDistribution::new(DVector::zeros(5), DMatrix::identity(6, 6), 2, 3).unwrap_err();
        assert_eq!(e.field(), Some("mean"));
        let mut cov = DMatrix::identity(6, 6);
        cov[(4, 1)] = f64::INFINITY;
        let e = WeightDistribution::new(DVector::zeros(6), cov, 2, 3).unwrap_err();
        assert_eq!(e.field(), Some("cov[4][1]"));
        let mut cov = DMatrix::identity(6, 6);
        cov[(4, 1)] = 0.5;
        let e = WeightDistribution::new(DVector::zeros(6), cov, 2, 3).unwrap_err();
        assert_eq!(e.field(), Some("cov[4][1]"));
    }
}
