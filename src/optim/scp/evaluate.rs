//! One SCP iterate evaluated on the optimisation phases: forward
//! kinematics, every clearance pair within the activation distance (parry),
//! the goal residual, the limit rows, and the merit the step test uses.

use crate::optim::constraints::EndEval;
use crate::optim::problem::phases::PhaseRows;
use crate::optim::problem::Problem;
use crate::optim::solution::SolveControl;
use crate::optim::tolerances::{CLEARANCE_BUFFER_M, FEASIBILITY_TOLERANCE, LINEAR_TOLERANCE};
use crate::robot::Frames;
use crate::scene::Clearance;
use nalgebra::DVector;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Constraint values at one iterate on the optimisation phases.
pub(in crate::optim) struct GridEval {
    pub(in crate::optim) z: DVector<f64>,
    pub(in crate::optim) w: DVector<f64>,
    pub(in crate::optim) cost: f64,
    /// Pairs within the activation distance, per phase that has any.
    pub(in crate::optim) pairs: Vec<PhasePairs>,
    /// Σ max(0, clearance_m + buffer - d).
    pub(in crate::optim) buffered_violation: f64,
    /// Σ max(0, clearance_m - d) + goal excess: what must reach zero.
    pub(in crate::optim) true_violation: f64,
    /// The problem's single-phase constraints, in its order.
    pub(in crate::optim) ends: Vec<EndEval>,
    pub(in crate::optim) linear_ok: bool,
    /// The caller's deadline or cancel flag stopped the clearance pass:
    /// the pairs are incomplete, so the iterate is never accepted.
    pub(in crate::optim) interrupted: bool,
}

pub(in crate::optim) struct PhasePairs {
    pub(in crate::optim) phase: usize,
    pub(in crate::optim) phase_value: f64,
    pub(in crate::optim) q: Vec<f64>,
    pub(in crate::optim) frames: Frames,
    pub(in crate::optim) list: Vec<Clearance>,
}

impl GridEval {
    pub(in crate::optim) fn merit(&self, rho: f64) -> f64 {
        self.cost + rho * (self.buffered_violation + self.goal_excess())
    }

    /// The single-phase constraints' excess beyond their buffered
    /// tolerances (the merit's).
    pub(in crate::optim) fn goal_excess(&self) -> f64 {
        self.ends.iter().fold(0.0, |sum, e| sum + e.buffered_excess)
    }

    pub(in crate::optim) fn feasible(&self) -> bool {
        !self.interrupted && self.linear_ok && self.true_violation <= FEASIBILITY_TOLERANCE
    }

    /// Whether the iterate collides with an obstacle (signed distance below
    /// zero) at an optimisation phase: an obstacle across it, not merely
    /// near it. `false` when the evaluation was interrupted.
    pub(in crate::optim) fn collides(&self) -> bool {
        !self.interrupted
            && self
                .pairs
                .iter()
                .flat_map(|phase| phase.list.iter())
                .any(|c| c.distance < 0.0)
    }
}

impl Problem {
    /// Evaluate constraints at `z` on the optimisation phases; a stop by
    /// `ctl` skips the phases not yet evaluated and marks the result
    /// [`GridEval::interrupted`].
    pub(in crate::optim) fn evaluate_grid(
        &self,
        rows: &PhaseRows,
        z: DVector<f64>,
        centre: &DVector<f64>,
        ctl: &SolveControl,
    ) -> GridEval {
        let w = self.whitening.weights(&z);
        let target = self.clearance_m + CLEARANCE_BUFFER_M;
        let interrupted = AtomicBool::new(false);
        let pairs: Vec<PhasePairs> = if self.scene.is_empty() {
            Vec::new()
        } else {
            let phase_pairs = |p: usize| {
                if ctl.should_stop() {
                    interrupted.store(true, Ordering::Relaxed);
                    return None;
                }
                let q = rows.position(p, &w);
                let frames = self.robot.fk(&q);
                let list = self
                    .scene
                    .clearances_within(&self.robot, &frames, self.activation_m);
                (!list.is_empty()).then_some(PhasePairs {
                    phase: p,
                    phase_value: rows.phases()[p],
                    q,
                    frames,
                    list,
                })
            };
            if ctl.parallel() {
                (0..rows.len())
                    .into_par_iter()
                    .filter_map(phase_pairs)
                    .collect()
            } else {
                (0..rows.len()).filter_map(phase_pairs).collect()
            }
        };
        let mut buffered = 0.0;
        let mut truth = 0.0;
        for pp in &pairs {
            let phase_target = target + rows.margin(pp.phase);
            for c in &pp.list {
                buffered += (phase_target - c.distance).max(0.0);
                truth += (self.clearance_m - c.distance).max(0.0);
            }
        }
        let ends: Vec<EndEval> = self
            .end_constraints
            .iter()
            .map(|c| c.evaluate(&self.robot, self.ends.position(c.phase(), &w)))
            .collect();
        let goal_excess = ends.iter().fold(0.0, |sum, e| sum + e.excess);
        let linear_ok = self.linear_ok(rows, &w);
        GridEval {
            cost: (&z - centre).norm_squared(),
            z,
            w,
            pairs,
            buffered_violation: buffered,
            true_violation: truth + goal_excess,
            ends,
            linear_ok,
            interrupted: interrupted.into_inner(),
        }
    }

    /// Whether `w` satisfies the equality, weight-bound and limit rows of
    /// the optimisation phases (within [`LINEAR_TOLERANCE`]).
    fn linear_ok(&self, rows: &PhaseRows, w: &DVector<f64>) -> bool {
        let lin = &self.linear;
        lin.equality_error(&self.ends, w) <= LINEAR_TOLERANCE
            && lin.weight_bound_excess(w, self.prior.n_basis) <= LINEAR_TOLERANCE
            && lin.violated(rows, w, LINEAR_TOLERANCE).is_empty()
    }

    /// The most violated non-linear constraint at `eval`, in words.
    pub(in crate::optim) fn worst_constraint(&self, eval: &GridEval) -> String {
        let mut worst: Option<(f64, String)> = None;
        for pp in &eval.pairs {
            for c in &pp.list {
                keep_worst(&mut worst, self.clearance_m - c.distance, || {
                    format!(
                        "clearance_m: {} at t = {:.2} s (required {:.4} m)",
                        c.describe(&self.robot, &self.scene),
                        pp.phase_value * self.duration,
                        self.clearance_m
                    )
                });
            }
        }
        for (c, e) in self.end_constraints.iter().zip(&eval.ends) {
            keep_worst(&mut worst, e.excess, || c.describe(e));
        }
        match worst {
            Some((_, text)) => text,
            None if !eval.linear_ok => {
                "joint limits / velocity limits / start configuration".into()
            }
            None => "no constraint violated on the optimisation phases".into(),
        }
    }
}

/// Keep `(excess, text())` as the worst violation so far when it is a
/// violation and larger than the worst.
fn keep_worst(worst: &mut Option<(f64, String)>, excess: f64, text: impl FnOnce() -> String) {
    if excess > FEASIBILITY_TOLERANCE && worst.as_ref().is_none_or(|(e, _)| excess > *e) {
        *worst = Some((excess, text()));
    }
}
