//! Sequential convex programming towards a centre in whitened coordinates
//! (the prior mean for [`Problem::solve`], a draw for [`Problem::project`]).
//!
//! Each iteration linearises every clearance pair within the activation
//! distance (at every optimisation phase) and the goal at the current
//! iterate, and solves one QP with Clarabel: hard limit rows, L1-slacked
//! clearance rows and goal cone, and a trust-region ball `|z - z_k| ≤ Δ`.
//! The QP is solved on a small [`working_set`](super::working_set): the
//! rows active in the previous QP, thinned limit rows a step can reach, and
//! thinned clearance rows near the target. Limit rows the solution breaks
//! are always generated until none is left; clearance rows get
//! [`WORKING_SET_ROUNDS`] round(s), so that an iterate deep in collision
//! (hundreds of violated rows) still costs a small QP; the model the step
//! is judged against is then the working set's. A step is accepted when the
//! true merit `|z - c|² + ρ·violation` (real FK and parry distances, every
//! pair at every phase) improves by at least 10 % of the model's
//! prediction; otherwise the trust region shrinks. When the iteration
//! stalls short of feasibility, generation becomes exact (every violated
//! clearance row joins the QP), and only a stall on that full model raises
//! the penalty, up to a cap, after which the solve stops as
//! `max_iterations` naming the worst constraint (`infeasible` is reserved
//! for proofs: [`Problem::diagnose`]'s certificates and a QP whose hard
//! limit rows Clarabel proves incompatible). A converged feasible iterate is
//! verified densely; flagged phases join the optimisation set and the loop
//! goes on.

use super::linear::{RowKind, RowRef};
use super::phases::PhaseRows;
use super::problem::{Problem, FEASIBILITY_TOLERANCE};
use super::qp::{Cone, Inequality, Qp, QpFailure, QpSettings};
use super::report::{Status, TrajectoryReport};
use super::verify::Verification;
use super::working_set::{thin_in_time, Candidate};
use crate::robot::Frames;
use crate::scene::Clearance;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;
use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Clearance the QP aims for beyond `clearance_m` (m), so that small
/// linearisation and sampling errors do not leave the true trajectory just
/// short of the requirement.
pub const CLEARANCE_BUFFER_M: f64 = 2e-4;
/// Goal tolerance the QP aims for: `tolerance_m` less a buffer of
/// [`CLEARANCE_BUFFER_M`] (at most half the tolerance), for the same reason.
fn buffered_tolerance(tolerance_m: f64) -> f64 {
    tolerance_m - CLEARANCE_BUFFER_M.min(0.5 * tolerance_m)
}
/// Largest L1 penalty before slack is declared irreducible.
pub const MAX_PENALTY: f64 = 1e6;
/// A feasible iterate whose next step is predicted to improve the merit by
/// less than this fraction of it has converged (the tail of SCP on curved
/// constraints is linear; this stops it at a relative cost error of about
/// this size).
const OPTIMALITY_TOLERANCE: f64 = 1e-3;
/// Largest trust-region half-width.
pub const MAX_TRUST_REGION: f64 = 1e3;
/// Smallest trust-region half-width before the iteration counts as stalled.
pub const MIN_TRUST_REGION: f64 = 1e-4;
/// Linear rows count as satisfied within this (rad, rad/s).
const LINEAR_TOLERANCE: f64 = 1e-7;
/// Clearance rows within this much of the target (m) start in the working
/// set of each QP; the rest join by constraint generation.
const CLEARANCE_BAND_M: f64 = 3e-3;
/// A candidate row the QP solution breaks by more than this (rad, rad/s or
/// m) joins the working set.
const GENERATION_TOLERANCE: f64 = 1e-8;
/// Generation rounds of clearance rows per QP while the iterate is being
/// improved; limit rows are always generated to the end. One round (the
/// working set as it stands) keeps QPs small in the early iterations, when
/// hundreds of clearance rows are violated; the merit test guards the step,
/// and a stall switches to exact generation (see [`Problem::solve`]).
const WORKING_SET_ROUNDS: usize = 1;
/// Most phases added per dense verification round.
const MAX_ADDED_PER_ROUND: usize = 64;

/// How a caller stops a running solve.
#[derive(Clone, Debug, Default)]
pub struct SolveControl {
    /// Stop (status `max_iterations`, with a warning) after this instant.
    pub deadline: Option<Instant>,
    /// Stop when this becomes true.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl SolveControl {
    /// Why the solve must stop now, if it must.
    pub fn stop_reason(&self) -> Option<&'static str> {
        if self
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
        {
            return Some("cancelled by the caller");
        }
        if self.deadline.is_some_and(|d| Instant::now() >= d) {
            return Some("deadline reached");
        }
        None
    }

    fn seconds_left(&self) -> Option<f64> {
        self.deadline
            .map(|d| d.saturating_duration_since(Instant::now()).as_secs_f64())
    }
}

/// Counters of one solve (for benchmarks and the CLI).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SolveStats {
    /// SCP iterations (QP subproblems).
    pub iterations: usize,
    /// Clarabel solves (a subproblem takes one per generation round).
    pub qp_solves: usize,
    /// Clarabel interior-point iterations over all solves.
    pub ipm_iterations: usize,
    /// Steps rejected by the merit test.
    pub rejected_steps: usize,
    /// Largest QP: rows of the constraint matrix.
    pub max_qp_rows: usize,
    /// Largest QP: variables.
    pub max_qp_variables: usize,
    /// Phases added by dense verification.
    pub added_phases: usize,
    /// Final L1 penalty.
    pub final_penalty: f64,
    /// Wall time building and solving QPs (ms).
    pub qp_ms: f64,
    /// Wall time evaluating iterates on the optimisation phases (ms).
    pub evaluation_ms: f64,
    /// Wall time in dense verification (ms).
    pub verification_ms: f64,
}

/// Run `f`, adding its wall time in milliseconds to `acc`.
fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    *acc += t.elapsed().as_secs_f64() * 1e3;
    out
}

/// The result of [`Problem::solve`] / [`Problem::project`].
#[derive(Clone, Debug)]
pub struct Solution {
    /// Outcome.
    pub status: Status,
    /// Weights (joint-major).
    pub weights: Vec<f64>,
    /// Mahalanobis distance of the weights to the prior.
    pub mahalanobis: f64,
    /// Dense verification of the weights.
    pub report: TrajectoryReport,
    /// Why the status is not `optimal`.
    pub reason: Option<String>,
    /// Counters.
    pub stats: SolveStats,
}

/// Constraint values at one iterate on the optimisation phases.
struct GridEval {
    z: DVector<f64>,
    w: DVector<f64>,
    cost: f64,
    /// Pairs within the activation distance, per phase that has any.
    pairs: Vec<PhasePairs>,
    /// Σ max(0, clearance_m + buffer - d).
    buffered_violation: f64,
    /// Σ max(0, clearance_m - d) + goal excess: what must reach zero.
    true_violation: f64,
    goal: Option<GoalEval>,
    linear_ok: bool,
}

struct PhasePairs {
    phase: usize,
    phase_value: f64,
    q: Vec<f64>,
    frames: Frames,
    list: Vec<Clearance>,
}

struct GoalEval {
    q: Vec<f64>,
    residual: Vector3<f64>,
    /// Distance beyond `tolerance_m` (what must reach zero).
    excess: f64,
    /// Distance beyond the buffered tolerance the QP aims for (the merit's).
    buffered_excess: f64,
}

impl GridEval {
    fn merit(&self, rho: f64) -> f64 {
        self.cost + rho * (self.buffered_violation + self.goal_excess())
    }

    fn goal_excess(&self) -> f64 {
        self.goal.as_ref().map_or(0.0, |g| g.buffered_excess)
    }

    fn feasible(&self) -> bool {
        self.linear_ok && self.true_violation <= FEASIBILITY_TOLERANCE
    }
}

impl Problem {
    /// SCP towards the prior mean (the Mahalanobis-closest feasible weights).
    pub fn solve(&self, ctl: &SolveControl) -> Result<Solution> {
        let zero = DVector::zeros(self.whitening.dim());
        self.run(&zero, ctl)
    }

    /// Mahalanobis-closest feasible weights to `target` (under `Σ + λI`).
    pub fn project(&self, target: &[f64], ctl: &SolveControl) -> Result<Solution> {
        crate::error::ensure_len("target", target, self.prior.dim())?;
        crate::error::ensure_finite("target", target)?;
        let centre = self.whitening.whiten(&DVector::from_column_slice(target));
        self.run(&centre, ctl)
    }

    fn run(&self, centre: &DVector<f64>, ctl: &SolveControl) -> Result<Solution> {
        let started = Instant::now();
        let mut rows = self.grid.clone();
        let mut stats = SolveStats::default();
        let mut rho = self.options.penalty;
        let mut radius = self.options.trust_region;
        let mut eval = timed(&mut stats.evaluation_ms, || {
            self.evaluate_grid(&rows, centre.clone(), centre)
        });
        let mut converged = true;
        let mut hint = ActiveRows::default();
        let mut exact = false;
        loop {
            if converged && eval.feasible() {
                let v = timed(&mut stats.verification_ms, || self.verify(&eval.w));
                if v.flagged.is_empty() && self.is_feasible(&v.report) {
                    stats.final_penalty = rho;
                    return Ok(self.finish(
                        Status::Optimal,
                        &eval,
                        Some(v),
                        None,
                        stats,
                        started,
                        &[],
                    ));
                }
                let added = self.add_flagged(&mut rows, &v);
                stats.added_phases += added;
                if added == 0 {
                    let reason = "dense verification failed on a constraint the optimiser cannot refine (goal or equality)";
                    return Ok(self.finish(
                        Status::MaxIterations,
                        &eval,
                        Some(v),
                        Some(reason.into()),
                        stats,
                        started,
                        &[],
                    ));
                }
                eval = timed(&mut stats.evaluation_ms, || {
                    self.evaluate_grid(&rows, eval.z.clone(), centre)
                });
            }
            converged = false;
            if let Some(why) = ctl.stop_reason() {
                let warn = format!("solver stopped early: {why}");
                return Ok(self.stopped_early(&eval, warn, stats, started));
            }
            if stats.iterations >= self.options.max_iterations {
                let reason = format!(
                    "no converged feasible solution within {} iterations ({})",
                    self.options.max_iterations,
                    self.worst_constraint(&eval)
                );
                return Ok(self.unverified(Status::MaxIterations, &eval, reason, stats, started));
            }
            let at = Linearisation {
                exact,
                rows: &rows,
                eval: &eval,
                centre,
                rho,
                trust: eval.linear_ok.then_some(radius),
            };
            let mut qp_ms = 0.0;
            let subproblem = timed(&mut qp_ms, || self.subproblem(&at, &hint, ctl, &mut stats));
            stats.qp_ms += qp_ms;
            let (sol, model_here) = match subproblem {
                Ok((sol, model_here, active)) => {
                    hint = active;
                    (sol, model_here)
                }
                Err(QpFailure::Infeasible) => {
                    let reason = "joint position limits (minus the margin), velocity limits and the start / final configuration cannot all hold".to_string();
                    return Ok(self.unverified(Status::Infeasible, &eval, reason, stats, started));
                }
                Err(QpFailure::OutOfTime) => {
                    let warn = "solver stopped early: deadline reached".to_string();
                    return Ok(self.stopped_early(&eval, warn, stats, started));
                }
                Err(QpFailure::Numerical(what)) => {
                    let reason = format!("QP solver failed ({what}); best iterate returned");
                    return Ok(self.unverified(
                        Status::MaxIterations,
                        &eval,
                        reason,
                        stats,
                        started,
                    ));
                }
            };
            stats.iterations += 1;
            let step = (&sol.z - &eval.z).norm();
            let trial = timed(&mut stats.evaluation_ms, || {
                self.evaluate_grid(&rows, sol.z, centre)
            });
            let merit_here = eval.merit(rho);
            let predicted = model_here - sol.objective;
            let actual = merit_here - trial.merit(rho);
            let scale = 1.0 + merit_here.abs();
            let accept = !eval.linear_ok || actual >= 0.1 * predicted.max(0.0) - 1e-12 * scale;
            tracing::debug!(
                iteration = stats.iterations,
                rows = sol.rows,
                merit = merit_here,
                predicted,
                actual,
                step,
                radius,
                rho,
                violation = eval.true_violation,
                trial_violation = trial.true_violation,
                linear_ok = eval.linear_ok,
                accept,
                "scp step"
            );
            if accept {
                let tiny = step <= 1e-6 * (1.0 + trial.z.amax())
                    || predicted <= 1e-7 * scale
                    || (trial.feasible()
                        && (actual.abs() <= 1e-6 * scale
                            || predicted <= OPTIMALITY_TOLERANCE * scale));
                if eval.linear_ok && actual >= 0.75 * predicted && step >= 0.9 * radius {
                    radius = (radius * 2.0).min(MAX_TRUST_REGION);
                }
                eval = trial;
                if tiny {
                    converged = true;
                }
            } else {
                stats.rejected_steps += 1;
                radius = (0.25 * radius).min(0.5 * step);
                if radius < MIN_TRUST_REGION {
                    converged = true;
                    radius = self.options.trust_region;
                }
            }
            if converged && !eval.feasible() && eval.linear_ok && !exact {
                // A stall on the working-set model proves nothing: go on
                // with every clearance row generated, so that a penalty
                // increase (and `infeasible`) rests on the full model.
                exact = true;
                converged = false;
            } else if converged && !eval.feasible() && eval.linear_ok {
                rho *= 10.0;
                converged = false;
                if rho > MAX_PENALTY {
                    stats.final_penalty = rho;
                    // A stall of a non-convex penalty method is a local
                    // minimum of the violation, not a proof: `infeasible` is
                    // kept for the certificates of `diagnose` and the QP.
                    let reason = format!(
                        "no feasible solution found: {} could not be reduced further at the largest penalty (a local minimum of the violation; the problem may be infeasible)",
                        self.worst_constraint(&eval)
                    );
                    return Ok(self.unverified(
                        Status::MaxIterations,
                        &eval,
                        reason,
                        stats,
                        started,
                    ));
                }
            }
        }
    }

    /// Add (a spread-out subset of) the phases dense verification flagged.
    fn add_flagged(&self, rows: &mut PhaseRows, v: &Verification) -> usize {
        let before = rows.len();
        let stride = v.flagged.len().div_ceil(MAX_ADDED_PER_ROUND).max(1);
        for &p in v.flagged.iter().step_by(stride) {
            rows.push(&self.basis, &self.whitening, p);
        }
        rows.len() - before
    }

    /// Evaluate constraints at `z` on the optimisation phases.
    fn evaluate_grid(&self, rows: &PhaseRows, z: DVector<f64>, centre: &DVector<f64>) -> GridEval {
        let w = self.whitening.weights(&z);
        let target = self.clearance_m + CLEARANCE_BUFFER_M;
        let pairs: Vec<PhasePairs> = if self.scene.is_empty() {
            Vec::new()
        } else {
            (0..rows.len())
                .into_par_iter()
                .filter_map(|p| {
                    let q = rows.position(p, &w);
                    let frames = self.robot.fk(&q);
                    let list =
                        self.scene
                            .clearances_within(&self.robot, &frames, self.activation_m);
                    (!list.is_empty()).then_some(PhasePairs {
                        phase: p,
                        phase_value: rows.phases()[p],
                        q,
                        frames,
                        list,
                    })
                })
                .collect()
        };
        let mut buffered = 0.0;
        let mut truth = 0.0;
        for c in pairs.iter().flat_map(|pp| &pp.list) {
            buffered += (target - c.distance).max(0.0);
            truth += (self.clearance_m - c.distance).max(0.0);
        }
        let goal = self.goal.as_ref().map(|g| {
            let q = self.ends.position(1, &w);
            let p = self.robot.tcp_pose(&q).translation.vector;
            let residual = p - Vector3::from(g.position);
            let excess = (residual.norm() - g.tolerance_m).max(0.0);
            let buffered_excess = (residual.norm() - buffered_tolerance(g.tolerance_m)).max(0.0);
            GoalEval {
                q,
                residual,
                excess,
                buffered_excess,
            }
        });
        let goal_excess = goal.as_ref().map_or(0.0, |g| g.excess);
        let linear_ok = self.linear_ok(rows, &w);
        GridEval {
            cost: (&z - centre).norm_squared(),
            z,
            w,
            pairs,
            buffered_violation: buffered,
            true_violation: truth + goal_excess,
            goal,
            linear_ok,
        }
    }

    fn linear_ok(&self, rows: &PhaseRows, w: &DVector<f64>) -> bool {
        let lin = &self.linear;
        lin.equality_error(&self.ends, w) <= LINEAR_TOLERANCE
            && lin.weight_bound_excess(w, self.prior.n_basis) <= LINEAR_TOLERANCE
            && lin.violated(rows, w, LINEAR_TOLERANCE).is_empty()
    }

    /// Build and solve the QP at `eval` by constraint generation over the
    /// [`working_set`](super::working_set); returns the solution (optimal
    /// for the full linearised QP) and the model's value at the current
    /// iterate.
    fn subproblem(
        &self,
        at: &Linearisation,
        hint: &ActiveRows,
        ctl: &SolveControl,
        stats: &mut SolveStats,
    ) -> std::result::Result<(super::qp::QpSolution, f64, ActiveRows), QpFailure> {
        let Linearisation {
            exact,
            rows,
            eval,
            centre,
            rho,
            trust,
        } = *at;
        let mean = &self.prior.mean;
        let target = self.clearance_m + CLEARANCE_BUFFER_M;
        let mut qp = Qp::new(self.whitening.dim());
        qp.center = centre.clone();
        qp.equalities = self.linear.equalities(&self.ends, mean);
        qp.inequalities.extend(self.linear.weight_bounds(
            self.whitening.factor(),
            mean,
            self.prior.n_basis,
        ));
        let mut ids = vec![RowId::Other; qp.inequalities.len()];
        let clearance = self.clearance_rows(rows, eval, target, rho);
        let mut model_slack: f64 = clearance.iter().map(|c| c.shortfall).sum();
        if let Some((cone, excess)) = self.goal_cone(eval, rho) {
            qp.cones.push(cone);
            model_slack += excess;
        }
        if let Some(r) = trust {
            qp.trust = Some((eval.z.clone(), r));
        }
        let settings = QpSettings {
            tolerance: self.options.qp_tolerance,
            time_limit: ctl.seconds_left(),
            ..Default::default()
        };
        let model_here = eval.cost + rho * model_slack;

        // The first working set: the rows active in the previous QP, thinned
        // limit rows a step can reach, and thinned clearance rows within a
        // band of the target.
        let mut linear_in = HashSet::new();
        let mut clearance_in = vec![false; clearance.len()];
        for &r in &hint.linear {
            self.add_linear_row(&mut qp, &mut ids, &mut linear_in, rows, r);
        }
        let carried: Vec<usize> = (0..clearance.len())
            .filter(|&i| hint.clearance.contains(&clearance[i].id()))
            .collect();
        add_clearance_rows(&mut qp, &mut ids, &mut clearance_in, &clearance, &carried);
        let screened = self.linear.screen_banded(rows, &eval.w, trust);
        self.add_linear_rows(&mut qp, &mut ids, &mut linear_in, rows, &eval.w, screened);
        let initial = thin_in_time(
            &clearance
                .iter()
                .map(|c| Candidate {
                    key: c.key,
                    phase: c.phase,
                    score: -c.distance,
                    in_band: c.distance < target + CLEARANCE_BAND_M,
                })
                .collect::<Vec<_>>(),
        );
        add_clearance_rows(&mut qp, &mut ids, &mut clearance_in, &clearance, &initial);

        // Constraint generation until the solution violates no candidate
        // (limit rows always; clearance rows for a few rounds, then the
        // model is the working set's).
        let mut round = 0;
        loop {
            round += 1;
            let sol = qp.solve(&settings)?;
            stats.qp_solves += 1;
            stats.ipm_iterations += sol.ipm_iterations as usize;
            stats.max_qp_rows = stats.max_qp_rows.max(sol.rows);
            stats.max_qp_variables = stats.max_qp_variables.max(sol.variables);
            let w = self.whitening.weights(&sol.z);
            let linear_missing: Vec<RowRef> = self
                .linear
                .violated(rows, &w, GENERATION_TOLERANCE)
                .into_iter()
                .filter(|r| !linear_in.contains(r))
                .collect();
            // (index, violation) of the clearance rows the solution breaks.
            let violated: Vec<(usize, f64)> = (0..clearance.len())
                .filter(|&i| !clearance_in[i])
                .map(|i| (i, clearance[i].violation(&sol.z)))
                .filter(|&(_, v)| v > GENERATION_TOLERANCE)
                .collect();
            if linear_missing.is_empty() && violated.is_empty() {
                let active = active_rows(&ids, &sol, &clearance);
                return Ok((sol, model_here, active));
            }
            if linear_missing.is_empty() && !exact && round >= WORKING_SET_ROUNDS {
                // The model is the working set's: rows left out do not count.
                let left_out: f64 = (0..clearance.len())
                    .filter(|&i| !clearance_in[i])
                    .map(|i| clearance[i].shortfall)
                    .sum();
                let active = active_rows(&ids, &sol, &clearance);
                return Ok((sol, model_here - rho * left_out, active));
            }
            self.add_linear_rows(&mut qp, &mut ids, &mut linear_in, rows, &w, linear_missing);
            let chosen = thin_in_time(
                &violated
                    .iter()
                    .map(|&(i, v)| Candidate {
                        key: clearance[i].key,
                        phase: clearance[i].phase,
                        score: v,
                        in_band: true,
                    })
                    .collect::<Vec<_>>(),
            );
            let chosen: Vec<usize> = chosen.into_iter().map(|k| violated[k].0).collect();
            add_clearance_rows(&mut qp, &mut ids, &mut clearance_in, &clearance, &chosen);
        }
    }

    /// Every clearance pair of `eval` linearised at its iterate:
    /// `d + ∇d·(z - z_k) >= target`, with an L1-penalised slack.
    fn clearance_rows(
        &self,
        rows: &PhaseRows,
        eval: &GridEval,
        target: f64,
        rho: f64,
    ) -> Vec<ClearanceRow> {
        eval.pairs
            .iter()
            .flat_map(|pp| {
                let jac = rows.position_jacobian(pp.phase);
                pp.list.iter().map(move |c| {
                    let g = self
                        .scene
                        .clearance_gradient(&self.robot, &pp.q, &pp.frames, c);
                    let a = jac.tr_mul(&g);
                    ClearanceRow {
                        phase_index: pp.phase,
                        key: (c.shape, c.obstacle),
                        phase: pp.phase_value,
                        distance: c.distance,
                        shortfall: (target - c.distance).max(0.0),
                        row: Inequality {
                            b: c.distance - a.dot(&eval.z) - target,
                            a: -a,
                            penalty: Some(rho),
                        },
                    }
                })
            })
            .collect()
    }

    /// The goal as a second-order cone linearised at `eval`, and its excess.
    fn goal_cone(&self, eval: &GridEval, rho: f64) -> Option<(Cone, f64)> {
        let (goal, ge) = (self.goal.as_ref()?, eval.goal.as_ref()?);
        let j = self.robot.tcp_jacobian(&ge.q);
        let linear = DMatrix::from_iterator(3, j.ncols(), j.rows(0, 3).iter().cloned());
        let g = linear * self.ends.position_jacobian(1);
        let gz = &g * &eval.z;
        let cone = Cone {
            offset: DVector::from_fn(3, |i, _| ge.residual[i] - gz[i]),
            matrix: g,
            radius: buffered_tolerance(goal.tolerance_m),
            penalty: rho,
        };
        Some((cone, ge.buffered_excess))
    }

    /// Add `candidates` (thinned in time, scored by their excess at `w`)
    /// to the QP's hard rows.
    fn add_linear_rows(
        &self,
        qp: &mut Qp,
        ids: &mut Vec<RowId>,
        included: &mut HashSet<RowRef>,
        rows: &PhaseRows,
        w: &DVector<f64>,
        candidates: Vec<RowRef>,
    ) {
        let scored: Vec<Candidate<(usize, RowKind)>> = candidates
            .iter()
            .map(|&r| Candidate {
                key: (r.joint, r.kind),
                phase: rows.phases()[r.phase],
                score: self.linear.excess(rows, w, r),
                in_band: true,
            })
            .collect();
        for k in thin_in_time(&scored) {
            self.add_linear_row(qp, ids, included, rows, candidates[k]);
        }
    }

    /// Add limit row `r` to the QP unless it is already there.
    fn add_linear_row(
        &self,
        qp: &mut Qp,
        ids: &mut Vec<RowId>,
        included: &mut HashSet<RowRef>,
        rows: &PhaseRows,
        r: RowRef,
    ) {
        if included.insert(r) {
            qp.inequalities
                .push(self.linear.inequality(rows, &self.prior.mean, r));
            ids.push(RowId::Linear(r));
        }
    }

    /// The most violated non-linear constraint at `eval`, in words.
    fn worst_constraint(&self, eval: &GridEval) -> String {
        let mut worst: Option<(f64, String)> = None;
        for pp in &eval.pairs {
            for c in &pp.list {
                let excess = self.clearance_m - c.distance;
                if excess > FEASIBILITY_TOLERANCE && worst.as_ref().is_none_or(|(e, _)| excess > *e)
                {
                    let t = pp.phase_value * self.duration;
                    worst = Some((
                        excess,
                        format!(
                            "clearance_m: link {} is {:.4} m from obstacle '{}' at t = {:.2} s (required {:.4} m)",
                            c.link_name(&self.robot),
                            c.distance,
                            c.obstacle_id(&self.scene),
                            t,
                            self.clearance_m
                        ),
                    ));
                }
            }
        }
        if let (Some(goal), Some(ge)) = (&self.goal, &eval.goal) {
            if ge.excess > FEASIBILITY_TOLERANCE
                && worst.as_ref().is_none_or(|(e, _)| ge.excess > *e)
            {
                worst = Some((
                    ge.excess,
                    format!(
                        "goal: the TCP ends {:.4} m from the goal (tolerance_m {:.4})",
                        ge.residual.norm(),
                        goal.tolerance_m
                    ),
                ));
            }
        }
        match worst {
            Some((_, text)) => text,
            None if !eval.linear_ok => {
                "joint limits / velocity limits / start configuration".into()
            }
            None => "no constraint violated on the optimisation phases".into(),
        }
    }

    /// Finish without a prior verification (it is run here) and with `reason`.
    fn unverified(
        &self,
        status: Status,
        eval: &GridEval,
        reason: String,
        stats: SolveStats,
        started: Instant,
    ) -> Solution {
        self.finish(status, eval, None, Some(reason), stats, started, &[])
    }

    /// Finish as `max_iterations` because the caller stopped the solver;
    /// the reason is also reported as a warning.
    fn stopped_early(
        &self,
        eval: &GridEval,
        warn: String,
        stats: SolveStats,
        started: Instant,
    ) -> Solution {
        let warnings = [warn.clone()];
        self.finish(
            Status::MaxIterations,
            eval,
            None,
            Some(warn),
            stats,
            started,
            &warnings,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn finish(
        &self,
        status: Status,
        eval: &GridEval,
        verification: Option<Verification>,
        reason: Option<String>,
        stats: SolveStats,
        started: Instant,
        extra_warnings: &[String],
    ) -> Solution {
        let v = verification.unwrap_or_else(|| self.verify(&eval.w));
        let mut report = v.report;
        report.iterations = stats.iterations;
        report.warnings = self.warnings.clone();
        report.warnings.extend(extra_warnings.iter().cloned());
        if stats.added_phases > 0 {
            report.warnings.push(format!(
                "dense verification added {} phases to the optimisation set",
                stats.added_phases
            ));
        }
        report.solve_ms = started.elapsed().as_secs_f64() * 1e3;
        Solution {
            status,
            weights: eval.w.as_slice().to_vec(),
            mahalanobis: self.whitening.mahalanobis(&eval.w),
            report,
            reason,
            stats,
        }
    }
}

/// A linearised clearance row of one (robot shape, obstacle) pair at one
/// optimisation phase.
struct ClearanceRow {
    /// Index of the phase in the optimisation set.
    phase_index: usize,
    /// (robot shape, obstacle).
    key: (usize, usize),
    phase: f64,
    /// Signed distance at the iterate the row is linearised at.
    distance: f64,
    /// `max(0, target - distance)`: the row's slack at that iterate.
    shortfall: f64,
    row: Inequality,
}

impl ClearanceRow {
    /// (phase index, robot shape, obstacle): the row's identity across
    /// iterations.
    fn id(&self) -> (usize, usize, usize) {
        (self.phase_index, self.key.0, self.key.1)
    }

    /// How far `z` breaks the linearised row without slack (> 0: violated).
    fn violation(&self, z: &DVector<f64>) -> f64 {
        self.row.a.dot(z) - self.row.b
    }
}

/// Add the clearance rows `chosen` (indices into `all`) to the QP.
fn add_clearance_rows(
    qp: &mut Qp,
    ids: &mut Vec<RowId>,
    included: &mut [bool],
    all: &[ClearanceRow],
    chosen: &[usize],
) {
    for &i in chosen {
        if !included[i] {
            included[i] = true;
            qp.inequalities.push(all[i].row.clone());
            ids.push(RowId::Clearance(i));
        }
    }
}

/// What one QP inequality is.
#[derive(Clone, Copy, Debug)]
enum RowId {
    /// A limit or velocity row.
    Linear(RowRef),
    /// Index into the subproblem's clearance rows.
    Clearance(usize),
    /// An opt-in weight bound.
    Other,
}

/// Rows active at a QP solution (positive multiplier): the start
/// of the next QP's working set.
#[derive(Clone, Debug, Default)]
struct ActiveRows {
    linear: Vec<RowRef>,
    /// (phase index, robot shape, obstacle).
    clearance: HashSet<(usize, usize, usize)>,
}

/// Multipliers below this fraction of the largest one count as inactive.
const ACTIVE_DUAL_FRACTION: f64 = 1e-6;

/// The rows of `ids` active at `sol`.
fn active_rows(
    ids: &[RowId],
    sol: &super::qp::QpSolution,
    clearance: &[ClearanceRow],
) -> ActiveRows {
    let largest = sol
        .inequality_duals
        .iter()
        .fold(0.0f64, |m, &d| m.max(d.abs()));
    let threshold = ACTIVE_DUAL_FRACTION * largest.max(1e-12);
    let mut out = ActiveRows::default();
    for (k, id) in ids.iter().enumerate() {
        let active = sol.inequality_duals[k] > threshold;
        match (*id, active) {
            (RowId::Linear(r), true) => out.linear.push(r),
            (RowId::Clearance(i), true) => {
                out.clearance.insert(clearance[i].id());
            }
            _ => {}
        }
    }
    out
}

/// Where a subproblem is linearised.
#[derive(Clone, Copy)]
struct Linearisation<'a> {
    /// Generate clearance rows until none is violated (else
    /// [`WORKING_SET_ROUNDS`] rounds).
    exact: bool,
    rows: &'a PhaseRows,
    eval: &'a GridEval,
    centre: &'a DVector<f64>,
    rho: f64,
    trust: Option<f64>,
}

impl From<QpFailure> for Error {
    fn from(f: QpFailure) -> Error {
        f.into_error()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::example::{typical_request, ExampleSettings};
    use crate::optim::linear::LinearSet;

    /// The QP of every candidate row, built without the working set.
    fn full_qp(p: &Problem, at: &Linearisation) -> Qp {
        let target = p.clearance_m + CLEARANCE_BUFFER_M;
        let mut qp = Qp::new(p.whitening.dim());
        qp.center = at.centre.clone();
        qp.equalities = p.linear.equalities(&p.ends, &p.prior.mean);
        qp.inequalities = LinearSet::all_rows(at.rows)
            .map(|r| p.linear.inequality(at.rows, &p.prior.mean, r))
            .collect();
        qp.inequalities.extend(
            p.clearance_rows(at.rows, at.eval, target, at.rho)
                .into_iter()
                .map(|c| c.row),
        );
        if let Some((cone, _)) = p.goal_cone(at.eval, at.rho) {
            qp.cones.push(cone);
        }
        qp.trust = at.trust.map(|r| (at.eval.z.clone(), r));
        qp
    }

    #[test]
    fn exact_constraint_generation_solves_the_full_qp() {
        let robot = crate::robot::Robot::panda().unwrap();
        for seed in [0, 4] {
            let p = typical_request(&robot, seed, &ExampleSettings::default())
                .unwrap()
                .validate(&robot)
                .unwrap();
            let centre = DVector::zeros(p.whitening.dim());
            // Linearise at a point off the prior mean (inside the limits).
            let z0 = DVector::from_fn(p.whitening.dim(), |i, _| 0.05 * ((i % 5) as f64 - 2.0));
            let eval = p.evaluate_grid(&p.grid, z0, &centre);
            assert!(!eval.pairs.is_empty(), "seed {seed}: no clearance pair");
            let at = Linearisation {
                exact: true,
                rows: &p.grid,
                eval: &eval,
                centre: &centre,
                rho: 1e3,
                trust: Some(2.0),
            };
            let mut stats = SolveStats::default();
            let (sol, _, _) = p
                .subproblem(
                    &at,
                    &ActiveRows::default(),
                    &SolveControl::default(),
                    &mut stats,
                )
                .unwrap();
            let full = full_qp(&p, &at).solve(&QpSettings::default()).unwrap();
            assert!(
                stats.max_qp_rows < full.rows / 4,
                "seed {seed}: working set {} rows of {}",
                stats.max_qp_rows,
                full.rows
            );
            // Clarabel stops at a 1e-8 duality gap; with the strongly convex
            // |z|² that bounds |z - z*| by about sqrt(1e-8 x objective).
            let gap = (&sol.z - &full.z).amax();
            assert!(gap < 1e-4, "seed {seed}: |z - z_full| = {gap:e}");
            // Rows left out may each be broken by up to GENERATION_TOLERANCE
            // without their slack: at most ρ·1e-8 per row in the objective.
            let rel = (sol.objective - full.objective).abs() / (1.0 + full.objective.abs());
            assert!(
                rel < 1e-6,
                "seed {seed}: objective {} vs {}",
                sol.objective,
                full.objective
            );
        }
    }
}
