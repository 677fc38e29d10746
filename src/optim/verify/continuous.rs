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
//! samples meet it, the interval is bisected up to [`MAX_BISECTIONS`]
//! times, **pair by pair**. The bound holds for each (robot primitive,
//! obstacle) pair on its own, since each pair's distance is 1-Lipschitz in
//! the displacement too: the pairs within the activation distance at either
//! end are listed, those whose own bound meets the clearance are certified
//! for the whole interval, and only the rest are followed into the halves:
//! a midpoint costs one forward kinematics and one exact query per pair
//! still open ([`Scene::pair_distance_below`]), not the broad phase over
//! every primitive and obstacle. (The optimum touches the clearance, so the
//! intervals around its closest pair bisect 3-6 levels on almost every
//! answer; that bisection was half of a dense verification.) Pairs outside
//! the activation distance at both ends are bounded by
//! `activation − D / 2`; where that is not enough, the interval is bisected
//! with full samples as before. An interval that still falls short, or
//! where a midpoint falls below the clearance, is reported by its midpoint
//! and its two ends, which the optimiser adds to its grid.
//!
//! The intervals are certified in parallel when the solve may use the
//! cores ([`SolveControl::parallel`]); the result is merged in their order,
//! so it is the same either way.

use crate::optim::problem::Problem;
use crate::optim::solution::SolveControl;
use crate::optim::tolerances::FEASIBILITY_TOLERANCE;
use crate::optim::verify::Verifier;
use crate::robot::lever::lever_arms_over;
use crate::robot::{Frames, Robot};
#[cfg(doc)]
use crate::scene::Scene;
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::sync::OnceLock;

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
/// (per second), clearance (capped at the activation distance), and what an
/// interval computes when it first needs them: the forward kinematics, the
/// configuration's lever arms and the pairs within the activation distance.
#[derive(Debug)]
struct Sample {
    z: f64,
    q: Vec<f64>,
    qd: Vec<f64>,
    clearance: f64,
    frames: OnceLock<Frames>,
    arms: OnceLock<Vec<f64>>,
    pairs: OnceLock<Vec<PairDistance>>,
}

/// One (robot primitive, obstacle) pair's distance at a sample.
#[derive(Clone, Copy, Debug)]
struct PairDistance {
    shape: usize,
    obstacle: usize,
    distance: f64,
}

/// A pair not yet certified on an interval: its distances (capped at the
/// activation distance) at the two ends.
#[derive(Clone, Copy, Debug)]
struct OpenPair {
    shape: usize,
    obstacle: usize,
    a: f64,
    b: f64,
}

impl OpenPair {
    /// The pair's bound on the interval for displacement bound
    /// `displacement` ([`pair_bound`]).
    fn bound(&self, displacement: f64) -> f64 {
        pair_bound(self.a, self.b, displacement)
    }

    /// Whether the interval is decided for this pair: its bound meets
    /// `required`, or an end already misses it (the bound then stands as
    /// the certificate's, below the requirement).
    fn settled(&self, displacement: f64, required: f64) -> bool {
        self.bound(displacement) >= required || self.a < required || self.b < required
    }
}

impl Sample {
    /// A sample whose forward kinematics, lever arms and pairs are computed
    /// when first needed.
    fn new(z: f64, q: Vec<f64>, qd: Vec<f64>, clearance: f64) -> Sample {
        Sample {
            z,
            q,
            qd,
            clearance,
            frames: OnceLock::new(),
            arms: OnceLock::new(),
            pairs: OnceLock::new(),
        }
    }

    fn frames(&self, robot: &Robot) -> &Frames {
        self.frames.get_or_init(|| robot.fk(&self.q))
    }

    /// [`Robot::lever_arms_at`] this sample's configuration.
    fn arms(&self, robot: &Robot) -> &[f64] {
        self.arms
            .get_or_init(|| robot.lever_arms_at(self.frames(robot)))
    }

    /// Every pair within the activation distance at this sample, in the
    /// broad phase's order.
    fn pairs(&self, p: &Problem) -> &[PairDistance] {
        self.pairs.get_or_init(|| {
            p.scene
                .clearances_within(&p.robot, self.frames(&p.robot), p.activation_m)
                .into_iter()
                .map(|c| PairDistance {
                    shape: c.shape,
                    obstacle: c.obstacle,
                    distance: c.distance,
                })
                .collect()
        })
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
    pair_bound(a.clearance, b.clearance, displacement)
}

/// `(c_a + c_b − D) / 2`, and never more than `c_a` or `c_b`.
fn pair_bound(ca: f64, cb: f64, displacement: f64) -> f64 {
    (0.5 * (ca + cb - displacement)).min(ca).min(cb)
}

impl Certificate {
    fn empty() -> Certificate {
        Certificate {
            clearance_m: f64::INFINITY,
            margin_m: 0.0,
            flagged: Vec::new(),
        }
    }

    /// Take an interval bound `bound` reached with displacement bound
    /// `displacement`.
    fn accept(&mut self, bound: f64, displacement: f64) {
        self.clearance_m = self.clearance_m.min(bound);
        self.margin_m = self.margin_m.max(0.5 * displacement);
    }

    /// Flag the interval `[a, b]`: its midpoint (where the bound is
    /// weakest, or the trajectory dips) and both ends. A constraint at the
    /// midpoint alone lets the optimiser push the dip to either side of it
    /// (a new flag, round after round); with the ends the dip is held on
    /// both sides (docs/experiments.md).
    fn flag_interval(&mut self, a: f64, b: f64) {
        self.flagged.extend([0.5 * (a + b), a, b]);
    }

    /// Append `later`, the certificate of the intervals after this one's.
    fn merge(mut self, later: Certificate) -> Certificate {
        self.accept(later.clearance_m, 2.0 * later.margin_m);
        self.flagged.extend(later.flagged);
        self
    }
}

impl Verifier<'_> {
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
        ctl: &SolveControl,
    ) -> Option<Certificate> {
        let samples: Vec<Sample> = (0..self.problem.dense_phases.len())
            .map(|p| {
                Sample::new(
                    self.problem.dense_phases[p],
                    q.row(p).iter().copied().collect(),
                    qd.row(p).iter().copied().collect(),
                    clearance[p].unwrap_or(self.problem.activation_m),
                )
            })
            .collect();
        if samples.len() == 1 {
            let mut out = Certificate::empty();
            out.clearance_m = samples[0].clearance;
            return Some(out);
        }
        let interval = |p: usize| {
            (!ctl.should_stop()).then(|| {
                let mut out = Certificate::empty();
                self.certify_interval(wm, &samples[p], &samples[p + 1], 0, &mut out);
                out
            })
        };
        let intervals = 0..samples.len().saturating_sub(1);
        let parts: Option<Vec<Certificate>> = if ctl.parallel() {
            intervals.into_par_iter().map(interval).collect()
        } else {
            intervals.map(interval).collect()
        };
        Some(
            parts?
                .into_iter()
                .fold(Certificate::empty(), Certificate::merge),
        )
    }

    /// The displacement bound between `a` and `b` with the
    /// configuration-free lever arms, or, unless `enough` accepts that one,
    /// with the arms of the two configurations (one forward kinematics each).
    fn displacement(&self, a: &Sample, b: &Sample, enough: impl Fn(f64) -> bool) -> f64 {
        let h = (b.z - a.z) * self.problem.duration;
        let path = path_lengths(&a.q, &b.q, &a.qd, &b.qd, h);
        let free = dot(self.problem.robot.lever_arms(), &path);
        if enough(free) {
            return free;
        }
        let robot = &self.problem.robot;
        displacement_bound_between(robot, a.arms(robot), b.arms(robot), &path)
    }

    /// Bound the clearance between `a` and `b`, bisecting while the bound
    /// misses the requirement and both ends meet it: pair by pair where the
    /// pairs outside the activation distance are certified by it, else with
    /// full samples.
    fn certify_interval(
        &self,
        wm: &DMatrix<f64>,
        a: &Sample,
        b: &Sample,
        depth: usize,
        out: &mut Certificate,
    ) {
        let required = self.problem.clearance_m - FEASIBILITY_TOLERANCE;
        let ends_ok = a.clearance >= required && b.clearance >= required;
        let displacement =
            self.displacement(a, b, |d| !ends_ok || interval_bound(a, b, d) >= required);
        let bound = interval_bound(a, b, displacement);
        if !ends_ok {
            // A sample below the clearance: the dense check flags its own
            // samples; a bisection midpoint is flagged here, or the
            // optimiser would never see where the trajectory dips.
            out.flagged.extend(
                [a, b]
                    .iter()
                    .filter(|s| s.clearance < required)
                    .map(|s| s.z),
            );
        }
        if bound >= required || !ends_ok {
            out.accept(bound, displacement);
            return;
        }
        if depth == MAX_BISECTIONS {
            out.accept(bound, displacement);
            out.flag_interval(a.z, b.z);
            return;
        }
        let beyond = pair_bound(
            self.problem.activation_m,
            self.problem.activation_m,
            displacement,
        );
        if beyond >= required {
            out.accept(beyond, displacement);
            let open = self.open_pairs(a, b, displacement, required, out);
            self.certify_pairs(wm, a, b, &open, depth, out);
            return;
        }
        let mid = self.sample_at(wm, 0.5 * (a.z + b.z));
        self.certify_interval(wm, a, &mid, depth + 1, out);
        self.certify_interval(wm, &mid, b, depth + 1, out);
    }

    /// The pairs within the activation distance at `a` or `b` (the other
    /// end's distance capped at it) whose own bound misses `required`; the
    /// others are certified on the interval into `out`.
    fn open_pairs(
        &self,
        a: &Sample,
        b: &Sample,
        displacement: f64,
        required: f64,
        out: &mut Certificate,
    ) -> Vec<OpenPair> {
        let cap = self.problem.activation_m;
        let mut pairs: Vec<OpenPair> = a
            .pairs(self.problem)
            .iter()
            .map(|pa| OpenPair {
                shape: pa.shape,
                obstacle: pa.obstacle,
                a: pa.distance.min(cap),
                b: cap,
            })
            .collect();
        for pb in b.pairs(self.problem) {
            match pairs
                .iter_mut()
                .find(|o| (o.shape, o.obstacle) == (pb.shape, pb.obstacle))
            {
                Some(open) => open.b = pb.distance.min(cap),
                None => pairs.push(OpenPair {
                    shape: pb.shape,
                    obstacle: pb.obstacle,
                    a: cap,
                    b: pb.distance.min(cap),
                }),
            }
        }
        pairs.retain(|o| {
            let settled = o.settled(displacement, required);
            if settled {
                out.accept(o.bound(displacement), displacement);
            }
            !settled
        });
        pairs
    }

    /// Bisect `[a, b]` for the `open` pairs only (each meets `required` at
    /// both ends; the interval's other pairs are certified), up to
    /// [`MAX_BISECTIONS`] levels in all; an interval still open at the last
    /// level is flagged by its midpoint.
    fn certify_pairs(
        &self,
        wm: &DMatrix<f64>,
        a: &Sample,
        b: &Sample,
        open: &[OpenPair],
        depth: usize,
        out: &mut Certificate,
    ) {
        if open.is_empty() {
            return;
        }
        let z = 0.5 * (a.z + b.z);
        if depth == MAX_BISECTIONS {
            out.flag_interval(a.z, b.z);
            return;
        }
        let mid = self.bare_sample_at(wm, z);
        let frames = mid.frames(&self.problem.robot);
        let at_mid: Vec<f64> = open
            .iter()
            .map(|o| {
                self.problem.scene.pair_distance_below(
                    &self.problem.robot,
                    frames,
                    o.shape,
                    o.obstacle,
                    self.problem.activation_m,
                )
            })
            .collect();
        let required = self.problem.clearance_m - FEASIBILITY_TOLERANCE;
        if at_mid.iter().any(|&m| m < required) {
            // The trajectory dips below the clearance between the samples:
            // the optimiser must see this phase, as for a full midpoint.
            out.flag_interval(a.z, b.z);
        }
        let halves = [(a, &mid, true), (&mid, b, false)];
        for (lo, hi, first) in halves {
            let spans: Vec<OpenPair> = open
                .iter()
                .zip(&at_mid)
                .map(|(o, &m)| match first {
                    true => OpenPair { b: m, ..*o },
                    false => OpenPair { a: m, ..*o },
                })
                .collect();
            let displacement =
                self.displacement(lo, hi, |d| spans.iter().all(|o| o.settled(d, required)));
            let still_open: Vec<OpenPair> = spans
                .into_iter()
                .filter(|o| {
                    let settled = o.settled(displacement, required);
                    if settled || depth + 1 == MAX_BISECTIONS {
                        out.accept(o.bound(displacement), displacement);
                    }
                    !settled
                })
                .collect();
            self.certify_pairs(wm, lo, hi, &still_open, depth + 1, out);
        }
    }

    /// Positions and velocities at phase `z` (the rest computed on demand).
    fn bare_sample_at(&self, wm: &DMatrix<f64>, z: f64) -> Sample {
        let [psi, dpsi, ..] =
            self.problem
                .warp
                .time_rows(&self.problem.basis, z, self.problem.duration);
        Sample::new(
            z,
            (wm.transpose() * psi).iter().copied().collect(),
            (wm.transpose() * dpsi).iter().copied().collect(),
            self.problem.activation_m,
        )
    }

    /// A full sample at phase `z`: positions, velocities and the clearance
    /// over every pair.
    fn sample_at(&self, wm: &DMatrix<f64>, z: f64) -> Sample {
        let mut s = self.bare_sample_at(wm, z);
        s.clearance = self
            .problem
            .scene
            .closest_within(
                &self.problem.robot,
                s.frames(&self.problem.robot),
                self.problem.activation_m,
            )
            .map_or(self.problem.activation_m, |c| c.distance);
        s
    }
}
