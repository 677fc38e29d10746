//! Joint trajectories to TCP pose trajectories and their ProMP weights.

use crate::promp::fit::{fit_weights, trajectory_from_weights};
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Isometry3, Quaternion, Translation3, UnitQuaternion};

/// Dimensions of a task-space trajectory: position and quaternion.
pub const TASK_DIMS: usize = 7;

/// Names of the task-space dimensions, in order.
pub const TASK_DIM_NAMES: [&str; TASK_DIMS] = ["x", "y", "z", "qx", "qy", "qz", "qw"];

/// TCP poses (`T x 7`: x, y, z, qx, qy, qz, qw) along a joint trajectory
/// (`T x dof`), quaternion signs continuous from `reference` (see the
/// module docs).
pub fn task_trajectory(
    robot: &Robot,
    joints: &DMatrix<f64>,
    reference: &UnitQuaternion<f64>,
) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(joints.nrows(), TASK_DIMS);
    let mut q = vec![0.0; joints.ncols()];
    for t in 0..joints.nrows() {
        for (j, v) in q.iter_mut().enumerate() {
            *v = joints[(t, j)];
        }
        let pose = robot.tcp_pose(&q);
        let p = pose.translation.vector;
        let c = pose.rotation.coords;
        for (k, v) in p.iter().chain(c.iter()).enumerate() {
            out[(t, k)] = *v;
        }
    }
    continuous_quaternions(&mut out, reference);
    out
}

/// Flip quaternion signs (columns 3..7) so that each sample is the one of
/// `±q` closer to the previous sample, the first the one closer to
/// `reference`.
pub fn continuous_quaternions(poses: &mut DMatrix<f64>, reference: &UnitQuaternion<f64>) {
    let mut previous = reference.coords;
    for t in 0..poses.nrows() {
        let mut c =
            nalgebra::Vector4::new(poses[(t, 3)], poses[(t, 4)], poses[(t, 5)], poses[(t, 6)]);
        if c.dot(&previous) < 0.0 {
            c = -c;
            for k in 0..4 {
                poses[(t, 3 + k)] = c[k];
            }
        }
        previous = c;
    }
}

/// The pose of one task-space row (the quaternion normalised; an error when
/// its norm is not a usable rotation).
pub fn pose_of_row(row: &[f64]) -> Result<Isometry3<f64>> {
    if row.len() != TASK_DIMS || row.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "task_space",
            format!("a pose needs {TASK_DIMS} finite numbers, got {row:?}"),
        ));
    }
    let q = Quaternion::new(row[6], row[3], row[4], row[5]);
    if q.norm() < 1e-6 {
        return Err(Error::Numerical(format!(
            "a task-space quaternion has norm {:.2e}: no orientation",
            q.norm()
        )));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(row[0], row[1], row[2]),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// Task-space weights (dimension-major, `7 * n_basis`) of the joint-space
/// weights `joint_weights` (joint-major, `dof * n_basis`).
pub fn task_weights(
    basis: &Basis,
    robot: &Robot,
    joint_weights: &[f64],
    reference: &UnitQuaternion<f64>,
) -> Result<DVector<f64>> {
    let n = robot.dof() * basis.n_basis();
    if joint_weights.len() != n {
        return Err(Error::invalid(
            "weights",
            format!(
                "expected {n} joint-space weights, got {}",
                joint_weights.len()
            ),
        ));
    }
    let joints = trajectory_from_weights(basis, joint_weights, robot.dof());
    fit_weights(basis, &task_trajectory(robot, &joints, reference))
}

/// The task-space weights of each demonstration given by its joint-space
/// weights, quaternions continuous from `reference`; errors name the
/// demonstration.
pub fn task_weight_set(
    basis: &Basis,
    robot: &Robot,
    demos: &[&[f64]],
    reference: &UnitQuaternion<f64>,
) -> Result<Vec<DVector<f64>>> {
    demos
        .iter()
        .enumerate()
        .map(|(k, w)| {
            task_weights(basis, robot, w, reference).map_err(|e| e.within(&format!("demos[{k}]")))
        })
        .collect()
}

/// The task-space weight distribution of demonstrations given by their
/// joint-space weights (at least two), quaternions continuous from
/// `reference`.
pub fn task_distribution(
    basis: &Basis,
    robot: &Robot,
    demos: &[&[f64]],
    reference: &UnitQuaternion<f64>,
) -> Result<WeightDistribution> {
    let weights = task_weight_set(basis, robot, demos, reference)?;
    WeightDistribution::from_demonstrations(&weights, TASK_DIMS, basis.n_basis())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;

    fn motion(robot: &Robot, basis: &Basis) -> DMatrix<f64> {
        let home = crate::robot::PANDA_HOME;
        DMatrix::from_fn(basis.n_samples(), robot.dof(), |t, j| {
            let z = basis.phases()[t];
            home[j] + 0.4 * (z * z * (3.0 - 2.0 * z)) * if j % 2 == 0 { 1.0 } else { -0.7 }
        })
    }

    #[test]
    fn fitted_task_weights_reproduce_the_tcp_poses() {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let joints = motion(&robot, &basis);
        let w = crate::promp::fit::fit_weights(&basis, &joints).unwrap();
        let reference = robot.tcp_pose(&crate::robot::PANDA_HOME).rotation;
        let tw = task_weights(&basis, &robot, w.as_slice(), &reference).unwrap();
        let task = trajectory_from_weights(&basis, tw.as_slice(), TASK_DIMS);
        let q_joint = trajectory_from_weights(&basis, w.as_slice(), robot.dof());
        for t in 0..basis.n_samples() {
            let q: Vec<f64> = q_joint.row(t).iter().copied().collect();
            let truth = robot.tcp_pose(&q);
            let row: Vec<f64> = task.row(t).iter().copied().collect();
            let pose = pose_of_row(&row).unwrap();
            let dp = (pose.translation.vector - truth.translation.vector).norm();
            assert!(dp < 5e-4, "t = {t}: {dp} m");
            assert!(pose.rotation.angle_to(&truth.rotation) < 5e-3, "t = {t}");
        }
    }

    #[test]
    fn quaternion_signs_are_continuous_and_start_near_the_reference() {
        let mut poses = DMatrix::zeros(5, TASK_DIMS);
        // Alternating signs of one rotation, then a sign flip mid-way.
        for t in 0..5 {
            let s = if t % 2 == 0 { 1.0 } else { -1.0 };
            let q = UnitQuaternion::from_euler_angles(0.1 * t as f64, 0.2, 0.3);
            for k in 0..4 {
                poses[(t, 3 + k)] = s * q.coords[k];
            }
        }
        let reference = UnitQuaternion::from_quaternion(Quaternion::new(-1.0, 0.0, 0.0, 0.0));
        continuous_quaternions(&mut poses, &reference);
        for t in 0..5 {
            let c: Vec<f64> = (3..7).map(|k| poses[(t, k)]).collect();
            let q = UnitQuaternion::from_euler_angles(0.1 * t as f64, 0.2, 0.3);
            // w of the rotation is positive; the reference has w = -1.
            assert!(
                c[3] < 0.0,
                "sample {t} took the sign away from the reference"
            );
            assert!((c[3] + q.coords[3]).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_rows_and_weights_are_refused() {
        assert!(pose_of_row(&[0.0; 6]).is_err());
        assert!(pose_of_row(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f64::NAN]).is_err());
        assert!(pose_of_row(&[0.0; 7]).is_err());
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let e = task_weights(&basis, &robot, &[0.0; 3], &UnitQuaternion::identity()).unwrap_err();
        assert_eq!(e.field(), Some("weights"));
    }
}
