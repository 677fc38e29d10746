//! The demonstration generator: human-like reaching motions from home to a
//! pre-grasp pose in front of a berry.
//!
//! One demonstration: a start near home (truncated Gaussian, per joint), a
//! pre-grasp TCP position `standoff_m` short of the berry centre along the
//! approach axis (the direction from the home TCP, i.e. the camera side, to
//! the berry) with position and axis noise, solved by [`Robot::ik`] with a
//! random null-space bias around the target's noise-free pre-grasp
//! configuration (one elbow/wrist branch per target), plus final-pose
//! joint noise with the TCP position restored by a position-only IK (so
//! the redundant joints vary like a human demonstrator's), then a
//! minimum-jerk joint profile plus a random
//! via-point bump, `n_samples` samples. It is kept only if every joint stays
//! within its limits and the robot keeps `clearance_m` from every obstacle
//! at every `check_stride`-th sample (and the last); otherwise it is drawn
//! again, at most `max_tries` times.

use crate::promp::annotation::{joints_from_distribution, JointAnnotation};
use crate::promp::{fit_weights, Basis, WeightDistribution};
use crate::robot::{IkOptions, IkTarget, Robot};
use crate::scene::Scene;
use crate::synth::dataset::Pose;
use crate::synth::settings::DemoSettings;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Isometry3, Point3, Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// One accepted demonstration.
#[derive(Clone, Debug)]
pub struct Demonstration {
    /// `n_samples x dof` joint trajectory.
    pub trajectory: DMatrix<f64>,
    /// Joint-major ProMP weights.
    pub weights: DVector<f64>,
    /// Final TCP pose.
    pub final_tcp: Isometry3<f64>,
    /// Smallest clearance found along the checked samples (m); infinite for an empty scene.
    pub min_clearance_m: f64,
}

impl Demonstration {
    /// First sample.
    pub fn start(&self) -> Vec<f64> {
        self.trajectory.row(0).iter().copied().collect()
    }

    /// Last sample.
    pub fn final_q(&self) -> Vec<f64> {
        self.trajectory
            .row(self.trajectory.nrows() - 1)
            .iter()
            .copied()
            .collect()
    }
}

/// All demonstrations of one target and what the dataset stores about them.
#[derive(Clone, Debug)]
pub struct TargetDemos {
    /// The demonstrations.
    pub demos: Vec<Demonstration>,
    /// Full weight distribution over the demos.
    pub distribution: WeightDistribution,
    /// The paper's per-joint annotation of it.
    pub annotation: Vec<JointAnnotation>,
    /// Mean start configuration.
    pub start: Vec<f64>,
    /// Mean final TCP pose.
    pub final_tcp: Pose,
}

/// Everything the generator needs, borrowed.
pub struct DemoContext<'a> {
    /// The arm.
    pub robot: &'a Robot,
    /// The obstacles of the configuration.
    pub scene: &'a Scene,
    /// ProMP basis.
    pub basis: &'a Basis,
    /// Settings.
    pub settings: &'a DemoSettings,
}

/// Minimum-jerk position profile `10 t^3 - 15 t^4 + 6 t^5` on [0, 1].
pub fn min_jerk(t: f64) -> f64 {
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

/// Via-point bump `64 t^3 (1 - t)^3`: 1 at t = 1/2, zero position,
/// velocity and acceleration at both ends.
pub fn via_bump(t: f64) -> f64 {
    64.0 * (t * (1.0 - t)).powi(3)
}

/// Joint trajectory from `start` to `goal` with a via deviation `via`.
pub fn reaching_trajectory(
    start: &[f64],
    goal: &[f64],
    via: &[f64],
    n_samples: usize,
) -> DMatrix<f64> {
    DMatrix::from_fn(n_samples, start.len(), |k, j| {
        let t = k as f64 / (n_samples - 1) as f64;
        start[j] + (goal[j] - start[j]) * min_jerk(t) + via[j] * via_bump(t)
    })
}

/// Unit approach axis from the home TCP (the camera side) towards the berry.
pub fn approach_axis(home_tcp: &Point3<f64>, berry: &Point3<f64>) -> Result<Unit<Vector3<f64>>> {
    Unit::try_new(berry - home_tcp, 1e-9)
        .ok_or_else(|| Error::invalid("target_position", "coincides with the home TCP"))
}

/// Iterations of the position-only IK after the final-pose noise.
const FINAL_POSITION_IK_ITERATIONS: usize = 100;

impl DemoContext<'_> {
    /// Generate all demonstrations of one target.
    pub fn target(
        &self,
        berry: &Point3<f64>,
        berry_id: &str,
        rng: &mut impl Rng,
    ) -> Result<TargetDemos> {
        let home = self.robot.home();
        let axis = approach_axis(&self.robot.tcp_pose(&home).translation.vector.into(), berry)?;
        let anchor = self.nominal_solution(&home, berry, &axis, berry_id)?;
        let demos = (0..self.settings.demos)
            .map(|_| self.one_with_retries(&home, &anchor, berry, &axis, berry_id, rng))
            .collect::<Result<Vec<_>>>()?;
        self.summarise(demos)
    }

    /// The noise-free pre-grasp configuration reached from home: every
    /// demonstration of the target is biased towards it, so that they all
    /// stay on one elbow / wrist branch as a human demonstrator's do.
    fn nominal_solution(
        &self,
        home: &[f64],
        berry: &Point3<f64>,
        axis: &Unit<Vector3<f64>>,
        berry_id: &str,
    ) -> Result<Vec<f64>> {
        let target = IkTarget {
            position: berry - axis.into_inner() * self.settings.standoff_m,
            approach_axis: Some(*axis),
        };
        let sol = self.robot.ik(&target, home, &self.ik_options(home, 0))?;
        if !self.ik_converged(&sol) {
            return Err(Error::Infeasible(format!(
                "no pre-grasp configuration for {berry_id} (IK position error {:.4} m)",
                sol.position_error_m
            )));
        }
        Ok(sol.q)
    }

    /// IK settings of a demonstration biased towards `bias`.
    fn ik_options(&self, bias: &[f64], seed: u64) -> IkOptions {
        IkOptions {
            null_space_bias: Some(bias.to_vec()),
            null_space_gain: self.settings.null_space_gain,
            max_iterations: 600,
            // Iterate to a tight tolerance so the null-space pull acts;
            // accept anything within the demo tolerance.
            tolerance_m: 1e-4,
            axis_tolerance_rad: 1e-3,
            restarts: 0,
            seed,
            ..IkOptions::default()
        }
    }

    /// The demonstrator's own final-pose variation: joint noise on the IK
    /// solution, then the TCP position (not the approach axis) restored by
    /// a position-only IK from there, so the hand still stops at the
    /// pre-grasp point while wrist and elbow angles vary.
    fn final_pose_noise(
        &self,
        q: &[f64],
        position: &Point3<f64>,
        rng: &mut impl Rng,
    ) -> std::result::Result<Vec<f64>, String> {
        let noise = &self.settings.final_joint_noise_rad;
        let noisy: Vec<f64> = q
            .iter()
            .enumerate()
            .map(|(j, v)| v + noise.get(j).copied().unwrap_or(0.0) * standard_normal(rng))
            .collect();
        let options = IkOptions {
            max_iterations: FINAL_POSITION_IK_ITERATIONS,
            tolerance_m: 1e-4,
            restarts: 0,
            ..IkOptions::default()
        };
        let target = IkTarget {
            position: *position,
            approach_axis: None,
        };
        let sol = self
            .robot
            .ik(&target, &noisy, &options)
            .map_err(|e| format!("IK failed: {e}"))?;
        if sol.position_error_m > self.settings.ik_tolerance_m {
            return Err(format!(
                "final-pose noise left the TCP {:.4} m from the pre-grasp point",
                sol.position_error_m
            ));
        }
        Ok(sol.q)
    }

    /// Whether an IK answer is within the demonstration tolerances.
    fn ik_converged(&self, sol: &crate::robot::IkSolution) -> bool {
        sol.position_error_m <= self.settings.ik_tolerance_m
            && sol.axis_error_rad <= self.settings.ik_axis_tolerance_rad
    }

    fn one_with_retries(
        &self,
        home: &[f64],
        anchor: &[f64],
        berry: &Point3<f64>,
        axis: &Unit<Vector3<f64>>,
        berry_id: &str,
        rng: &mut impl Rng,
    ) -> Result<Demonstration> {
        let mut last = String::new();
        for _ in 0..self.settings.max_tries {
            match self.one(home, anchor, berry, axis, rng) {
                Ok(d) => return Ok(d),
                Err(reason) => last = reason,
            }
        }
        Err(Error::Infeasible(format!(
            "no valid demonstration to {berry_id} after {} draws; last rejection: {last}",
            self.settings.max_tries
        )))
    }

    /// One draw; `Err` carries the rejection reason.
    fn one(
        &self,
        home: &[f64],
        anchor: &[f64],
        berry: &Point3<f64>,
        axis: &Unit<Vector3<f64>>,
        rng: &mut impl Rng,
    ) -> std::result::Result<Demonstration, String> {
        let s = self.settings;
        let start = self.sample_start(home, rng);
        let goal_axis = perturb_axis(axis, s.axis_noise_rad, s.axis_pitch_noise_rad, rng);
        let noise = gaussian_vector(s.position_noise_m, rng);
        let target = IkTarget {
            position: berry
                - goal_axis.into_inner()
                    * (s.standoff_m + s.standoff_jitter_m * standard_normal(rng))
                + noise,
            approach_axis: Some(goal_axis),
        };
        let bias: Vec<f64> = anchor
            .iter()
            .enumerate()
            .map(|(j, a)| {
                a + s.null_space_std_rad.get(j).copied().unwrap_or(0.0) * standard_normal(rng)
            })
            .collect();
        let sol = self
            .robot
            .ik(&target, &bias, &self.ik_options(&bias, rng.gen()))
            .map_err(|e| format!("IK failed: {e}"))?;
        if !self.ik_converged(&sol) {
            return Err(format!(
                "IK did not converge (position error {:.4} m)",
                sol.position_error_m
            ));
        }
        let via: Vec<f64> = (0..home.len())
            .map(|_| rng.gen_range(-1.0..=1.0) * s.via_deviation_rad)
            .collect();
        let final_q = self.final_pose_noise(&sol.q, &target.position, rng)?;
        let trajectory = reaching_trajectory(&start, &final_q, &via, self.basis.n_samples());
        self.check_limits(&trajectory)?;
        let min_clearance_m = self.check_clearance(&trajectory)?;
        let weights =
            fit_weights(self.basis, &trajectory).map_err(|e| format!("ProMP fit failed: {e}"))?;
        Ok(Demonstration {
            final_tcp: self.robot.tcp_pose(&final_q),
            trajectory,
            weights,
            min_clearance_m,
        })
    }

    fn sample_start(&self, home: &[f64], rng: &mut impl Rng) -> Vec<f64> {
        let s = self.settings;
        home.iter()
            .map(|h| loop {
                let d = s.start_std_rad * standard_normal(rng);
                if d.abs() <= s.start_max_rad {
                    break h + d;
                }
            })
            .collect()
    }

    fn check_limits(&self, traj: &DMatrix<f64>) -> std::result::Result<(), String> {
        for (j, lim) in self.robot.limits().iter().enumerate() {
            let col = traj.column(j);
            let (lo, hi) = (col.min(), col.max());
            if lo < lim.lower || hi > lim.upper {
                return Err(format!(
                    "joint {} leaves its limits [{:.3}, {:.3}] (range {lo:.3}..{hi:.3})",
                    j + 1,
                    lim.lower,
                    lim.upper
                ));
            }
        }
        Ok(())
    }

    fn check_clearance(&self, traj: &DMatrix<f64>) -> std::result::Result<f64, String> {
        let n = traj.nrows();
        let mut min = f64::INFINITY;
        let samples = (0..n)
            .step_by(self.settings.check_stride)
            .chain(std::iter::once(n - 1));
        for k in samples {
            let q: Vec<f64> = traj.row(k).iter().copied().collect();
            let frames = self.robot.fk(&q);
            if let Some(c) = self.scene.min_clearance(self.robot, &frames) {
                if c.distance < self.settings.clearance_m {
                    return Err(format!(
                        "clearance {:.4} m < {} m between {} and {} at sample {k}",
                        c.distance,
                        self.settings.clearance_m,
                        c.link_name(self.robot),
                        c.obstacle_id(self.scene)
                    ));
                }
                min = min.min(c.distance);
            }
        }
        Ok(min)
    }

    fn summarise(&self, demos: Vec<Demonstration>) -> Result<TargetDemos> {
        let weights: Vec<DVector<f64>> = demos.iter().map(|d| d.weights.clone()).collect();
        let dof = self.robot.dof();
        let distribution =
            WeightDistribution::from_demonstrations(&weights, dof, self.basis.n_basis())?;
        let annotation = joints_from_distribution(&distribution)?;
        let starts: Vec<Vec<f64>> = demos.iter().map(|d| d.start()).collect();
        let start = mean_rows(&starts);
        let final_tcp = mean_pose(&demos.iter().map(|d| d.final_tcp).collect::<Vec<_>>());
        Ok(TargetDemos {
            demos,
            distribution,
            annotation,
            start,
            final_tcp,
        })
    }
}

/// Element-wise mean of equally long rows.
pub fn mean_rows(rows: &[Vec<f64>]) -> Vec<f64> {
    let n = rows.len().max(1) as f64;
    let len = rows.first().map_or(0, Vec::len);
    (0..len)
        .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n)
        .collect()
}

/// Mean position and sign-aligned normalised mean quaternion.
pub fn mean_pose(poses: &[Isometry3<f64>]) -> Pose {
    let n = poses.len().max(1) as f64;
    let p = poses
        .iter()
        .fold(Vector3::zeros(), |s, x| s + x.translation.vector)
        / n;
    let reference = poses
        .first()
        .map(|x| x.rotation.coords)
        .unwrap_or_else(|| UnitQuaternion::identity().coords);
    let sum = poses.iter().fold(nalgebra::Vector4::zeros(), |s, x| {
        let c = x.rotation.coords;
        if c.dot(&reference) < 0.0 {
            s - c
        } else {
            s + c
        }
    });
    let q = sum.try_normalize(1e-12).unwrap_or(reference);
    Pose {
        position: [p.x, p.y, p.z],
        quaternion: [q[0], q[1], q[2], q[3]],
    }
}

fn standard_normal(rng: &mut impl Rng) -> f64 {
    rand_distr::StandardNormal.sample(rng)
}

fn gaussian_vector(std: f64, rng: &mut impl Rng) -> Vector3<f64> {
    match Normal::new(0.0, std) {
        Ok(d) => Vector3::from_fn(|_, _| d.sample(rng)),
        Err(_) => Vector3::zeros(),
    }
}

/// Tilt `axis` by Gaussian angles: `yaw_std` sideways (about world up) and
/// `pitch_std` in the vertical plane through the axis.
pub fn perturb_axis(
    axis: &Unit<Vector3<f64>>,
    yaw_std: f64,
    pitch_std: f64,
    rng: &mut impl Rng,
) -> Unit<Vector3<f64>> {
    let a = axis.into_inner();
    let helper = if a.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let e1 = a.cross(&helper).normalize();
    let e2 = a.cross(&e1);
    let (x, y) = (
        yaw_std * standard_normal(rng),
        pitch_std * standard_normal(rng),
    );
    Unit::new_normalize(a + e1 * x.tan() + e2 * y.tan())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_jerk_and_bump_have_the_closed_form_boundary_values() {
        let h = 1e-5;
        for f in [min_jerk, via_bump] {
            let d = |t: f64| (f(t + h) - f(t - h)) / (2.0 * h);
            assert!(d(h).abs() < 1e-6 && d(1.0 - h).abs() < 1e-6);
        }
        assert_eq!(min_jerk(0.0), 0.0);
        assert!((min_jerk(1.0) - 1.0).abs() < 1e-15);
        assert!((min_jerk(0.5) - 0.5).abs() < 1e-15);
        assert!((via_bump(0.5) - 1.0).abs() < 1e-15);
        assert_eq!(via_bump(0.0), 0.0);
    }

    #[test]
    fn reaching_trajectory_starts_and_ends_where_asked() {
        let t = reaching_trajectory(&[0.0, 1.0], &[1.0, -1.0], &[0.3, 0.0], 150);
        assert_eq!(t.shape(), (150, 2));
        assert_eq!(t[(0, 0)], 0.0);
        assert!((t[(149, 1)] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn perturbed_axes_have_the_requested_spread() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let a = Unit::new_normalize(Vector3::new(0.97, -0.06, -0.22));
        let angles: Vec<f64> = (0..4000)
            .map(|_| {
                perturb_axis(&a, 0.05, 0.05, &mut rng)
                    .dot(&a)
                    .clamp(-1.0, 1.0)
                    .acos()
            })
            .collect();
        // The angle is Rayleigh distributed: mean = sigma sqrt(pi / 2).
        let mean = angles.iter().sum::<f64>() / angles.len() as f64;
        assert!(
            (mean - 0.05 * (std::f64::consts::PI / 2.0).sqrt()).abs() < 0.003,
            "{mean}"
        );
    }

    #[test]
    fn mean_pose_handles_quaternion_sign_flips() {
        let r = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let flipped = UnitQuaternion::new_unchecked(-r.into_inner());
        let p = mean_pose(&[
            Isometry3::from_parts(Vector3::x().into(), r),
            Isometry3::from_parts(Vector3::y().into(), flipped),
        ]);
        let q = nalgebra::Quaternion::new(
            p.quaternion[3],
            p.quaternion[0],
            p.quaternion[1],
            p.quaternion[2],
        );
        assert!((q.coords - r.coords).norm() < 1e-12 || (q.coords + r.coords).norm() < 1e-12);
        assert_eq!(p.position, [0.5, 0.5, 0.0]);
    }
}
