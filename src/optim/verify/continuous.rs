//! The continuous-motion clearance certificate: a lower bound on the
//! clearance over the whole trajectory, not only at the verification
//! samples.
//!
//! Between two samples `t_a < t_b` every point of the robot's collision
//! geometry moves at most `D = Σ_j L_j · V_j`, where `L_j` is the joint's
//! lever arm (how far any point moves per radian: [`crate::robot::lever`])
//! and `V_j` the joint's path length over the interval. Signed distance is
//! 1-Lipschitz in the robot's displacement, so at any `t` in between the
//! clearance is at least `max(c_a − D(t_a, t), c_b − D(t, t_b))`, and
//! because the two displacements add up to at most `D`, at least
//!
//! ```text
//! (c_a + c_b − D) / 2     (and never more than min(c_a, c_b)).
//! ```
//!
//! `V_j` is `|Δq_j|` when the joint moves one way; when its velocity changes
//! sign inside the interval the path is longer, by at most `A·h²/4` for an
//! acceleration bound `A` over the interval of length `h`. The bound uses
//! `|Δq_j| + h·|Δq̇_j|/2` (the second term is `A·h²/2` for a constant
//! acceleration, twice the worst case), which 100× oversampling of random
//! trajectories confirms (tests/optim_continuous.rs).
//!
//! `L_j` is first the configuration-free arm ([`Robot::lever_arms`]: the
//! straight chain's reach). Where that bound falls short, the arms of the
//! two end configurations, carried over the interval
//! ([`lever_arms_over`]), replace it: about half as large on the base
//! joints of a bent arm, for one forward kinematics per sample. On the
//! hard set this cuts the verification time by about a fifth
//! (docs/experiments.md).
//!
//! Where the bound falls short of the requested clearance although both
//! samples meet it, the interval is bisected (new samples: forward
//! kinematics and clearance queries at the midpoint) up to
//! [`MAX_BISECTIONS`] times. An interval that still falls short is reported
//! by its midpoint phase, which the optimiser adds to its grid.

use crate::optim::problem::Problem;
use crate::optim::tolerances::FEASIBILITY_TOLERANCE;
use crate::robot::lever::lever_arms_over;
use crate::robot::Robot;
use nalgebra::DMatrix;
use std::cell::OnceCell;

/// Bisections of one verification interval before it is flagged.
pub const MAX_BISECTIONS: usize = 6;

/// The continuous clearance bound of one trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Certificate {
    /// Lower bound (m) on the clearance over the whole motion.
    pub clearance_m: f64,
    /// Largest half-displacement bound `D / 2` (m) subtracted on an
    /// interval that was accepted (after bisection).
    pub margin_m: f64,
    /// Phases inside intervals that could not be certified.
    pub flagged: Vec<f64>,
}

/// One sample of the trajectory: phase, joint positions, joint velocities
/// (per second), clearance (capped at the activation distance) and the
/// configuration's lever arms (computed when an interval first needs them).
#[derive(Clone, Debug)]
struct Sample {
    z: f64,
    q: Vec<f64>,
    qd: Vec<f64>,
    clearance: f64,
    arms: OnceCell<Vec<f64>>,
}

impl Sample {
    /// [`Robot::lever_arms_at`] this sample's configuration.
    fn arms(&self, robot: &Robot) -> &[f64] {
        self.arms
            .get_or_init(|| robot.lever_arms_at(&robot.fk(&self.q)))
    }
}

/// Each joint's path-length bound between two samples `h` seconds apart
/// with positions `qa`, `qb` and velocities `qda`, `qdb` (per second):
/// `|Δq_j| + h |Δq̇_j| / 2` (see the module docs).
pub fn path_lengths(qa: &[f64], qb: &[f64], qda: &[f64], qdb: &[f64], h: f64) -> Vec<f64> {
    (0..qa.len())
        .map(|j| (qb[j] - qa[j]).abs() + 0.5 * h * (qdb[j] - qda[j]).abs())
        .collect()
}

/// `Σ_j L_j (|Δq_j| + h |Δq̇_j| / 2)`: how far any point of the robot's
/// collision geometry can move between two samples `h` seconds apart with
/// positions `qa`, `qb` and velocities `qda`, `qdb` (per second), for
/// configuration-free lever arms `L`.
pub fn displacement_bound(
    lever_arms: &[f64],
    qa: &[f64],
    qb: &[f64],
    qda: &[f64],
    qdb: &[f64],
    h: f64,
) -> f64 {
    dot(lever_arms, &path_lengths(qa, qb, qda, qdb, h))
}

/// The same bound with the lever arms of the configurations at both ends
/// (`arms_a`, `arms_b`: [`Robot::lever_arms_at`]) carried over the interval
/// by [`lever_arms_over`]: never more than [`displacement_bound`], and
/// about half of it where the arm is bent.
pub fn displacement_bound_between(
    robot: &Robot,
    arms_a: &[f64],
    arms_b: &[f64],
    path: &[f64],
) -> f64 {
    dot(
        &lever_arms_over(arms_a, arms_b, robot.lever_arms(), path),
        path,
    )
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `(c_a + c_b − D) / 2`, and never more than either end's clearance.
fn interval_bound(a: &Sample, b: &Sample, displacement: f64) -> f64 {
    (0.5 * (a.clearance + b.clearance - displacement))
        .min(a.clearance)
        .min(b.clearance)
}

impl Problem {
    /// Certify the trajectory with weight matrix `wm` (`n_basis × n_joints`)
    /// given its dense samples `q`, `qd` and per-sample clearances (`None`:
    /// at least the activation distance). `None` when `ctl` stopped it
    /// (checked between intervals).
    pub(crate) fn continuous_certificate(
        &self,
        wm: &DMatrix<f64>,
        q: &DMatrix<f64>,
        qd: &DMatrix<f64>,
        clearance: &[Option<f64>],
        ctl: &crate::optim::solution::SolveControl,
    ) -> Option<Certificate> {
        let sample = |p: usize| Sample {
            z: self.dense_phases[p],
            q: q.row(p).iter().copied().collect(),
            qd: qd.row(p).iter().copied().collect(),
            clearance: clearance[p].unwrap_or(self.activation_m),
            arms: OnceCell::new(),
        };
        let mut out = Certificate {
            clearance_m: f64::INFINITY,
            margin_m: 0.0,
            flagged: Vec::new(),
        };
        for p in 0..self.dense_phases.len().saturating_sub(1) {
            if ctl.should_stop() {
                return None;
            }
            self.certify_interval(wm, sample(p), sample(p + 1), 0, &mut out);
        }
        if self.dense_phases.len() == 1 {
            out.clearance_m = sample(0).clearance;
        }
        Some(out)
    }

    /// Bound the clearance between `a` and `b`, bisecting while the bound
    /// misses the requirement and both ends meet it. The configuration-free
    /// lever arms are tried first; where they miss, the arms of the two
    /// configurations (one forward kinematics each), before bisecting.
    fn certify_interval(
        &self,
        wm: &DMatrix<f64>,
        a: Sample,
        b: Sample,
        depth: usize,
        out: &mut Certificate,
    ) {
        let required = self.clearance_m - FEASIBILITY_TOLERANCE;
        let ends_ok = a.clearance >= required && b.clearance >= required;
        let h = (b.z - a.z) * self.duration;
        let path = path_lengths(&a.q, &b.q, &a.qd, &b.qd, h);
        let mut displacement = dot(self.robot.lever_arms(), &path);
        let mut bound = interval_bound(&a, &b, displacement);
        if bound < required && ends_ok {
            let robot = &self.robot;
            displacement = displacement_bound_between(robot, a.arms(robot), b.arms(robot), &path);
            bound = interval_bound(&a, &b, displacement);
        }
        if bound >= required || !ends_ok {
            self.accept(bound, displacement, out);
            return;
        }
        if depth == MAX_BISECTIONS {
            self.accept(bound, displacement, out);
            out.flagged.push(0.5 * (a.z + b.z));
            return;
        }
        let mid = self.sample_at(wm, 0.5 * (a.z + b.z));
        self.certify_interval(wm, a, mid.clone(), depth + 1, out);
        self.certify_interval(wm, mid, b, depth + 1, out);
    }

    fn accept(&self, bound: f64, displacement: f64, out: &mut Certificate) {
        out.clearance_m = out.clearance_m.min(bound);
        out.margin_m = out.margin_m.max(0.5 * displacement);
    }

    /// A new sample at phase `z`: positions, velocities and clearance.
    fn sample_at(&self, wm: &DMatrix<f64>, z: f64) -> Sample {
        let [psi, dpsi, ..] = self.warp.time_rows(&self.basis, z, self.duration);
        let q: Vec<f64> = (wm.transpose() * psi).iter().copied().collect();
        let qd: Vec<f64> = (wm.transpose() * dpsi).iter().copied().collect();
        let frames = self.robot.fk(&q);
        let clearance = self
            .scene
            .closest_within(&self.robot, &frames, self.activation_m)
            .map_or(self.activation_m, |c| c.distance);
        Sample {
            z,
            q,
            qd,
            clearance,
            arms: OnceCell::from(self.robot.lever_arms_at(&frames)),
        }
    }
}
