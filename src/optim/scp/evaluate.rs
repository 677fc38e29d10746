//! One SCP iterate evaluated on the optimisation phases: forward
//! kinematics, every clearance pair within the activation distance (parry),
//! the goal residual, the limit rows, and the merit the step test uses.

use crate::optim::problem::phases::PhaseRows;
use crate::optim::problem::Problem;
use crate::optim::solution::SolveControl;
use crate::optim::tolerances::{buffered_angle, buffered_tolerance};
use crate::optim::tolerances::{CLEARANCE_BUFFER_M, FEASIBILITY_TOLERANCE, LINEAR_TOLERANCE};
use crate::robot::Frames;
use crate::scene::Clearance;
use nalgebra::{DVector, UnitQuaternion, Vector3};
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
    pub(in crate::optim) goal: Option<GoalEval>,
    /// The position waypoints, in the problem's order.
    pub(in crate::optim) via: Vec<GoalEval>,
    /// The configurations at the tolerant configuration waypoints, in the
    /// problem's order.
    pub(in crate::optim) via_boxes: Vec<Vec<f64>>,
    /// Their excess beyond the buffered tolerances (the merit's).
    pub(in crate::optim) via_box_excess: f64,
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

pub(in crate::optim) struct GoalEval {
    pub(in crate::optim) q: Vec<f64>,
    pub(in crate::optim) residual: Vector3<f64>,
    /// Distance beyond `tolerance_m` (what must reach zero).
    pub(in crate::optim) excess: f64,
    /// Distance beyond the buffered tolerance the QP aims for (the merit's).
    pub(in crate::optim) buffered_excess: f64,
    /// The approach direction, when the goal has one.
    pub(in crate::optim) approach: Option<ApproachEval>,
}

/// The approach constraint `a(q)·u >= cos(tolerance)` at the final
/// configuration, `a` the gripper's z axis and `u` the goal's axis.
pub(in crate::optim) struct ApproachEval {
    /// `a(q)·u`.
    pub(in crate::optim) cosine: f64,
    /// `∂(a·u)/∂q`: `(ω_j × a)·u` for each joint's angular Jacobian column.
    pub(in crate::optim) gradient: Vec<f64>,
    /// `cos(tolerance) - a·u` when positive (what must reach zero).
    pub(in crate::optim) excess: f64,
    /// The same against the buffered tolerance the QP aims for.
    pub(in crate::optim) buffered_excess: f64,
    /// The cosine the QP aims for.
    pub(in crate::optim) target: f64,
}

impl GridEval {
    pub(in crate::optim) fn merit(&self, rho: f64) -> f64 {
        self.cost + rho * (self.buffered_violation + self.goal_excess())
    }

    pub(in crate::optim) fn goal_excess(&self) -> f64 {
        let via: f64 =
            self.via.iter().map(|v| v.buffered_excess).sum::<f64>() + self.via_box_excess;
        via + self.goal.as_ref().map_or(0.0, |g| {
            g.buffered_excess + g.approach.as_ref().map_or(0.0, |a| a.buffered_excess)
        })
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
        for c in pairs.iter().flat_map(|pp| &pp.list) {
            buffered += (target - c.distance).max(0.0);
            truth += (self.clearance_m - c.distance).max(0.0);
        }
        let goal = self.goal.as_ref().map(|g| {
            let (mut eval, rotation) =
                self.tcp_eval(&w, 1, &Vector3::from(g.position), g.tolerance_m);
            eval.approach = self.approach_eval(&eval.q, &rotation);
            eval
        });
        let via: Vec<GoalEval> = self
            .via_positions
            .iter()
            .map(|v| self.tcp_eval(&w, v.ends, &v.position, v.tolerance_m).0)
            .collect();
        let via_boxes: Vec<Vec<f64>> = self
            .via_boxes
            .iter()
            .map(|v| self.ends.position(v.ends, &w))
            .collect();
        let (box_excess, via_box_excess) =
            self.via_boxes
                .iter()
                .zip(&via_boxes)
                .fold((0.0, 0.0), |(e, b), (v, q)| {
                    (
                        e + v.excess(q, v.tolerance_rad),
                        b + v.excess(q, buffered_angle(v.tolerance_rad)),
                    )
                });
        let goal_excess = box_excess
            + via.iter().map(|v| v.excess).sum::<f64>()
            + goal.as_ref().map_or(0.0, |g| {
                g.excess + g.approach.as_ref().map_or(0.0, |a| a.excess)
            });
        let linear_ok = self.linear_ok(rows, &w);
        GridEval {
            cost: (&z - centre).norm_squared(),
            z,
            w,
            pairs,
            buffered_violation: buffered,
            true_violation: truth + goal_excess,
            goal,
            via,
            via_boxes,
            via_box_excess,
            linear_ok,
            interrupted: interrupted.into_inner(),
        }
    }

    /// The TCP at `ends` phase `p` against `target` within `tolerance` (no
    /// approach), and the TCP's orientation there.
    fn tcp_eval(
        &self,
        w: &DVector<f64>,
        p: usize,
        target: &Vector3<f64>,
        tolerance: f64,
    ) -> (GoalEval, UnitQuaternion<f64>) {
        let q = self.ends.position(p, w);
        let pose = self.robot.tcp_pose(&q);
        let residual = pose.translation.vector - target;
        let eval = GoalEval {
            excess: (residual.norm() - tolerance).max(0.0),
            buffered_excess: (residual.norm() - buffered_tolerance(tolerance)).max(0.0),
            q,
            residual,
            approach: None,
        };
        (eval, pose.rotation)
    }

    /// The approach constraint at final configuration `q` (where the TCP's
    /// orientation is `rotation`), if the goal has an approach axis.
    fn approach_eval(&self, q: &[f64], rotation: &UnitQuaternion<f64>) -> Option<ApproachEval> {
        let (axis, tolerance) = self.approach()?;
        let a = rotation * Vector3::z();
        let jac = self.robot.tcp_jacobian(q);
        let gradient = (0..jac.ncols())
            .map(|j| {
                let omega = Vector3::new(jac[(3, j)], jac[(4, j)], jac[(5, j)]);
                omega.cross(&a).dot(&axis)
            })
            .collect();
        let cosine = a.dot(&axis);
        let target = buffered_angle(tolerance).cos();
        Some(ApproachEval {
            cosine,
            gradient,
            excess: (tolerance.cos() - cosine).max(0.0),
            buffered_excess: (target - cosine).max(0.0),
            target,
        })
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
        if let (Some(goal), Some(ge)) = (&self.goal, &eval.goal) {
            keep_worst(&mut worst, ge.excess, || {
                format!(
                    "goal: the TCP ends {:.4} m from the goal (tolerance_m {:.4})",
                    ge.residual.norm(),
                    goal.tolerance_m
                )
            });
        }
        for (v, ve) in self.via_positions.iter().zip(&eval.via) {
            keep_worst(&mut worst, ve.excess, || {
                format!(
                    "via_points[{}]: the TCP passes {:.4} m from the position (tolerance_m {:.4})",
                    v.index,
                    ve.residual.norm(),
                    v.tolerance_m
                )
            });
        }
        for (v, q) in self.via_boxes.iter().zip(&eval.via_boxes) {
            keep_worst(&mut worst, v.excess(q, v.tolerance_rad), || {
                format!(
                    "via_points[{}]: the joints pass beyond tolerance_rad {:.4} of the configuration",
                    v.index, v.tolerance_rad
                )
            });
        }
        if let Some(a) = eval.goal.as_ref().and_then(|g| g.approach.as_ref()) {
            let limit = self.approach().map_or(0.0, |(_, t)| t);
            keep_worst(&mut worst, a.excess, || {
                format!(
                    "goal.approach_axis: the gripper ends {:.4} rad off the approach axis (approach_tolerance_rad {limit:.4})",
                    a.cosine.clamp(-1.0, 1.0).acos()
                )
            });
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
