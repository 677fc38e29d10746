//! Gaussian conditioning of a weight distribution on via-points: joint
//! positions observed at given phases (start configuration, final
//! configuration, any intermediate pose).

use super::basis::Basis;
use super::distribution::{observation_matrix, WeightDistribution};
use super::psd;
use crate::{error::ensure_finite, Error, Result};
use nalgebra::{DMatrix, DVector};

/// Joint positions `q` observed at `phase` with isotropic observation
/// noise variance `noise_var` (rad²) per joint; 0 pins the point exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct ViaPoint {
    /// Phase in `[0, 1]`.
    pub phase: f64,
    /// Observed joint positions (one per joint).
    pub q: Vec<f64>,
    /// Observation noise variance per joint (>= 0).
    pub noise_var: f64,
}

impl ViaPoint {
    fn validate(&self, index: usize, n_joints: usize) -> Result<()> {
        let field = format!("via_points[{index}]");
        if !(0.0..=1.0).contains(&self.phase) {
            return Err(Error::invalid(
                format!("{field}.phase"),
                format!("must be in [0, 1], got {}", self.phase),
            ));
        }
        if self.q.len() != n_joints {
            return Err(Error::invalid(
                format!("{field}.q"),
                format!("expected {n_joints} joint positions, got {}", self.q.len()),
            ));
        }
        ensure_finite(&format!("{field}.q"), &self.q)?;
        if !self.noise_var.is_finite() || self.noise_var < 0.0 {
            return Err(Error::invalid(
                format!("{field}.noise_var"),
                format!("must be finite and >= 0, got {}", self.noise_var),
            ));
        }
        Ok(())
    }
}

impl WeightDistribution {
    /// The posterior `p(w | q(z_k) = q_k)` for all via-points (Kalman form):
    /// `K = Σ Hᵀ (H Σ Hᵀ + R)⁻¹`, `μ' = μ + K (y - H μ)`, `Σ' = Σ - K H Σ`.
    /// A singular innovation matrix (exact observations of a rank-deficient
    /// prior) is handled with a pseudo-inverse.
    pub fn condition(&self, basis: &Basis, via_points: &[ViaPoint]) -> Result<Self> {
        if via_points.is_empty() {
            return Ok(self.clone());
        }
        self.check_basis(basis)?;
        let nj = self.n_joints;
        let m = via_points.len() * nj;
        let mut h = DMatrix::zeros(m, self.dim());
        let mut y = DVector::zeros(m);
        let mut r = DMatrix::zeros(m, m);
        for (k, via) in via_points.iter().enumerate() {
            via.validate(k, nj)?;
            h.rows_mut(k * nj, nj)
                .copy_from(&observation_matrix(&basis.row_at(via.phase), nj));
            y.rows_mut(k * nj, nj).copy_from_slice(&via.q);
            for j in 0..nj {
                r[(k * nj + j, k * nj + j)] = via.noise_var;
            }
        }
        let sigma_ht = &self.cov * h.transpose();
        let innovation = psd::symmetrize(&(&h * &sigma_ht + r));
        let gain = solve_right(&sigma_ht, &innovation)?;
        let mean = &self.mean + &gain * (y - &h * &self.mean);
        let cov = psd::symmetrize(&(&self.cov - &gain * sigma_ht.transpose()));
        Ok(WeightDistribution {
            mean,
            cov,
            ..self.clone()
        })
    }
}

/// `A S⁻¹` for symmetric `S`: Cholesky when definite, pseudo-inverse otherwise.
fn solve_right(a: &DMatrix<f64>, s: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    if let Some(chol) = s.clone().cholesky() {
        return Ok(chol.solve(&a.transpose()).transpose());
    }
    let tol = 1e-12 * s.amax().max(1e-300);
    let pinv = s
        .clone()
        .pseudo_inverse(tol)
        .map_err(|e| Error::Numerical(format!("conditioning: {e}")))?;
    Ok(a * pinv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;
    use rand::{Rng, SeedableRng};

    fn prior(seed: u64) -> (Basis, WeightDistribution) {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = 16;
        let a = DMatrix::from_fn(n, n, |_, _| rng.gen_range(-1.0..1.0));
        let cov = &a * a.transpose() * 0.1 + DMatrix::identity(n, n) * 0.01;
        let mean = DVector::from_fn(n, |_, _| rng.gen_range(-1.0..1.0));
        (basis, WeightDistribution::new(mean, cov, 2, 8).unwrap())
    }

    #[test]
    fn posterior_passes_through_the_via_point_to_the_noise() {
        let (basis, d) = prior(1);
        let via = ViaPoint {
            phase: 0.6,
            q: vec![0.3, -0.7],
            noise_var: 1e-6,
        };
        let post = d.condition(&basis, std::slice::from_ref(&via)).unwrap();
        let (m, c) = post.marginal(&basis, 0.6, 0.0);
        assert!((m[0] - 0.3).abs() < 1e-3 && (m[1] + 0.7).abs() < 1e-3);
        assert!(c[(0, 0)] <= 1e-6 && c[(1, 1)] <= 1e-6);
        let exact = d
            .condition(
                &basis,
                &[ViaPoint {
                    noise_var: 0.0,
                    ..via
                }],
            )
            .unwrap();
        let (m, _) = exact.marginal(&basis, 0.6, 0.0);
        assert!((m[0] - 0.3).abs() < 1e-9 && (m[1] + 0.7).abs() < 1e-9);
    }

    #[test]
    fn posterior_matches_the_information_form() {
        let (basis, d) = prior(2);
        let vias = [
            ViaPoint {
                phase: 0.0,
                q: vec![0.1, 0.2],
                noise_var: 0.01,
            },
            ViaPoint {
                phase: 1.0,
                q: vec![-0.4, 0.9],
                noise_var: 0.02,
            },
        ];
        let post = d.condition(&basis, &vias).unwrap();
        // Information form: P' = P + Hᵀ R⁻¹ H, P' mu' = P mu + Hᵀ R⁻¹ y.
        let p = d.cov.clone().try_inverse().unwrap();
        let mut info = p.clone();
        let mut rhs = &p * &d.mean;
        for v in &vias {
            let h = observation_matrix(&basis.row_at(v.phase), 2);
            info += h.transpose() * &h / v.noise_var;
            rhs += h.transpose() * DVector::from_vec(v.q.clone()) / v.noise_var;
        }
        let cov = info.clone().try_inverse().unwrap();
        let mean = &cov * rhs;
        assert!((&post.mean - mean).amax() < 1e-8);
        assert!((&post.cov - cov).amax() < 1e-8);
    }

    #[test]
    fn bad_via_points_name_the_field() {
        let (basis, d) = prior(3);
        let bad = ViaPoint {
            phase: 1.5,
            q: vec![0.0, 0.0],
            noise_var: 0.0,
        };
        assert_eq!(
            d.condition(&basis, &[bad]).unwrap_err().field(),
            Some("via_points[0].phase")
        );
        let bad = ViaPoint {
            phase: 0.5,
            q: vec![0.0],
            noise_var: 0.0,
        };
        assert_eq!(
            d.condition(&basis, &[bad]).unwrap_err().field(),
            Some("via_points[0].q")
        );
    }
}
