//! A task-space weight distribution turned into a joint-space prior the
//! optimiser can use: draws tracked by inverse kinematics from the start,
//! and the joint-space ProMP fitted to the tracked draws.
//!
//! Tracking is damped least squares on the full TCP pose (position, and
//! orientation as the rotation vector of `R_target R(q)ᵀ` weighted by
//! [`JointPriorOptions::orientation_weight_m`]), a few iterations per
//! phase sample, each sample starting from the previous sample's
//! configuration (continuity; the first from the plan's start), every
//! configuration kept inside the joint limits. The prior's mean is the
//! tracked task-space mean (FK is not linear: the average of the tracked
//! draws would miss it by millimetres), its covariance the tracked draws'
//! spread about that mean. Draws run in parallel and
//! are collected in order: the prior is the same whatever the thread count.

use super::poses::{pose_of_row, TASK_DIMS};
use crate::promp::fit::{fit_weights, trajectory_from_weights};
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Isometry3, Matrix6, Vector6};
use rand::SeedableRng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How the task-space covariance reaches joint space.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Propagation {
    /// Track draws of the distribution and fit the joint ProMP to them
    /// (Monte Carlo: follows the IK's non-linearity, costs a tracking pass
    /// per draw).
    #[default]
    Draws,
    /// Track the mean only and map the covariance through the tracking's
    /// linearisation at it (`A Σ Aᵀ`, `A` the damped pseudo-inverse of
    /// the pose Jacobian along the mean, between the two bases): one
    /// tracking pass.
    Linearised,
}

/// Settings of [`joint_prior`].
#[derive(Clone, Debug)]
pub struct JointPriorOptions {
    /// How the covariance is propagated.
    pub propagation: Propagation,
    /// Task-space draws tracked (the mean is always the first; with
    /// [`Propagation::Linearised`] only the mean).
    pub draws: usize,
    /// Seed of the draws.
    pub seed: u64,
    /// Most IK iterations per phase sample.
    pub iterations_per_sample: usize,
    /// Damping λ of the least-squares step.
    pub damping: f64,
    /// Metres that one radian of orientation error counts as.
    pub orientation_weight_m: f64,
    /// Position error at which a sample is tracked (m).
    pub tolerance_m: f64,
    /// Orientation error at which a sample is tracked (rad).
    pub tolerance_rad: f64,
    /// Largest change of any joint in one iteration (rad).
    pub max_step_rad: f64,
}

impl Default for JointPriorOptions {
    fn default() -> Self {
        JointPriorOptions {
            propagation: Propagation::Draws,
            draws: 64,
            seed: 0,
            iterations_per_sample: 10,
            damping: 0.01,
            orientation_weight_m: 0.2,
            tolerance_m: 1e-4,
            tolerance_rad: 1e-3,
            max_step_rad: 0.25,
        }
    }
}

/// How closely the joint-space prior follows the task-space distribution.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct JointPriorReport {
    /// Draws tracked (the mean included).
    pub draws: usize,
    /// Largest TCP position error of the tracked mean over its samples (m).
    pub mean_position_error_m: f64,
    /// Largest orientation error of the tracked mean (rad).
    pub mean_orientation_error_rad: f64,
    /// Median over draws of each draw's largest position error (m).
    pub median_draw_position_error_m: f64,
    /// Largest position error of any draw at its final sample (m): where
    /// a draw is out of the arm's reach.
    pub max_final_position_error_m: f64,
}

/// The joint-space prior of `task` (a task-space distribution, see
/// [`super::poses`]) for a motion from `start`; see the module docs.
/// `stop` is asked before each draw: when it says stop (a request's
/// deadline), the work ends with [`Error::Cancelled`].
pub fn joint_prior(
    robot: &Robot,
    basis: &Basis,
    task: &WeightDistribution,
    start: &[f64],
    options: &JointPriorOptions,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<(WeightDistribution, JointPriorReport)> {
    check_inputs(robot, basis, task, start, options)?;
    let inputs = Inputs {
        robot,
        basis,
        task,
        start,
        options,
        stop,
    };
    match options.propagation {
        Propagation::Draws => by_draws(&inputs),
        Propagation::Linearised => linearised(&inputs),
    }
}

/// What [`joint_prior`] was given, checked.
struct Inputs<'a> {
    robot: &'a Robot,
    basis: &'a Basis,
    task: &'a WeightDistribution,
    start: &'a [f64],
    options: &'a JointPriorOptions,
    stop: &'a (dyn Fn() -> bool + Sync),
}

impl Inputs<'_> {
    /// `Err(Cancelled)` when the caller says stop.
    fn check_stop(&self) -> Result<()> {
        if (self.stop)() {
            return Err(Error::Cancelled(
                "the deadline passed while the task-space prior was tracked".into(),
            ));
        }
        Ok(())
    }

    /// Track the task-space trajectory of weights `w` from the start.
    fn track_weights(&self, w: &DVector<f64>) -> Result<Tracked> {
        let poses = trajectory_from_weights(self.basis, w.as_slice(), TASK_DIMS);
        track(self.robot, &poses, self.start, self.options)
    }
}

/// [`Propagation::Draws`]: the mean and `draws - 1` seeded draws tracked in
/// parallel (collected in order), the joint ProMP fitted to them about the
/// tracked mean.
fn by_draws(inputs: &Inputs) -> Result<(WeightDistribution, JointPriorReport)> {
    let (robot, basis, task, options) = (inputs.robot, inputs.basis, inputs.task, inputs.options);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
    let mut draws = vec![task.mean.clone()];
    draws.extend(task.sample(&mut rng, options.draws - 1));
    let tracked = draws
        .par_iter()
        .map(|w| {
            inputs.check_stop()?;
            inputs.track_weights(w)
        })
        .collect::<Result<Vec<Tracked>>>()?;
    let weights = tracked
        .iter()
        .map(|t| fit_weights(basis, &t.joints))
        .collect::<Result<Vec<DVector<f64>>>>()?;
    let prior = about_the_tracked_mean(&weights, robot.dof(), basis.n_basis())?;
    let mut worst: Vec<f64> = tracked.iter().map(|t| t.max_position_m).collect();
    worst.sort_by(f64::total_cmp);
    let report = JointPriorReport {
        draws: tracked.len(),
        mean_position_error_m: tracked[0].max_position_m,
        mean_orientation_error_rad: tracked[0].max_orientation_rad,
        median_draw_position_error_m: worst[worst.len() / 2],
        max_final_position_error_m: tracked
            .iter()
            .map(|t| t.final_position_m)
            .fold(0.0, f64::max),
    };
    Ok((prior, report))
}

/// [`Propagation::Linearised`]: the tracked mean, and the task-space
/// covariance mapped through `A = P · blockdiag_t(J_t⁺ G_t) · Φ` (`Φ` the
/// task basis, `G_t` the quaternion-to-angular-velocity map at the mean,
/// `J_t⁺` the damped pseudo-inverse of the weighted pose Jacobian at the
/// tracked configuration, `P` the joint basis' least-squares projector).
fn linearised(inputs: &Inputs) -> Result<(WeightDistribution, JointPriorReport)> {
    let (robot, basis, task, options) = (inputs.robot, inputs.basis, inputs.task, inputs.options);
    inputs.check_stop()?;
    let poses = trajectory_from_weights(basis, task.mean.as_slice(), TASK_DIMS);
    let tracked = track(robot, &poses, inputs.start, options)?;
    let mean = fit_weights(basis, &tracked.joints)?;
    let (n, nb, w) = (robot.dof(), basis.n_basis(), options.orientation_weight_m);
    let (phi, projector) = (basis.matrix(), basis.projector());
    let mut a = DMatrix::<f64>::zeros(n * nb, TASK_DIMS * nb);
    for t in 0..basis.n_samples() {
        let q: Vec<f64> = tracked.joints.row(t).iter().copied().collect();
        let row: Vec<f64> = poses.row(t).iter().copied().collect();
        let b = damped_pseudo_inverse(robot, &q, w, options.damping) * pose_rate(&row, w);
        for j in 0..n {
            for d in 0..TASK_DIMS {
                let bjd = b[(j, d)];
                if bjd == 0.0 {
                    continue;
                }
                for i in 0..nb {
                    let pb = projector[(i, t)] * bjd;
                    for k in 0..nb {
                        a[(j * nb + i, d * nb + k)] += pb * phi[(t, k)];
                    }
                }
            }
        }
    }
    let cov = &a * &task.cov * a.transpose();
    let prior = WeightDistribution::new(mean, (&cov + cov.transpose()) * 0.5, n, nb)?;
    let report = JointPriorReport {
        draws: 1,
        mean_position_error_m: tracked.max_position_m,
        mean_orientation_error_rad: tracked.max_orientation_rad,
        median_draw_position_error_m: tracked.max_position_m,
        max_final_position_error_m: tracked.final_position_m,
    };
    Ok((prior, report))
}

/// `Jᵀ (J Jᵀ + λ² I)⁻¹` (dof x 6) of the TCP Jacobian at `q` with its
/// angular rows weighted by `weight`.
fn damped_pseudo_inverse(robot: &Robot, q: &[f64], weight: f64, damping: f64) -> DMatrix<f64> {
    let mut jac = robot.tcp_jacobian(q);
    for r in 3..6 {
        for c in 0..jac.ncols() {
            jac[(r, c)] *= weight;
        }
    }
    let jjt: Matrix6<f64> = &jac * jac.transpose() + Matrix6::identity() * damping * damping;
    let inverse = jjt.try_inverse().unwrap_or_else(Matrix6::zeros);
    DMatrix::from_iterator(jac.ncols(), 6, (jac.transpose() * inverse).iter().copied())
}

/// The weighted twist `[dp; weight·ω]` (6 x 7) per unit change of a
/// task-space row `[p; quaternion]` at `row`: `ω = 2 (dq ⊗ q̄*)` (vector
/// part) for the normalised quaternion `q̄`, whose own direction does not
/// rotate.
fn pose_rate(row: &[f64], weight: f64) -> DMatrix<f64> {
    let mut g = DMatrix::zeros(6, TASK_DIMS);
    for k in 0..3 {
        g[(k, k)] = 1.0;
    }
    let q = nalgebra::Quaternion::new(row[6], row[3], row[4], row[5]);
    let norm = q.norm().max(1e-12);
    let conj = q.conjugate() / norm;
    for (col, unit) in [
        (3, [1.0, 0.0, 0.0, 0.0]),
        (4, [0.0, 1.0, 0.0, 0.0]),
        (5, [0.0, 0.0, 1.0, 0.0]),
        (6, [0.0, 0.0, 0.0, 1.0]),
    ] {
        let dq = nalgebra::Quaternion::new(unit[3], unit[0], unit[1], unit[2]) / norm;
        let omega = (dq * conj).imag() * 2.0;
        for k in 0..3 {
            g[(3 + k, col)] = weight * omega[k];
        }
    }
    g
}

/// The distribution centred on the tracked mean (`weights[0]`) with the
/// spread of the tracked draws about it: FK is not linear, so the average
/// of the draws' joint weights would not put the TCP on the task-space
/// mean; the tracked mean does.
fn about_the_tracked_mean(
    weights: &[DVector<f64>],
    n_joints: usize,
    n_basis: usize,
) -> Result<WeightDistribution> {
    let mean = weights[0].clone();
    let n = mean.len();
    let mut cov = DMatrix::zeros(n, n);
    for w in &weights[1..] {
        let d = w - &mean;
        cov.ger(1.0, &d, &d, 1.0);
    }
    cov /= (weights.len() - 1) as f64;
    WeightDistribution::new(mean, cov, n_joints, n_basis)
}

fn check_inputs(
    robot: &Robot,
    basis: &Basis,
    task: &WeightDistribution,
    start: &[f64],
    options: &JointPriorOptions,
) -> Result<()> {
    robot.validate_configuration("start", start)?;
    task.check_basis(basis)?;
    if task.n_joints != TASK_DIMS {
        return Err(Error::invalid(
            "prior",
            format!(
                "a task-space distribution has {TASK_DIMS} dimensions, this one {}",
                task.n_joints
            ),
        ));
    }
    if options.draws < 2 {
        return Err(Error::invalid(
            "draws",
            "at least 2 (the mean and one draw)",
        ));
    }
    let positive = [
        ("damping", options.damping),
        ("orientation_weight_m", options.orientation_weight_m),
        ("tolerance_m", options.tolerance_m),
        ("tolerance_rad", options.tolerance_rad),
        ("max_step_rad", options.max_step_rad),
    ];
    for (field, v) in positive {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(
                field,
                format!("must be finite and > 0, got {v}"),
            ));
        }
    }
    Ok(())
}

/// One tracked task-space trajectory.
struct Tracked {
    joints: DMatrix<f64>,
    max_position_m: f64,
    max_orientation_rad: f64,
    final_position_m: f64,
}

/// Track the poses (`T x 7`) from `start`, sample by sample.
fn track(
    robot: &Robot,
    poses: &DMatrix<f64>,
    start: &[f64],
    options: &JointPriorOptions,
) -> Result<Tracked> {
    let mut q = start.to_vec();
    let mut joints = DMatrix::zeros(poses.nrows(), robot.dof());
    let (mut max_position_m, mut max_orientation_rad, mut final_position_m) = (0.0f64, 0.0f64, 0.0);
    for t in 0..poses.nrows() {
        let row: Vec<f64> = poses.row(t).iter().copied().collect();
        let target = pose_of_row(&row)?;
        let (position, orientation) = reach(robot, &target, &mut q, options);
        max_position_m = max_position_m.max(position);
        max_orientation_rad = max_orientation_rad.max(orientation);
        final_position_m = position;
        for (j, v) in q.iter().enumerate() {
            joints[(t, j)] = *v;
        }
    }
    Ok(Tracked {
        joints,
        max_position_m,
        max_orientation_rad,
        final_position_m,
    })
}

/// Move `q` towards `target` by damped least-squares steps; returns the
/// remaining position and orientation errors.
fn reach(
    robot: &Robot,
    target: &Isometry3<f64>,
    q: &mut [f64],
    options: &JointPriorOptions,
) -> (f64, f64) {
    let w = options.orientation_weight_m;
    let mut errors = pose_error(robot, target, q, w);
    for _ in 0..options.iterations_per_sample {
        if errors.1 < options.tolerance_m && errors.2 < options.tolerance_rad {
            break;
        }
        let mut dq = damped_pseudo_inverse(robot, q, w, options.damping) * errors.0;
        let largest = dq.amax();
        if largest > options.max_step_rad {
            dq *= options.max_step_rad / largest;
        }
        for ((x, d), l) in q.iter_mut().zip(dq.iter()).zip(robot.limits()) {
            *x = (*x + d).clamp(l.lower, l.upper);
        }
        errors = pose_error(robot, target, q, w);
    }
    (errors.1, errors.2)
}

/// The weighted 6-D pose error at `q`, and its position (m) and
/// orientation (rad) parts.
fn pose_error(
    robot: &Robot,
    target: &Isometry3<f64>,
    q: &[f64],
    weight: f64,
) -> (Vector6<f64>, f64, f64) {
    let pose = robot.tcp_pose(q);
    let dp = target.translation.vector - pose.translation.vector;
    let dr = (target.rotation * pose.rotation.inverse()).scaled_axis();
    let e = Vector6::new(
        dp.x,
        dp.y,
        dp.z,
        weight * dr.x,
        weight * dr.y,
        weight * dr.z,
    );
    (e, dp.norm(), dr.norm())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;
    use crate::task_space::poses::task_distribution;

    fn never() -> bool {
        false
    }

    /// Demonstrations around a reaching motion from home, as joint weights.
    fn demos(robot: &Robot, basis: &Basis) -> Vec<Vec<f64>> {
        let home = crate::robot::PANDA_HOME;
        (0..10)
            .map(|k| {
                let s = 1.0 + 0.05 * (k as f64 - 4.5);
                let joints = DMatrix::from_fn(basis.n_samples(), robot.dof(), |t, j| {
                    let z = basis.phases()[t];
                    let ramp = z * z * (3.0 - 2.0 * z);
                    home[j] + s * ramp * [0.3, 0.4, 0.1, 0.6, -0.2, -0.5, 0.3][j]
                });
                fit_weights(basis, &joints).unwrap().as_slice().to_vec()
            })
            .collect()
    }

    /// The Panda, the default basis and the task-space distribution of
    /// [`demos`].
    fn demo_task() -> (Robot, Basis, WeightDistribution) {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let joint_demos = demos(&robot, &basis);
        let refs: Vec<&[f64]> = joint_demos.iter().map(|d| d.as_slice()).collect();
        let reference = robot.tcp_pose(&crate::robot::PANDA_HOME).rotation;
        let task = task_distribution(&basis, &robot, &refs, &reference).unwrap();
        (robot, basis, task)
    }

    #[test]
    fn the_joint_prior_of_a_task_distribution_follows_its_poses() {
        let (robot, basis, task) = demo_task();
        let options = JointPriorOptions {
            draws: 24,
            ..JointPriorOptions::default()
        };
        let start = crate::robot::PANDA_HOME.to_vec();
        let (prior, report) = joint_prior(&robot, &basis, &task, &start, &options, &never).unwrap();
        assert_eq!(report.draws, 24);
        assert!(report.mean_position_error_m < 1e-3, "{report:?}");
        assert!(report.mean_orientation_error_rad < 1e-2, "{report:?}");
        // The prior mean's final TCP is the task mean's final pose.
        let last = basis.n_samples() - 1;
        let q_mean = trajectory_from_weights(&basis, prior.mean.as_slice(), 7);
        let task_mean = trajectory_from_weights(&basis, task.mean.as_slice(), TASK_DIMS);
        let q: Vec<f64> = q_mean.row(last).iter().copied().collect();
        let want: Vec<f64> = task_mean.row(last).iter().copied().collect();
        let dp = (robot.tcp_pose(&q).translation.vector
            - pose_of_row(&want).unwrap().translation.vector)
            .norm();
        assert!(dp < 5e-3, "final TCP {dp} m from the task mean's");
        // Same options, same prior, whatever the thread count.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let (again, _) = pool
            .install(|| joint_prior(&robot, &basis, &task, &start, &options, &never))
            .unwrap();
        assert_eq!(again.mean, prior.mean);
        assert_eq!(again.cov, prior.cov);
        // A stop ends the work with Cancelled.
        let e = joint_prior(&robot, &basis, &task, &start, &options, &|| true).unwrap_err();
        assert!(matches!(e, Error::Cancelled(_)), "{e}");
    }

    #[test]
    fn linearised_propagation_agrees_with_the_draws() {
        // Same mean (the tracked task mean); final-sample joint spreads
        // within the Monte Carlo error of 256 draws plus the linearisation's.
        let (robot, basis, task) = demo_task();
        let start = crate::robot::PANDA_HOME.to_vec();
        let draws = JointPriorOptions {
            draws: 256,
            ..JointPriorOptions::default()
        };
        let linear = JointPriorOptions {
            propagation: Propagation::Linearised,
            ..JointPriorOptions::default()
        };
        let (a, _) = joint_prior(&robot, &basis, &task, &start, &draws, &never).unwrap();
        let (b, report) = joint_prior(&robot, &basis, &task, &start, &linear, &never).unwrap();
        assert_eq!(report.draws, 1);
        assert!((&a.mean - &b.mean).amax() < 1e-12);
        let last = basis.n_samples() - 1;
        let (sa, sb) = (a.trajectory_std(&basis, 0.0), b.trajectory_std(&basis, 0.0));
        for j in 0..7 {
            let (x, y) = (sa[(last, j)], sb[(last, j)]);
            assert!(
                y > 0.0 && (x - y).abs() <= 0.25 * x.max(y) + 1e-4,
                "joint {j}: {x} vs {y}"
            );
        }
    }

    #[test]
    fn joint_space_distributions_and_bad_options_are_refused() {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let joint_demos = demos(&robot, &basis);
        let w: Vec<DVector<f64>> = joint_demos
            .iter()
            .map(|d| DVector::from_column_slice(d))
            .collect();
        let joint = WeightDistribution::from_demonstrations(&w, 7, 8).unwrap();
        let start = crate::robot::PANDA_HOME.to_vec();
        let e = joint_prior(
            &robot,
            &basis,
            &joint,
            &start,
            &JointPriorOptions::default(),
            &never,
        );
        // 7 joints look like 7 task dimensions: the shape cannot tell them
        // apart, so the caller's model config must; only other shapes fail.
        assert!(e.is_ok());
        let narrow = WeightDistribution::from_demonstrations(
            &w.iter()
                .map(|v| v.rows(0, 48).into_owned())
                .collect::<Vec<_>>(),
            6,
            8,
        )
        .unwrap();
        let e = joint_prior(
            &robot,
            &basis,
            &narrow,
            &start,
            &JointPriorOptions::default(),
            &never,
        )
        .unwrap_err();
        assert_eq!(e.field(), Some("prior"));
        let bad = JointPriorOptions {
            damping: f64::NAN,
            ..JointPriorOptions::default()
        };
        let (_, _, task) = demo_task();
        let e = joint_prior(&robot, &basis, &task, &start, &bad, &never).unwrap_err();
        assert_eq!(e.field(), Some("damping"));
        let mut short = start.clone();
        short.pop();
        assert!(joint_prior(
            &robot,
            &basis,
            &task,
            &short,
            &JointPriorOptions::default(),
            &never
        )
        .is_err());
    }
}
