//! Task-space recordings: the TCP's pose over time, as a lab may log it
//! beside (or instead of) the joint states.
//!
//! A recording is a table with the `time` column (as for joint recordings,
//! any rate, any length, the same time units) and seven columns named
//! `x`, `y`, `z` (TCP position, m, robot base frame) and `qx`, `qy`,
//! `qz`, `qw` (TCP orientation, a unit quaternion), in CSV or JSON like
//! [`super::file`]. Each quaternion must have norm 1 within
//! [`QUATERNION_NORM_TOLERANCE`] and each position lie within
//! [`MAX_POSITION_M`] of the base; signs are made continuous along the
//! recording, from the TCP orientation at the target's mean start (see
//! [`crate::task_space`]), and the recording is fitted on the phase like a
//! joint recording.

use super::file::{read_demonstration_with, ReadOptions};
use super::fit::fit_demonstration;
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::synth::dataset::{DistributionJson, TargetRecord};
use crate::task_space::{continuous_quaternions, TASK_DIMS, TASK_DIM_NAMES};
use crate::{Error, Result};
use nalgebra::{DVector, UnitQuaternion};
use std::path::{Path, PathBuf};

/// How far a recorded quaternion's norm may be from 1.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Farthest a recorded TCP position may be from the base (m).
pub const MAX_POSITION_M: f64 = 10.0;

/// Read a task-space recording and fit its weights (dimension-major,
/// `7 * n_basis`), the quaternion signs continuous from `reference`.
/// Errors name the file, and the row and column of a bad cell.
pub fn fit_task_recording(
    basis: &Basis,
    path: &Path,
    options: &ReadOptions,
    reference: &UnitQuaternion<f64>,
) -> Result<DVector<f64>> {
    let columns: Vec<String> = TASK_DIM_NAMES.iter().map(|c| c.to_string()).collect();
    // The columns are the task dimensions' own names: no joint renaming.
    let plain = ReadOptions {
        time_unit: options.time_unit,
        joint_columns: Vec::new(),
    };
    let mut demo = read_demonstration_with(path, &columns, &plain)?;
    check_poses(path, &demo.positions)?;
    continuous_quaternions(&mut demo.positions, reference);
    Ok(fit_demonstration(basis, &demo)?.weights)
}

/// Record the task-space weights fitted from a target's TCP recordings
/// (`files`, one per joint-space demonstration when the record has them,
/// at least two) and their distribution in `record`.
pub fn set_task_space(
    basis: &Basis,
    robot: &Robot,
    files: &[PathBuf],
    options: &ReadOptions,
    record: &mut TargetRecord,
) -> Result<()> {
    let n_demos = record.demos.len();
    if files.len() < 2 || (n_demos > 0 && files.len() != n_demos) {
        return Err(Error::invalid(
            "task_demos",
            format!(
                "{} recordings: give one per demonstration ({n_demos}), at least 2",
                files.len()
            ),
        ));
    }
    let reference = record.task_reference(robot);
    let weights = files
        .iter()
        .map(|f| fit_task_recording(basis, f, options, &reference))
        .collect::<Result<Vec<_>>>()?;
    let distribution =
        WeightDistribution::from_demonstrations(&weights, TASK_DIMS, basis.n_basis())?;
    for (demo, w) in record.demos.iter_mut().zip(&weights) {
        demo.task_weights = Some(w.as_slice().to_vec());
    }
    record.task_distribution = Some(DistributionJson::from(&distribution));
    Ok(())
}

/// Every position within reach of reason, every quaternion a unit one.
fn check_poses(path: &Path, poses: &nalgebra::DMatrix<f64>) -> Result<()> {
    for r in 0..poses.nrows() {
        let p = nalgebra::Vector3::new(poses[(r, 0)], poses[(r, 1)], poses[(r, 2)]);
        if p.norm() > MAX_POSITION_M {
            return Err(Error::file(
                path,
                format!(
                    "sample {r}: the TCP position is {:.3} m from the base (at most {MAX_POSITION_M} m)",
                    p.norm()
                ),
            ));
        }
        let q = nalgebra::Vector4::new(poses[(r, 3)], poses[(r, 4)], poses[(r, 5)], poses[(r, 6)]);
        if (q.norm() - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(Error::file(
                path,
                format!(
                    "sample {r}: the quaternion (qx, qy, qz, qw) has norm {:.6}, not 1 (within {QUATERNION_NORM_TOLERANCE})",
                    q.norm()
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;
    use std::io::Write;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.join(name);
        std::fs::File::create(&path)
            .unwrap()
            .write_all(text.as_bytes())
            .unwrap();
        path
    }

    /// A recording at 100 Hz of a straight move with a turn about z, the
    /// quaternion's sign flipped every other row when `flip` (as some
    /// loggers do); `edit` may change row `k`'s eight cells.
    fn recording_with(flip: bool, edit: impl Fn(usize, &mut [f64; 8])) -> String {
        let mut s = String::from("time,x,y,z,qx,qy,qz,qw\n");
        for k in 0..=200 {
            let t = k as f64 / 100.0;
            let z = t / 2.0;
            let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5 * z);
            let sign = if flip && k % 2 == 1 { -1.0 } else { 1.0 };
            let c = q.coords * sign;
            let mut row = [t, 0.4 + 0.2 * z, -0.1 * z, 0.7, c[0], c[1], c[2], c[3]];
            edit(k, &mut row);
            let cells: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            s += &(cells.join(",") + "\n");
        }
        s
    }

    fn recording(flip: bool) -> String {
        recording_with(flip, |_, _| {})
    }

    #[test]
    fn a_recording_with_flipping_signs_fits_the_continuous_motion() {
        let dir = tempfile::tempdir().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let a = write(dir.path(), "a.csv", &recording(false));
        let b = write(dir.path(), "b.csv", &recording(true));
        let options = ReadOptions::default();
        let reference = UnitQuaternion::identity();
        let wa = fit_task_recording(&basis, &a, &options, &reference).unwrap();
        let wb = fit_task_recording(&basis, &b, &options, &reference).unwrap();
        assert!((&wa - &wb).amax() < 1e-9);
        let traj = crate::promp::fit::trajectory_from_weights(&basis, wa.as_slice(), 7);
        let last = basis.n_samples() - 1;
        assert!((traj[(last, 0)] - 0.6).abs() < 1e-3);
        let qz = (0.25f64).sin();
        assert!((traj[(last, 5)] - qz).abs() < 1e-3, "{}", traj[(last, 5)]);
    }

    #[test]
    fn bad_quaternions_positions_and_columns_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let options = ReadOptions::default();
        let r = UnitQuaternion::identity();
        let far = recording_with(false, |k, row| {
            if k == 3 {
                row[1] = 40.0;
            }
        });
        let path = write(dir.path(), "far.csv", &far);
        let e = fit_task_recording(&basis, &path, &options, &r).unwrap_err();
        assert!(
            e.to_string().contains("far.csv") && e.to_string().contains("sample 3"),
            "{e}"
        );
        let unnormed = recording_with(false, |k, row| {
            if k == 7 {
                row[7] *= 1.5;
            }
        });
        let path = write(dir.path(), "unnormed.csv", &unnormed);
        let e = fit_task_recording(&basis, &path, &options, &r).unwrap_err();
        assert!(
            e.to_string().contains("sample 7") && e.to_string().contains("quaternion"),
            "{e}"
        );
        let missing = recording(false).replace("qw", "w");
        let path = write(dir.path(), "missing.csv", &missing);
        let e = fit_task_recording(&basis, &path, &options, &r).unwrap_err();
        assert!(e.to_string().contains("qw"), "{e}");
    }
}
