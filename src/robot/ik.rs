//! Inverse kinematics: damped least squares for a TCP position and an
//! optional approach axis (the TCP z axis), inside the joint limits, with a
//! null-space term pulling towards a chosen configuration.
//!
//! Each iteration solves `dq = Jᵀ (J Jᵀ + λ² I)⁻¹ e` for the stacked error
//! `e` (position, then the approach-axis rotation vector scaled by
//! [`IkOptions::axis_weight_m`]), adds the null-space term
//! `(I - Jᵀ (J Jᵀ + λ² I)⁻¹ J) · gain · (bias - q)`, caps the step and
//! projects `q` back into the (margin-shrunk) limits. When an attempt does
//! not converge, it restarts from deterministic random configurations.

use super::Robot;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Matrix3, Point3, Unit, Vector3};
use rand::{Rng, SeedableRng};
use serde::Serialize;

/// What the TCP should reach.
#[derive(Clone, Debug)]
pub struct IkTarget {
    /// TCP position in the base frame.
    pub position: Point3<f64>,
    /// Desired TCP z axis (the gripper axis) in the base frame, if any.
    pub approach_axis: Option<Unit<Vector3<f64>>>,
}

/// Settings of [`Robot::ik`].
#[derive(Clone, Debug)]
pub struct IkOptions {
    /// Iterations per attempt.
    pub max_iterations: usize,
    /// Position error counted as converged (m).
    pub tolerance_m: f64,
    /// Approach-axis error counted as converged (rad).
    pub axis_tolerance_rad: f64,
    /// Damping λ of the least-squares step.
    pub damping: f64,
    /// Configuration the null-space term pulls towards (`None`: no pull).
    pub null_space_bias: Option<Vec<f64>>,
    /// Gain of the null-space pull per iteration (0..1).
    pub null_space_gain: f64,
    /// Keep every joint this far inside its limits (rad).
    pub limit_margin_rad: f64,
    /// Largest change of any joint in one iteration (rad).
    pub max_step_rad: f64,
    /// Weight of the axis error against the position error (m per rad).
    pub axis_weight_m: f64,
    /// Extra attempts from random configurations when the seed fails.
    pub restarts: usize,
    /// Seed of the random restarts (deterministic).
    pub seed: u64,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            max_iterations: 300,
            tolerance_m: 1e-4,
            axis_tolerance_rad: 1e-3,
            damping: 0.02,
            null_space_bias: None,
            null_space_gain: 0.05,
            limit_margin_rad: 0.0,
            max_step_rad: 0.25,
            axis_weight_m: 0.2,
            restarts: 8,
            seed: 1,
        }
    }
}

/// Result of [`Robot::ik`]: the best configuration found and its errors.
#[derive(Clone, Debug, Serialize)]
pub struct IkSolution {
    /// Joint values, within the limits shrunk by the margin.
    pub q: Vec<f64>,
    /// Distance from the TCP to the target position (m).
    pub position_error_m: f64,
    /// Angle between the TCP z axis and the approach axis (rad; 0 when none).
    pub axis_error_rad: f64,
    /// Iterations used, all attempts together.
    pub iterations: usize,
    /// Whether both tolerances were met.
    pub converged: bool,
}

impl Robot {
    /// Solve for joint values that put the TCP at `target`, starting from
    /// `seed` (moved inside the limits if it lies outside). Returns the best
    /// configuration found with `converged` telling whether the tolerances
    /// were met; errors only on invalid input.
    pub fn ik(&self, target: &IkTarget, seed: &[f64], options: &IkOptions) -> Result<IkSolution> {
        self.validate_configuration("seed", seed)?;
        validate_target(target)?;
        let bounds = self.ik_bounds(options)?;
        if let Some(bias) = &options.null_space_bias {
            self.validate_configuration("options.null_space_bias", bias)?;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
        let mut total_iterations = 0;
        let mut best: Option<IkSolution> = None;
        for attempt in 0..=options.restarts {
            let start: Vec<f64> = if attempt == 0 {
                seed.iter()
                    .zip(&bounds)
                    .map(|(q, (lo, hi))| q.clamp(*lo, *hi))
                    .collect()
            } else {
                bounds
                    .iter()
                    .map(|(lo, hi)| rng.gen_range(*lo..=*hi))
                    .collect()
            };
            let mut solution = self.ik_attempt(target, start, &bounds, options);
            total_iterations += solution.iterations;
            solution.iterations = total_iterations;
            let better = best
                .as_ref()
                .is_none_or(|b| ik_score(&solution, options) < ik_score(b, options));
            if better {
                best = Some(solution);
            }
            if best.as_ref().is_some_and(|b| b.converged) {
                break;
            }
        }
        let mut best =
            best.ok_or_else(|| Error::Numerical("inverse kinematics made no attempt".into()))?;
        best.iterations = total_iterations;
        Ok(best)
    }

    /// Joint bounds shrunk by the margin, validated.
    fn ik_bounds(&self, options: &IkOptions) -> Result<Vec<(f64, f64)>> {
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(
                    format!("options.{field}"),
                    format!("must be a finite number > 0, got {v}"),
                ))
            }
        };
        positive("tolerance_m", options.tolerance_m)?;
        positive("axis_tolerance_rad", options.axis_tolerance_rad)?;
        positive("max_step_rad", options.max_step_rad)?;
        positive("axis_weight_m", options.axis_weight_m)?;
        if options.max_iterations == 0 {
            return Err(Error::invalid(
                "options.max_iterations",
                "must be at least 1",
            ));
        }
        for (field, v) in [
            ("damping", options.damping),
            ("null_space_gain", options.null_space_gain),
            ("limit_margin_rad", options.limit_margin_rad),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(
                    format!("options.{field}"),
                    format!("must be a finite number >= 0, got {v}"),
                ));
            }
        }
        self.limits
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let (lo, hi) = (
                    l.lower + options.limit_margin_rad,
                    l.upper - options.limit_margin_rad,
                );
                if lo > hi {
                    Err(Error::invalid(
                        "options.limit_margin_rad",
                        format!(
                            "{} leaves no room in the range of {}",
                            options.limit_margin_rad, self.joint_names[i]
                        ),
                    ))
                } else {
                    Ok((lo, hi))
                }
            })
            .collect()
    }

    fn ik_attempt(
        &self,
        target: &IkTarget,
        mut q: Vec<f64>,
        bounds: &[(f64, f64)],
        options: &IkOptions,
    ) -> IkSolution {
        let mut iterations = 0;
        loop {
            let (error, jacobian, position_error, axis_error) =
                self.ik_residual(target, &q, options);
            let converged = position_error < options.tolerance_m
                && (target.approach_axis.is_none() || axis_error < options.axis_tolerance_rad);
            let finish = |q: Vec<f64>, iterations| IkSolution {
                q,
                position_error_m: position_error,
                axis_error_rad: axis_error,
                iterations,
                converged,
            };
            let bias = options.null_space_bias.as_deref();
            if (converged && bias.is_none()) || iterations >= options.max_iterations {
                return finish(q, iterations);
            }
            // Only with zero damping at a singularity: keep what we have.
            let Some((task, null)) = dls_step(&jacobian, &error, &q, bias, options) else {
                return finish(q, iterations);
            };
            if converged && null.amax() < NULL_SPACE_SETTLED_RAD {
                return finish(q, iterations);
            }
            iterations += 1;
            let mut dq = task + null;
            let largest = dq.amax();
            if largest > options.max_step_rad {
                dq *= options.max_step_rad / largest;
            }
            for (i, x) in q.iter_mut().enumerate() {
                *x = (*x + dq[i]).clamp(bounds[i].0, bounds[i].1);
            }
        }
    }

    /// Stacked error, its Jacobian, and the position / axis errors at `q`.
    fn ik_residual(
        &self,
        target: &IkTarget,
        q: &[f64],
        options: &IkOptions,
    ) -> (DVector<f64>, DMatrix<f64>, f64, f64) {
        let n = self.dof();
        let full = self.tcp_jacobian(q);
        let tcp = self.tcp_pose(q);
        let position_error = target.position.coords - tcp.translation.vector;
        match target.approach_axis {
            None => {
                let jac = DMatrix::from_iterator(3, n, full.fixed_rows::<3>(0).iter().copied());
                (
                    DVector::from_column_slice(position_error.as_slice()),
                    jac,
                    position_error.norm(),
                    0.0,
                )
            }
            Some(desired) => {
                let z = tcp.rotation * Vector3::z();
                let (rotation, angle) = axis_rotation(&z, &desired);
                // Rotations about the TCP z axis do not change it: project them out.
                let perp = Matrix3::identity() - z * z.transpose();
                let angular = perp * full.fixed_rows::<3>(3);
                let w = options.axis_weight_m;
                let mut jac = DMatrix::zeros(6, n);
                jac.view_mut((0, 0), (3, n))
                    .copy_from(&full.fixed_rows::<3>(0));
                jac.view_mut((3, 0), (3, n)).copy_from(&(angular * w));
                let mut error = DVector::zeros(6);
                error.fixed_rows_mut::<3>(0).copy_from(&position_error);
                error.fixed_rows_mut::<3>(3).copy_from(&(rotation * w));
                (error, jac, position_error.norm(), angle)
            }
        }
    }
}

/// Once converged with a null-space bias, iterate until the null-space step
/// falls below this (rad).
const NULL_SPACE_SETTLED_RAD: f64 = 1e-4;

/// The damped least-squares task step `Jᵀ (J Jᵀ + λ² I)⁻¹ e` and the
/// null-space pull `(I - Jᵀ (J Jᵀ + λ² I)⁻¹ J) · gain · (bias - q)` (zero
/// without a bias). `None` when `J Jᵀ + λ² I` is singular (λ = 0).
fn dls_step(
    jacobian: &DMatrix<f64>,
    error: &DVector<f64>,
    q: &[f64],
    bias: Option<&[f64]>,
    options: &IkOptions,
) -> Option<(DVector<f64>, DVector<f64>)> {
    let (m, n) = jacobian.shape();
    let damped =
        jacobian * jacobian.transpose() + DMatrix::identity(m, m) * options.damping.powi(2);
    let pseudo = jacobian.transpose() * damped.cholesky()?.inverse();
    let task = &pseudo * error;
    let null = match bias {
        None => DVector::zeros(n),
        Some(bias) => {
            let pull = DVector::from_iterator(
                n,
                bias.iter()
                    .zip(q)
                    .map(|(b, x)| options.null_space_gain * (b - x)),
            );
            // The exact projector (not the damped one) so that the pull
            // never leaks into the task and stalls it short of the target.
            let gram = jacobian * jacobian.transpose() + DMatrix::identity(m, m) * 1e-12;
            let projector = match gram.cholesky() {
                Some(c) => DMatrix::identity(n, n) - jacobian.transpose() * c.inverse() * jacobian,
                None => DMatrix::identity(n, n) - &pseudo * jacobian,
            };
            projector * pull
        }
    };
    Some((task, null))
}

/// Rotation vector turning `z` onto `desired` (perpendicular to both) and
/// the angle between them.
fn axis_rotation(z: &Vector3<f64>, desired: &Unit<Vector3<f64>>) -> (Vector3<f64>, f64) {
    let cross = z.cross(desired);
    let sin = cross.norm();
    let angle = sin.atan2(z.dot(desired));
    if sin < 1e-12 {
        if angle > 1.0 {
            // Opposite axes: any perpendicular rotation works.
            let other = if z.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            return (z.cross(&other).normalize() * angle, angle);
        }
        return (Vector3::zeros(), angle);
    }
    (cross * (angle / sin), angle)
}

fn ik_score(solution: &IkSolution, options: &IkOptions) -> f64 {
    solution.position_error_m / options.tolerance_m
        + solution.axis_error_rad / options.axis_tolerance_rad
}

fn validate_target(target: &IkTarget) -> Result<()> {
    crate::error::ensure_finite("target.position", target.position.coords.as_slice())?;
    if let Some(axis) = &target.approach_axis {
        crate::error::ensure_finite("target.approach_axis", axis.as_slice())?;
        if (axis.norm() - 1.0).abs() > 1e-6 {
            return Err(Error::invalid(
                "target.approach_axis",
                "must be a unit vector",
            ));
        }
    }
    Ok(())
}
