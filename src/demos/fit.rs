//! ProMP weights of recorded demonstrations, and the prior they make.
//!
//! Each recording is mapped onto the phase `[0, 1]` (first to last sample),
//! interpolated onto the basis' phase grid by cubic Lagrange interpolation
//! through the four nearest samples (error O(h⁴) for a smooth motion, so a
//! recording at 30 Hz and one at 1 kHz of the same motion give the same
//! weights), and fitted with the basis' least-squares projector, exactly as
//! [`crate::promp::fit_weights`] fits the generator's demonstrations. The
//! residual is measured at the recorded samples, not on the grid.

use super::file::Demonstration;
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Tolerance (rad or m) on the joint limits when checking recordings.
pub const LIMIT_TOLERANCE: f64 = 1e-9;

/// One demonstration's fit.
#[derive(Clone, Debug)]
pub struct DemoFit {
    /// Joint-major weights (`n_joints * n_basis`).
    pub weights: DVector<f64>,
    /// Root mean square of the fitted trajectory minus the recording, over
    /// every recorded sample and joint.
    pub rms_residual: f64,
    /// Largest absolute difference at any recorded sample and joint.
    pub max_residual: f64,
}

/// What `dpmp prior fit` reports per demonstration.
#[derive(Clone, Debug, Serialize)]
pub struct DemoReport {
    /// The file.
    pub file: String,
    /// Number of samples.
    pub samples: usize,
    /// First to last sample (s).
    pub duration_s: f64,
    /// Mean sampling rate (Hz).
    pub rate_hz: f64,
    /// RMS fit residual over all samples and joints (rad).
    pub rms_residual_rad: f64,
    /// Largest fit residual (rad).
    pub max_residual_rad: f64,
}

/// A prior fitted to demonstrations.
#[derive(Clone, Debug)]
pub struct PriorFit {
    /// Sample mean and covariance of the demonstrations' weights.
    pub distribution: WeightDistribution,
    /// Each demonstration's figures, in input order.
    pub demos: Vec<DemoReport>,
    /// Each demonstration's weights, in input order.
    pub weights: Vec<DVector<f64>>,
}

impl PriorFit {
    /// The median demonstration duration (s): the natural duration of a
    /// motion drawn from the prior.
    pub fn median_duration_s(&self) -> f64 {
        let mut d: Vec<f64> = self.demos.iter().map(|r| r.duration_s).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    }

    /// The largest RMS fit residual of any demonstration (rad).
    pub fn max_rms_residual(&self) -> f64 {
        self.demos
            .iter()
            .map(|d| d.rms_residual_rad)
            .fold(0.0, f64::max)
    }
}

/// The demonstration's positions at `phases` (each in `[0, 1]`), by cubic
/// Lagrange interpolation through the four nearest samples (linear with
/// fewer than four samples).
pub fn positions_at_phases(demo: &Demonstration, phases: &[f64]) -> DMatrix<f64> {
    let z = demo.phases();
    let l = z.len();
    let mut out = DMatrix::zeros(phases.len(), demo.n_joints());
    for (k, &p) in phases.iter().enumerate() {
        // z[i] <= p < z[i + 1] (the last interval includes p = 1).
        let i = z
            .partition_point(|&zi| zi <= p)
            .saturating_sub(1)
            .min(l - 2);
        let (start, count) = if l >= 4 {
            (i.saturating_sub(1).min(l - 4), 4)
        } else {
            (i, 2)
        };
        let nodes = &z[start..start + count];
        for m in 0..count {
            let weight = lagrange_weight(nodes, m, p);
            let row = demo.positions.row(start + m) * weight;
            let mut target = out.row_mut(k);
            target += row;
        }
    }
    out
}

/// The `m`-th Lagrange basis polynomial through `nodes`, at `x`.
fn lagrange_weight(nodes: &[f64], m: usize, x: f64) -> f64 {
    nodes
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != m)
        .map(|(_, &zi)| (x - zi) / (nodes[m] - zi))
        .product()
}

/// Fit one demonstration's weights; an error naming its file when it has
/// fewer samples than basis functions.
pub fn fit_demonstration(basis: &Basis, demo: &Demonstration) -> Result<DemoFit> {
    let needed = basis.n_basis().max(4);
    if demo.len() < needed {
        return Err(Error::file(
            &demo.source,
            format!(
                "too short: {} samples; fitting {} basis functions needs at least {needed}",
                demo.len(),
                basis.n_basis()
            ),
        ));
    }
    let on_grid = positions_at_phases(demo, basis.phases());
    let w = basis.projector() * on_grid; // n_basis x n_joints
    let (rms_residual, max_residual) = residual(basis, demo, &w);
    Ok(DemoFit {
        weights: DVector::from_column_slice(w.as_slice()),
        rms_residual,
        max_residual,
    })
}

/// RMS and largest difference between the fitted trajectory and the
/// recording at the recorded samples.
fn residual(basis: &Basis, demo: &Demonstration, w: &DMatrix<f64>) -> (f64, f64) {
    let (mut sum, mut max) = (0.0_f64, 0.0_f64);
    for (s, z) in demo.phases().into_iter().enumerate() {
        let fitted = basis.row_at(z).transpose() * w;
        for (j, q) in fitted.iter().enumerate() {
            let d = (q - demo.positions[(s, j)]).abs();
            sum += d * d;
            max = max.max(d);
        }
    }
    ((sum / (demo.positions.len() as f64)).sqrt(), max)
}

/// Every sample inside the robot's joint limits; the error names the file,
/// the joint and the time.
pub fn check_limits(robot: &Robot, demo: &Demonstration) -> Result<()> {
    for (j, (limit, name)) in robot.limits().iter().zip(robot.joint_names()).enumerate() {
        let column = demo.positions.column(j);
        let outside = column
            .iter()
            .position(|&q| q < limit.lower - LIMIT_TOLERANCE || q > limit.upper + LIMIT_TOLERANCE);
        if let Some(s) = outside {
            return Err(Error::file(
                &demo.source,
                format!(
                    "{name} = {} at t = {} s is outside its limits [{}, {}]",
                    column[s], demo.time_s[s], limit.lower, limit.upper
                ),
            ));
        }
    }
    Ok(())
}

/// Fit a prior to demonstrations of `robot` (in its joint order): each one
/// checked against the joint limits and fitted, then the sample mean and
/// covariance of the weights. At least two demonstrations.
pub fn fit_prior(basis: &Basis, robot: &Robot, demos: &[Demonstration]) -> Result<PriorFit> {
    let n_joints = robot.dof();
    let mut weights = Vec::with_capacity(demos.len());
    let mut reports = Vec::with_capacity(demos.len());
    for demo in demos {
        if demo.n_joints() != n_joints {
            return Err(Error::file(
                &demo.source,
                format!("{} joints, the robot has {n_joints}", demo.n_joints()),
            ));
        }
        check_limits(robot, demo)?;
        let fit = fit_demonstration(basis, demo)?;
        reports.push(DemoReport {
            file: demo.source.display().to_string(),
            samples: demo.len(),
            duration_s: demo.duration_s(),
            rate_hz: (demo.len() - 1) as f64 / demo.duration_s(),
            rms_residual_rad: fit.rms_residual,
            max_residual_rad: fit.max_residual,
        });
        weights.push(fit.weights);
    }
    let distribution =
        WeightDistribution::from_demonstrations(&weights, n_joints, basis.n_basis())?;
    Ok(PriorFit {
        distribution,
        demos: reports,
        weights,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;
    use std::path::Path;

    /// A smooth two-joint motion sampled at `rate_hz` for `duration_s`.
    fn recording(rate_hz: f64, duration_s: f64) -> Demonstration {
        let n = (rate_hz * duration_s).round() as usize + 1;
        let time: Vec<f64> = (0..n).map(|k| 3.0 + k as f64 / rate_hz).collect();
        let mut q = DMatrix::zeros(n, 2);
        for (k, t) in time.iter().enumerate() {
            let z = (t - 3.0) / duration_s;
            q[(k, 0)] = 0.3 * (std::f64::consts::PI * z).sin() + 0.1 * z;
            q[(k, 1)] = -0.5 + 0.8 * z * z * (3.0 - 2.0 * z);
        }
        Demonstration::new(Path::new("r.csv"), time, q).unwrap()
    }

    #[test]
    fn cubic_interpolation_is_exact_on_cubics_and_on_the_samples() {
        let time = vec![0.0, 0.3, 0.5, 1.1, 1.6, 2.0];
        let cubic = |t: f64| 0.2 - t + 0.7 * t * t - 0.3 * t * t * t;
        let q = DMatrix::from_fn(time.len(), 1, |r, _| cubic(time[r]));
        let d = Demonstration::new(Path::new("c.csv"), time.clone(), q).unwrap();
        let phases: Vec<f64> = (0..=40).map(|k| k as f64 / 40.0).collect();
        let at = positions_at_phases(&d, &phases);
        for (k, z) in phases.iter().enumerate() {
            assert!((at[(k, 0)] - cubic(2.0 * z)).abs() < 1e-12, "{z}");
        }
        let at_samples = positions_at_phases(&d, &d.phases());
        assert!((at_samples - &d.positions).amax() < 1e-12);
    }

    #[test]
    fn the_sampling_rate_does_not_change_the_weights() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let fast = fit_demonstration(&basis, &recording(1000.0, 8.0)).unwrap();
        let slow = fit_demonstration(&basis, &recording(30.0, 8.0)).unwrap();
        let diff = (&fast.weights - &slow.weights).amax();
        assert!(diff < 1e-6, "weights differ by {diff}");
        // The basis represents this motion to a few mrad.
        assert!(
            fast.rms_residual < 5e-3 && fast.max_residual < 2e-2,
            "{fast:?}"
        );
    }

    #[test]
    fn a_motion_in_the_basis_span_is_recovered_exactly() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let w = DMatrix::from_fn(8, 2, |i, j| ((i * 3 + j) as f64 * 0.37).sin());
        let n = 241;
        let time: Vec<f64> = (0..n).map(|k| k as f64 / 30.0).collect();
        let duration = time[n - 1];
        let q = DMatrix::from_fn(n, 2, |r, j| {
            (basis.row_at(time[r] / duration).transpose() * w.column(j))[0]
        });
        let d = Demonstration::new(Path::new("s.csv"), time, q).unwrap();
        let fit = fit_demonstration(&basis, &d).unwrap();
        let expected = DVector::from_column_slice(w.as_slice());
        // Interpolation error of a 30 Hz sampling, through the projector.
        assert!((fit.weights - expected).amax() < 1e-6);
        assert!(fit.max_residual < 1e-7, "{}", fit.max_residual);
    }

    #[test]
    fn too_short_and_out_of_limit_recordings_name_the_file() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let d = Demonstration::new(
            Path::new("short.csv"),
            vec![0.0, 1.0, 2.0],
            DMatrix::zeros(3, 2),
        )
        .unwrap();
        let e = fit_demonstration(&basis, &d).unwrap_err().to_string();
        assert!(e.contains("short.csv") && e.contains("too short"), "{e}");

        let robot = Robot::panda().unwrap();
        let n = 20;
        let time: Vec<f64> = (0..n).map(|k| k as f64 / 10.0).collect();
        let mut q = DMatrix::from_fn(n, 7, |_, j| robot.home()[j]);
        q[(12, 3)] = 0.5; // panda_joint4 must stay below -0.0698
        let d = Demonstration::new(Path::new("wide.csv"), time, q).unwrap();
        let e = fit_prior(&basis, &robot, &[d.clone(), d])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("wide.csv") && e.contains("panda_joint4") && e.contains("t = 1.2"),
            "{e}"
        );
    }
}
