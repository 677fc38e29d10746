//! Sequential convex programming towards a centre in whitened coordinates
//! (the prior mean for [`Problem::solve`], a draw for [`Problem::project`]).
//!
//! Each iteration linearises the clearances (pairs within the activation
//! distance, at every optimisation phase) and the goal at the current
//! iterate, solves one QP (hard linear rows, L1-slacked clearance rows and
//! goal cone, trust-region box) with Clarabel, and accepts the step when the
//! true merit `|z - c|² + ρ·violation` (real FK and parry distances)
//! improves by at least 10 % of the model's prediction; otherwise the trust
//! region shrinks. A converged feasible iterate is verified densely; flagged
//! phases join the optimisation set and the loop goes on. Slack that the
//! penalty cannot drive to zero raises the penalty, up to a cap, then the
//! problem is reported infeasible with the worst constraint.

use super::phases::PhaseRows;
use super::problem::{Problem, FEASIBILITY_TOLERANCE};
use super::qp::{Cone, Inequality, Qp, QpFailure, QpSettings};
use super::report::{Status, TrajectoryReport};
use super::verify::Verification;
use crate::robot::Frames;
use crate::scene::Clearance;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Clearance the QP aims for beyond `clearance_m` (m), so that small
/// linearisation and sampling errors do not leave the true trajectory just
/// short of the requirement.
pub const CLEARANCE_BUFFER_M: f64 = 2e-4;
/// Largest L1 penalty before slack is declared irreducible.
pub const MAX_PENALTY: f64 = 1e6;
/// Largest trust-region half-width.
pub const MAX_TRUST_REGION: f64 = 1e3;
/// Smallest trust-region half-width before the iteration counts as stalled.
pub const MIN_TRUST_REGION: f64 = 1e-4;
/// Linear rows count as satisfied within this (rad, rad/s).
const LINEAR_TOLERANCE: f64 = 1e-7;
/// Robot shapes linearised per obstacle and phase (the closest ones).
const SHAPES_PER_OBSTACLE: usize = 2;
/// Of a run of phases where a pair is short of the clearance target, every
/// this-many-th phase gets a QP row (besides the local minima).
const VIOLATION_STRIDE: usize = 3;
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
    /// QPs solved.
    pub iterations: usize,
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
    excess: f64,
}

impl GridEval {
    fn merit(&self, rho: f64) -> f64 {
        self.cost + rho * (self.buffered_violation + self.goal_excess())
    }

    fn goal_excess(&self) -> f64 {
        self.goal.as_ref().map_or(0.0, |g| g.excess)
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
        // Temporal screening of clearance rows; switched off for good at
        // the first rejected step, so that a stall (and so a penalty
        // increase or an `infeasible` verdict) is only declared on the full
        // set of clearance rows.
        let mut screen_time = true;
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
            let trust = eval.linear_ok.then_some(radius);
            let (sol, model_here) = match timed(&mut stats.qp_ms, || {
                self.subproblem(&rows, &eval, centre, rho, trust, screen_time, ctl)
            }) {
                Ok(x) => x,
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
            stats.max_qp_rows = stats.max_qp_rows.max(sol.rows);
            stats.max_qp_variables = stats.max_qp_variables.max(sol.variables);
            let step = (&sol.z - &eval.z).amax();
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
                    || (trial.feasible() && actual.abs() <= 1e-6 * scale);
                if eval.linear_ok && actual >= 0.75 * predicted && step >= 0.9 * radius {
                    radius = (radius * 2.0).min(MAX_TRUST_REGION);
                }
                eval = trial;
                if tiny {
                    converged = true;
                }
            } else {
                stats.rejected_steps += 1;
                if screen_time {
                    // The screened model missed a clearance row the step
                    // broke: use every row from now on, same radius.
                    screen_time = false;
                } else {
                    radius = (0.25 * radius).min(0.5 * step);
                    if radius < MIN_TRUST_REGION {
                        converged = true;
                        radius = self.options.trust_region;
                    }
                }
            }
            if converged && !eval.feasible() && eval.linear_ok {
                rho *= 10.0;
                converged = false;
                if rho > MAX_PENALTY {
                    stats.final_penalty = rho;
                    let reason = format!(
                        "constraint cannot be satisfied: {}",
                        self.worst_constraint(&eval)
                    );
                    return Ok(self.unverified(Status::Infeasible, &eval, reason, stats, started));
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
                    let list = closest_per_obstacle(
                        self.scene
                            .clearances_within(&self.robot, &frames, self.activation_m),
                        SHAPES_PER_OBSTACLE,
                    );
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
            GoalEval {
                q,
                residual,
                excess,
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

    /// Build and solve the QP at `eval`; returns the solution and the
    /// model's value at the current iterate.
    #[allow(clippy::too_many_arguments)]
    fn subproblem(
        &self,
        rows: &PhaseRows,
        eval: &GridEval,
        centre: &DVector<f64>,
        rho: f64,
        trust: Option<f64>,
        screen_time: bool,
        ctl: &SolveControl,
    ) -> std::result::Result<(super::qp::QpSolution, f64), QpFailure> {
        let mean = &self.prior.mean;
        let mut qp = Qp::new(self.whitening.dim());
        qp.center = centre.clone();
        qp.equalities = self.linear.equalities(&self.ends, mean);
        let mut included = self.linear.screen_banded(rows, &eval.w, trust);
        qp.inequalities = included
            .iter()
            .map(|&r| self.linear.inequality(rows, mean, r))
            .collect();
        qp.inequalities.extend(self.linear.weight_bounds(
            self.whitening.factor(),
            mean,
            self.prior.n_basis,
        ));
        let target = self.clearance_m + CLEARANCE_BUFFER_M;
        let mut model_slack = 0.0;
        let keep: Vec<Vec<bool>> = if screen_time {
            screen_in_time(&eval.pairs, target)
        } else {
            eval.pairs
                .iter()
                .map(|pp| vec![true; pp.list.len()])
                .collect()
        };
        for (k, pp) in eval.pairs.iter().enumerate() {
            if !keep[k].iter().any(|&x| x) {
                continue;
            }
            let jac = rows.position_jacobian(pp.phase);
            for (i, c) in pp.list.iter().enumerate() {
                if !keep[k][i] {
                    continue;
                }
                let g = self
                    .scene
                    .clearance_gradient(&self.robot, &pp.q, &pp.frames, c);
                let a = jac.tr_mul(&g);
                qp.inequalities.push(Inequality {
                    b: c.distance - a.dot(&eval.z) - target,
                    a: -a,
                    penalty: Some(rho),
                });
                model_slack += (target - c.distance).max(0.0);
            }
        }
        if let (Some(goal), Some(ge)) = (&self.goal, &eval.goal) {
            let j = self.robot.tcp_jacobian(&ge.q);
            let linear = DMatrix::from_iterator(3, j.ncols(), j.rows(0, 3).iter().cloned());
            let g = linear * self.ends.position_jacobian(1);
            let gz = &g * &eval.z;
            qp.cones.push(Cone {
                offset: DVector::from_fn(3, |i, _| ge.residual[i] - gz[i]),
                matrix: g,
                radius: goal.tolerance_m,
                penalty: rho,
            });
            model_slack += ge.excess;
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
        let mut sol = qp.solve(&settings)?;
        // Row generation: add any grid row the solution violates (each
        // round adds at least one of finitely many rows, so this ends).
        loop {
            let w = self.whitening.weights(&sol.z);
            let missing: Vec<_> = self
                .linear
                .violated(rows, &w, LINEAR_TOLERANCE * 0.1)
                .into_iter()
                .filter(|r| !included.contains(r))
                .collect();
            if missing.is_empty() {
                break;
            }
            for r in missing {
                qp.inequalities.push(self.linear.inequality(rows, mean, r));
                included.push(r);
            }
            sol = qp.solve(&settings)?;
        }
        Ok((sol, model_here))
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
                            c.link_name, c.distance, c.obstacle_id, t, self.clearance_m
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

/// One phase of a (shape, obstacle) pair: phase value, index into the
/// pairs, index into that phase's list, distance.
type PairEntry = (f64, usize, usize, f64);

/// Which clearance rows of `pairs` enter the QP. Clearance is smooth in
/// time, so per (robot shape, obstacle) pair only the phases where its
/// distance is a local minimum over the optimisation phases are kept, plus
/// every [`VIOLATION_STRIDE`]-th phase of each run where the pair is short
/// of `target`. The merit still counts every phase, and dense verification
/// still checks everything, so this only changes which rows steer the step.
fn screen_in_time(pairs: &[PhasePairs], target: f64) -> Vec<Vec<bool>> {
    let mut keep: Vec<Vec<bool>> = pairs.iter().map(|pp| vec![false; pp.list.len()]).collect();
    // (shape, obstacle) -> entries (phase value, pair-phase index, list index, distance).
    let mut by_pair: std::collections::HashMap<(usize, usize), Vec<PairEntry>> =
        std::collections::HashMap::new();
    for (k, pp) in pairs.iter().enumerate() {
        for (i, c) in pp.list.iter().enumerate() {
            by_pair.entry((c.shape, c.obstacle)).or_default().push((
                pp.phase_value,
                k,
                i,
                c.distance,
            ));
        }
    }
    for entries in by_pair.values_mut() {
        entries.sort_by(|a, b| a.0.total_cmp(&b.0));
        let n = entries.len();
        let mut run = 0usize;
        for e in 0..n {
            let d = entries[e].3;
            let before = if e > 0 {
                entries[e - 1].3
            } else {
                f64::INFINITY
            };
            let after = if e + 1 < n {
                entries[e + 1].3
            } else {
                f64::INFINITY
            };
            let minimum = d <= before && d <= after;
            let short = d < target;
            let thinned = if short {
                run += 1;
                (run - 1) % VIOLATION_STRIDE == 0
            } else {
                run = 0;
                false
            };
            if minimum || thinned {
                keep[entries[e].1][entries[e].2] = true;
            }
        }
    }
    keep
}

/// Keep the `k` closest robot shapes per obstacle (order preserved).
fn closest_per_obstacle(mut list: Vec<Clearance>, k: usize) -> Vec<Clearance> {
    list.sort_by(|a, b| {
        a.obstacle
            .cmp(&b.obstacle)
            .then(a.distance.total_cmp(&b.distance))
    });
    let mut out: Vec<Clearance> = Vec::with_capacity(list.len());
    let mut run = 0;
    for c in list {
        run = match out.last() {
            Some(prev) if prev.obstacle == c.obstacle => run + 1,
            _ => 0,
        };
        if run < k {
            out.push(c);
        }
    }
    out
}

impl From<QpFailure> for Error {
    fn from(f: QpFailure) -> Error {
        f.into_error()
    }
}
