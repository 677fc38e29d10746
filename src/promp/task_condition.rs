//! Gaussian conditioning of a weight distribution on a task-space
//! observation: the position of a point the final configuration puts
//! somewhere (the TCP at a pre-grasp goal), through the robot's forward
//! kinematics.
//!
//! The kinematics are nonlinear, so the posterior is computed as an
//! iterated Kalman update (Gauss–Newton on the posterior mode): linearise
//! `f(phi_T^T w)` at the current estimate `m_k` with `H_k = J(q_k) P`
//! (`P` picks the final phase sample of every joint), then
//!
//! `K_k = S H_kᵀ (H_k S H_kᵀ + R)⁻¹`,
//! `m_{k+1} = m + K_k (g - f(m_k) - H_k (m - m_k))`,
//!
//! with `(m, S)` the prior and `R = noise_var I`; the covariance is
//! `S - K H S` at the last linearisation. Only the three task directions
//! are observed: the posture (elbow, wrist, timing) keeps the prior's
//! spread, so a planner still has room to avoid obstacles.
//!
//! The kinematics come in as a function (position and its 3 x dof
//! Jacobian), so this module does not depend on [`crate::robot`].

use super::basis::Basis;
use super::distribution::{observation_matrix, WeightDistribution};
use super::psd;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Vector3};

/// Position of the observed point and its `3 x dof` Jacobian at `q`.
pub type PointKinematics<'a> = &'a dyn Fn(&[f64]) -> (Vector3<f64>, DMatrix<f64>);

/// A task-space observation of the final configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalPointObservation {
    /// Where the point is observed (m).
    pub position: Vector3<f64>,
    /// Observation noise variance per axis (m², > 0).
    pub noise_var: f64,
    /// Most linearisations.
    pub max_iterations: usize,
    /// Stop once the mean's point moves less than this between iterations (m).
    pub step_tolerance_m: f64,
}

impl FinalPointObservation {
    /// An observation at `position` with standard deviation `std_m`,
    /// iterated at most 20 times to 0.01 mm.
    pub fn new(position: Vector3<f64>, std_m: f64) -> Self {
        FinalPointObservation {
            position,
            noise_var: std_m * std_m,
            max_iterations: 20,
            step_tolerance_m: 1e-5,
        }
    }

    fn validate(&self) -> Result<()> {
        if self.position.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("goal.position", "must be finite"));
        }
        if !(self.noise_var.is_finite() && self.noise_var > 0.0) {
            return Err(Error::invalid(
                "goal.noise_var",
                format!("must be finite and > 0, got {}", self.noise_var),
            ));
        }
        if self.max_iterations == 0 {
            return Err(Error::invalid("goal.max_iterations", "must be at least 1"));
        }
        Ok(())
    }
}

/// The conditioned distribution and how the iteration went.
#[derive(Clone, Debug)]
pub struct TaskConditioned {
    /// The posterior.
    pub distribution: WeightDistribution,
    /// Linearisations used.
    pub iterations: usize,
    /// Distance from the posterior mean's final point to the observation (m).
    pub residual_m: f64,
}

impl WeightDistribution {
    /// The posterior `p(w | f(q_T(w)) = position)` under the observation's
    /// noise (see the module docs).
    pub fn condition_final_point(
        &self,
        basis: &Basis,
        observation: &FinalPointObservation,
        kinematics: PointKinematics,
    ) -> Result<TaskConditioned> {
        observation.validate()?;
        self.check_basis(basis)?;
        let problem = ModeProblem::new(self, basis, observation, kinematics)?;
        let mut estimate = self.mean.clone();
        let mut objective = problem.objective(&estimate);
        let mut iterations = 0;
        let last = loop {
            iterations += 1;
            let step = problem.gauss_newton(&estimate)?;
            let (next, value) = problem.line_search(&estimate, &step.target, objective);
            let moved = (&step.h * (&next - &estimate)).norm();
            estimate = next;
            objective = value;
            if moved < observation.step_tolerance_m || iterations >= observation.max_iterations {
                break step;
            }
        };
        let cov = psd::symmetrize(&(&self.cov - &last.gain * last.sigma_ht.transpose()));
        let residual_m = problem.residual(&estimate).norm();
        Ok(TaskConditioned {
            distribution: WeightDistribution {
                mean: estimate,
                cov,
                ..self.clone()
            },
            iterations,
            residual_m,
        })
    }
}

/// The posterior mode as a nonlinear least-squares problem:
/// `min ½ (w - m)ᵀ S⁻¹ (w - m) + ½ |g - f(P w)|² / r`.
struct ModeProblem<'a> {
    prior: &'a WeightDistribution,
    /// Cholesky factor of the prior covariance (for the objective).
    prior_chol: nalgebra::Cholesky<f64, nalgebra::Dyn>,
    pick: DMatrix<f64>,
    noise: DMatrix<f64>,
    observation: &'a FinalPointObservation,
    kinematics: PointKinematics<'a>,
}

/// One linearisation: the Kalman gain, `S Hᵀ`, `H`, and the full
/// Gauss–Newton target `m + K (g - f(w_k) - H (m - w_k))`.
struct Linearisation {
    gain: DMatrix<f64>,
    sigma_ht: DMatrix<f64>,
    h: DMatrix<f64>,
    target: DVector<f64>,
}

/// Halvings of a step before the line search gives up and takes the
/// smallest one.
const MAX_HALVINGS: usize = 30;

impl<'a> ModeProblem<'a> {
    fn new(
        prior: &'a WeightDistribution,
        basis: &Basis,
        observation: &'a FinalPointObservation,
        kinematics: PointKinematics<'a>,
    ) -> Result<Self> {
        let jitter = 1e-12 * prior.cov.diagonal().amax().max(1e-300);
        let regularised = &prior.cov + DMatrix::identity(prior.dim(), prior.dim()) * jitter;
        let prior_chol = psd::symmetrize(&regularised).cholesky().ok_or_else(|| {
            Error::Numerical("task-space conditioning: prior covariance not definite".into())
        })?;
        Ok(ModeProblem {
            prior,
            prior_chol,
            pick: observation_matrix(&basis.row_at(1.0), prior.n_joints),
            noise: DMatrix::identity(3, 3) * observation.noise_var,
            observation,
            kinematics,
        })
    }

    fn residual(&self, w: &DVector<f64>) -> Vector3<f64> {
        let q = &self.pick * w;
        self.observation.position - (self.kinematics)(q.as_slice()).0
    }

    fn objective(&self, w: &DVector<f64>) -> f64 {
        let d = w - &self.prior.mean;
        let prior_term = d.dot(&self.prior_chol.solve(&d));
        let fit_term = self.residual(w).norm_squared() / self.observation.noise_var;
        0.5 * (prior_term + fit_term)
    }

    fn gauss_newton(&self, w: &DVector<f64>) -> Result<Linearisation> {
        let q = &self.pick * w;
        let (point, jacobian) = (self.kinematics)(q.as_slice());
        check_jacobian(&jacobian, self.prior.n_joints)?;
        let h = &jacobian * &self.pick;
        let sigma_ht = &self.prior.cov * h.transpose();
        let innovation = psd::symmetrize(&(&h * &sigma_ht + &self.noise));
        let chol = innovation.cholesky().ok_or_else(|| {
            Error::Numerical("task-space conditioning: innovation not definite".into())
        })?;
        let gain = chol.solve(&sigma_ht.transpose()).transpose();
        let residual = DVector::from_column_slice((self.observation.position - point).as_slice());
        let target = &self.prior.mean + &gain * (residual - &h * (&self.prior.mean - w));
        Ok(Linearisation {
            gain,
            sigma_ht,
            h,
            target,
        })
    }

    /// The longest of `w + 2^-k (target - w)` that lowers the objective
    /// below `current`; the shortest tried when none does.
    fn line_search(
        &self,
        w: &DVector<f64>,
        target: &DVector<f64>,
        current: f64,
    ) -> (DVector<f64>, f64) {
        let direction = target - w;
        let mut fraction = 1.0;
        let mut candidate = target.clone();
        let mut value = self.objective(&candidate);
        for _ in 0..MAX_HALVINGS {
            if value < current {
                break;
            }
            fraction *= 0.5;
            candidate = w + &direction * fraction;
            value = self.objective(&candidate);
        }
        (candidate, value)
    }
}

fn check_jacobian(jacobian: &DMatrix<f64>, n_joints: usize) -> Result<()> {
    if jacobian.shape() != (3, n_joints) {
        return Err(Error::invalid(
            "kinematics",
            format!(
                "expected a 3 x {n_joints} Jacobian, got {} x {}",
                jacobian.nrows(),
                jacobian.ncols()
            ),
        ));
    }
    if jacobian.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical("kinematics: non-finite Jacobian".into()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::{PrompConfig, ViaPoint};
    use rand::{Rng, SeedableRng};

    fn prior(seed: u64, n_joints: usize) -> (Basis, WeightDistribution) {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = n_joints * basis.n_basis();
        let a = DMatrix::from_fn(n, n, |_, _| rng.gen_range(-1.0..1.0));
        let cov = &a * a.transpose() * 0.01 + DMatrix::identity(n, n) * 1e-3;
        let mean = DVector::from_fn(n, |_, _| rng.gen_range(-0.5..0.5));
        let d = WeightDistribution::new(mean, cov, n_joints, basis.n_basis()).unwrap();
        (basis, d)
    }

    #[test]
    fn linear_kinematics_give_the_closed_form_gaussian_posterior() {
        // f(q) = A q + b: the posterior is exact after one step and equals
        // conditioning the joint Gaussian of (w, A q_T(w) + b + noise).
        let (basis, d) = prior(4, 3);
        let a = DMatrix::from_row_slice(3, 3, &[1.0, 0.2, -0.3, 0.0, 0.8, 0.5, 0.4, -0.1, 1.1]);
        let b = Vector3::new(0.1, -0.2, 0.3);
        let f = |q: &[f64]| {
            let p = &a * DVector::from_column_slice(q);
            (Vector3::new(p[0], p[1], p[2]) + b, a.clone())
        };
        let goal = Vector3::new(0.4, 0.1, -0.2);
        let obs = FinalPointObservation::new(goal, 0.01);
        let post = d.condition_final_point(&basis, &obs, &f).unwrap();
        let h = &a * observation_matrix(&basis.row_at(1.0), 3);
        let s = &h * &d.cov * h.transpose() + DMatrix::identity(3, 3) * 1e-4;
        let s_inv = s.try_inverse().unwrap();
        let y = DVector::from_column_slice((goal - b).as_slice());
        let mean = &d.mean + &d.cov * h.transpose() * &s_inv * (y - &h * &d.mean);
        let cov = &d.cov - &d.cov * h.transpose() * &s_inv * &h * &d.cov;
        assert!((&post.distribution.mean - mean).amax() < 1e-10);
        assert!((&post.distribution.cov - cov).amax() < 1e-10);
        assert!(post.iterations <= 2);
    }

    #[test]
    fn identity_kinematics_match_joint_space_via_point_conditioning() {
        let (basis, d) = prior(5, 3);
        let f = |q: &[f64]| {
            (
                Vector3::new(q[0], q[1], q[2]),
                DMatrix::<f64>::identity(3, 3),
            )
        };
        let goal = Vector3::new(0.3, -0.2, 0.1);
        let obs = FinalPointObservation::new(goal, 0.02);
        let task = d.condition_final_point(&basis, &obs, &f).unwrap();
        let via = d
            .condition(
                &basis,
                &[ViaPoint {
                    phase: 1.0,
                    q: vec![0.3, -0.2, 0.1],
                    noise_var: 4e-4,
                }],
            )
            .unwrap();
        assert!((&task.distribution.mean - &via.mean).amax() < 1e-10);
        assert!((&task.distribution.cov - &via.cov).amax() < 1e-10);
    }

    #[test]
    fn nonlinear_kinematics_converge_to_the_goal_within_the_noise() {
        // A planar 3-link arm in the x-y plane (z fixed): the posterior's
        // final point lands within a few noise deviations of a reachable goal
        // more than 8 cm from the prior mean's, and the covariance stays PSD.
        let (basis, d) = prior(6, 3);
        let lengths = [0.4, 0.3, 0.2];
        let f = |q: &[f64]| {
            let mut angle = 0.0;
            let mut p = Vector3::zeros();
            let mut jac = DMatrix::zeros(3, 3);
            let mut angles = [0.0; 3];
            for i in 0..3 {
                angle += q[i];
                angles[i] = angle;
                p += Vector3::new(lengths[i] * angle.cos(), lengths[i] * angle.sin(), 0.0);
            }
            for j in 0..3 {
                for i in j..3 {
                    jac[(0, j)] -= lengths[i] * angles[i].sin();
                    jac[(1, j)] += lengths[i] * angles[i].cos();
                }
            }
            (p, jac)
        };
        let pick = observation_matrix(&basis.row_at(1.0), 3);
        let q_mean = &pick * &d.mean;
        let start = f(q_mean.as_slice()).0;
        // A reachable goal: where a visibly different posture puts the tip.
        let q_goal = q_mean + DVector::from_column_slice(&[0.25, -0.3, 0.2]);
        let goal = f(q_goal.as_slice()).0;
        assert!((goal - start).norm() > 0.08);
        let obs = FinalPointObservation::new(goal, 1e-3);
        let post = d.condition_final_point(&basis, &obs, &f).unwrap();
        assert!(post.residual_m < 3e-3, "residual {}", post.residual_m);
        let eig = post.distribution.cov.clone().symmetric_eigenvalues();
        assert!(eig.min() > -1e-12);
        // Observing a point never widens any direction.
        let diff = &d.cov - &post.distribution.cov;
        assert!(diff.symmetric_eigenvalues().min() > -1e-10);
    }

    #[test]
    fn bad_observations_are_rejected_with_their_field() {
        let (basis, d) = prior(7, 3);
        let f = |q: &[f64]| (Vector3::new(q[0], q[1], q[2]), DMatrix::identity(3, 3));
        let mut obs = FinalPointObservation::new(Vector3::new(f64::NAN, 0.0, 0.0), 0.01);
        let err = d.condition_final_point(&basis, &obs, &f).unwrap_err();
        assert!(err.to_string().contains("goal.position"), "{err}");
        obs.position = Vector3::zeros();
        obs.noise_var = 0.0;
        let err = d.condition_final_point(&basis, &obs, &f).unwrap_err();
        assert!(err.to_string().contains("goal.noise_var"), "{err}");
        let wrong = |_: &[f64]| (Vector3::zeros(), DMatrix::zeros(3, 2));
        let obs = FinalPointObservation::new(Vector3::zeros(), 0.01);
        assert!(d.condition_final_point(&basis, &obs, &wrong).is_err());
    }
}
