//! Probabilistic movement primitives (ProMP): the representation every other
//! stage speaks.
//!
//! A trajectory of `n_joints` joints sampled at `T` phases is
//! `Q = Phi W`, where `Phi` (`T x n_basis`) holds the normalised Gaussian
//! basis of the paper (Eq. 1–3) and column `j` of `W` holds the weights of
//! joint `j`. Weights travel as one joint-major vector,
//! `w[j * n_basis + i]` (the paper's `kron(I, Phi)` order).
//!
//! - [`config`] — [`PrompConfig`] (`n_basis`, `width`, `n_samples`).
//! - [`basis`] — [`Basis`]: the basis matrix, its phase derivative, rows at
//!   any phase.
//! - [`fit`] — weights from a trajectory of any length and back.
//! - [`distribution`] — [`WeightDistribution`]: from demonstrations,
//!   trajectory mean / covariance / per-time marginals, sampling.
//! - [`condition`] — Gaussian conditioning on via-points.
//! - [`task_condition`] — conditioning on where the final configuration
//!   puts a point (the TCP at a goal), through the kinematics.
//! - [`codec`] — the paper's `n(n+1)/2`-number LDLᵀ covariance code.
//! - [`annotation`] — the paper's per-joint annotation files.
//! - [`psd`] — symmetric positive semi-definite repair and factorisation.
//! - [`smooth`] — the prior without demonstrations: integrated squared
//!   acceleration, conditioned on the ends.

pub mod annotation;
pub mod basis;
pub mod codec;
pub mod condition;
pub mod config;
pub mod distribution;
pub mod fit;
pub mod psd;
pub mod smooth;
pub mod task_condition;

pub use annotation::Prior;
pub use basis::Basis;
pub use condition::ViaPoint;
pub use config::PrompConfig;
pub use distribution::WeightDistribution;
pub use fit::{fit_weights, trajectory_from_weights, velocities_from_weights};
pub use psd::repair_covariance;
pub use task_condition::{FinalPointObservation, TaskConditioned};
