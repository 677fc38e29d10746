//! One SCP subproblem: the clearance pairs and the goal linearised at the
//! iterate, assembled into a [`Qp`] over a [working set](crate::optim::scp::working_set)
//! of rows and solved by constraint generation.

use crate::optim::problem::linear::{RowKind, RowRef};
use crate::optim::problem::phases::PhaseRows;
use crate::optim::problem::Problem;
use crate::optim::qp::dual_active_set::WarmStart;
use crate::optim::qp::{Inequality, Qp, QpFailure, QpSettings, QpSolution};
use crate::optim::scp::evaluate::GridEval;
use crate::optim::scp::working_set::{thin_in_time, Candidate};
use crate::optim::solution::{timed, SolveControl, SolveStats};
use crate::optim::tolerances::{
    ACTIVE_DUAL_FRACTION, CERTIFY_TIGHTENING, CLEARANCE_BAND_M, CLEARANCE_BUFFER_M,
    GENERATION_TOLERANCE,
};
use nalgebra::DVector;
use std::collections::HashSet;

/// Generation rounds of clearance rows per QP while the iterate is being
/// improved; limit rows are always generated to the end. One round (the
/// working set as it stands) keeps QPs small in the early iterations, when
/// hundreds of clearance rows are violated; the merit test guards the step,
/// and a stall switches to exact generation (see [`Problem::solve`]).
const WORKING_SET_ROUNDS: usize = 1;

impl Problem {
    /// Build and solve the QP at `eval` by constraint generation over the
    /// [`working_set`](crate::optim::scp::working_set); returns the solution (optimal
    /// for the full linearised QP, or for the working set's model after
    /// [`WORKING_SET_ROUNDS`] unless `at.exact`), the model's value at the
    /// current iterate, and the rows active at the solution.
    pub(in crate::optim) fn subproblem(
        &self,
        at: &Linearisation,
        hint: &ActiveRows,
        ctl: &SolveControl,
        stats: &mut SolveStats,
    ) -> std::result::Result<(QpSolution, f64, ActiveRows), QpFailure> {
        let target = self.clearance_m + CLEARANCE_BUFFER_M;
        let mut clearance = self.clearance_rows(at.rows, at.eval, target, at.rho);
        let mut model_slack: f64 = clearance.iter().map(|c| c.shortfall).sum();
        let corrections = self.correction_rows(at, target, &mut clearance);
        let mut work = WorkingQp::new(self.base_qp(at), &clearance, at.rows);
        work.add_clearance(&corrections);
        for (c, e) in self.end_constraints.iter().zip(&at.eval.ends) {
            let jacobian = self.ends.position_jacobian(c.phase());
            let rows = c.linearise(&self.robot, &jacobian, e, &at.eval.z, at.rho);
            work.qp.cones.extend(rows.cones);
            for row in rows.inequalities {
                work.qp.inequalities.push(row);
                work.ids.push(RowId::Other);
            }
            model_slack += e.buffered_excess;
        }
        let model_here = at.eval.cost + at.rho * model_slack;
        self.first_working_set(&mut work, at, hint, target);
        let mut round = 0;
        let mut warm = work.carried_states(hint);
        let mut mu = at.proximal_hint;
        loop {
            round += 1;
            let settings = QpSettings {
                tolerance: self.options.qp_tolerance,
                time_limit: ctl.seconds_left(),
                ..Default::default()
            };
            let sol = if at.certify {
                timed(&mut stats.clarabel_ms, || {
                    certifying_solve(&work.qp, &settings)
                })?
            } else {
                // Infeasibility is a proof: Clarabel (the solver of record)
                // confirms what the active-set method reports.
                match work.qp.solve_active_set(&warm, mu, ctl.deadline) {
                    Err(QpFailure::Infeasible) => timed(&mut stats.clarabel_ms, || {
                        certifying_solve(&work.qp, &settings)
                    })?,
                    other => other?,
                }
            };
            stats.count(&sol);
            warm = sol.row_states.clone().unwrap_or_default();
            mu = sol.proximal_weight;
            let w = self.whitening.weights(&sol.z);
            let linear_missing: Vec<RowRef> = self
                .linear
                .violated(at.rows, &w, GENERATION_TOLERANCE)
                .into_iter()
                .filter(|r| !work.linear_in.contains(r))
                .collect();
            let violated = work.violated_clearance(&sol.z);
            if linear_missing.is_empty() && violated.is_empty() {
                let active = work.active_rows(&sol);
                return Ok((sol, model_here, active));
            }
            if linear_missing.is_empty() && !at.exact && round >= WORKING_SET_ROUNDS {
                // The model is the working set's: rows left out do not count.
                let active = work.active_rows(&sol);
                return Ok((sol, model_here - at.rho * work.left_out_shortfall(), active));
            }
            // Every row the solution breaks joins, unthinned: thinning
            // here only bought more generation rounds, each a re-solve
            // (docs/experiments.md).
            for r in linear_missing {
                self.add_linear_row(&mut work, at.rows, r);
            }
            let broken: Vec<usize> = violated.iter().map(|&(i, _)| i).collect();
            work.add_clearance(&broken);
        }
    }

    /// The second-order correction's rows (see [`Linearisation::correction`]):
    /// every pair of the rejected trial point short of `target`, linearised
    /// there, appended to `clearance`; returns their indices. They add
    /// nothing to the model's value at the iterate (the step is judged
    /// against the prediction of the QP it corrects).
    fn correction_rows(
        &self,
        at: &Linearisation,
        target: f64,
        clearance: &mut Vec<ClearanceRow>,
    ) -> Vec<usize> {
        let Some(trial) = at.correction else {
            return Vec::new();
        };
        let short: Vec<ClearanceRow> = self
            .clearance_rows(at.rows, trial, target, at.rho)
            .into_iter()
            .filter(|c| c.shortfall > 0.0)
            .collect();
        let candidates: Vec<Candidate<(usize, usize)>> = short
            .iter()
            .map(|c| Candidate {
                key: c.key,
                phase: c.phase,
                score: c.shortfall,
                in_band: true,
            })
            .collect();
        let start = clearance.len();
        let mut short: Vec<Option<ClearanceRow>> = short.into_iter().map(Some).collect();
        for k in thin_in_time(&candidates) {
            if let Some(c) = short[k].take() {
                clearance.push(ClearanceRow {
                    shortfall: 0.0,
                    ..c
                });
            }
        }
        (start..clearance.len()).collect()
    }

    /// The QP's cost centre, equalities, opt-in weight bounds and trust
    /// region: everything but the limit, clearance and goal rows.
    fn base_qp(&self, at: &Linearisation) -> Qp {
        let mean = &self.prior.mean;
        let mut qp = Qp::new(self.whitening.dim());
        qp.center = at.centre.clone();
        qp.equalities = self.linear.equalities(&self.ends, mean);
        qp.inequalities.extend(self.linear.weight_bounds(
            self.whitening.factor(),
            mean,
            self.prior.n_basis,
        ));
        if let Some(r) = at.trust {
            qp.trust = Some((at.eval.z.clone(), r));
        }
        qp
    }

    /// The first working set: the rows active in the previous QP, thinned
    /// limit rows a step can reach, and thinned clearance rows within
    /// [`CLEARANCE_BAND_M`] of the target.
    fn first_working_set(
        &self,
        work: &mut WorkingQp,
        at: &Linearisation,
        hint: &ActiveRows,
        target: f64,
    ) {
        for &r in &hint.linear {
            self.add_linear_row(work, at.rows, r);
        }
        let carried: Vec<usize> = (0..work.clearance.len())
            .filter(|&i| hint.clearance.contains(&work.clearance[i].id()))
            .collect();
        work.add_clearance(&carried);
        let screened = self.linear.screen_banded(at.rows, &at.eval.w, at.trust);
        self.add_linear_rows(work, at.rows, &at.eval.w, screened);
        let near = thin_in_time(
            &work
                .clearance
                .iter()
                .map(|c| Candidate {
                    key: c.key,
                    phase: c.phase,
                    score: -c.distance,
                    in_band: c.distance < target + at.rows.margin(c.phase_index) + CLEARANCE_BAND_M,
                })
                .collect::<Vec<_>>(),
        );
        work.add_clearance(&near);
    }

    /// Every clearance pair of `eval` linearised at its iterate:
    /// `d + ∇d·(z - z_k) >= target + margin` (the phase's extra clearance,
    /// [`PhaseRows::margin`]), with an L1-penalised slack. Each row
    /// is kept in joint space (`∇_q d` at its phase); its whitened form is
    /// built only when it joins the QP ([`ClearanceRow::inequality`]).
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
                let qz = rows.linear_position(pp.phase, &eval.z);
                let target = target + rows.margin(pp.phase);
                pp.list.iter().map(move |c| {
                    let gradient = self
                        .scene
                        .clearance_gradient(&self.robot, &pp.q, &pp.frames, c);
                    ClearanceRow {
                        phase_index: pp.phase,
                        key: (c.shape, c.obstacle),
                        phase: pp.phase_value,
                        distance: c.distance,
                        shortfall: (target - c.distance).max(0.0),
                        b: c.distance - gradient.dot(&qz) - target,
                        gradient,
                        penalty: rho,
                    }
                })
            })
            .collect()
    }

    /// Add `candidates` (thinned in time, scored by their excess at `w`)
    /// to the QP's hard rows.
    fn add_linear_rows(
        &self,
        work: &mut WorkingQp,
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
            self.add_linear_row(work, rows, candidates[k]);
        }
    }

    /// Add limit row `r` to the QP unless it is already there.
    fn add_linear_row(&self, work: &mut WorkingQp, rows: &PhaseRows, r: RowRef) {
        if work.linear_in.insert(r) {
            let row = self.linear.inequality(rows, &self.prior.mean, r);
            work.qp.inequalities.push(row);
            work.ids.push(RowId::Linear(r));
        }
    }
}

/// A linearised clearance row of one (robot shape, obstacle) pair at one
/// optimisation phase, `-∇_q d · J_p z <= b` (with an L1-penalised slack),
/// `J_p` the phase's joint positions' Jacobian in the whitened weights.
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
    /// `∂d/∂q` at the iterate (one entry per joint).
    gradient: DVector<f64>,
    /// `d - ∇_q d · J_p z_k - target`.
    b: f64,
    penalty: f64,
}

impl ClearanceRow {
    /// (phase index, robot shape, obstacle): the row's identity across
    /// iterations.
    fn id(&self) -> (usize, usize, usize) {
        (self.phase_index, self.key.0, self.key.1)
    }

    /// How far `z` breaks the linearised row without slack (> 0: violated),
    /// given `J_p z` at the row's phase.
    fn violation(&self, qz: &DVector<f64>) -> f64 {
        -self.gradient.dot(qz) - self.b
    }

    /// The row over the whitened weights.
    fn inequality(&self, rows: &PhaseRows) -> Inequality {
        Inequality {
            a: -rows.position_gradient(self.phase_index, &self.gradient),
            b: self.b,
            penalty: Some(self.penalty),
        }
    }
}

/// A QP under construction and which candidate rows it holds.
struct WorkingQp<'c> {
    qp: Qp,
    /// What each of `qp.inequalities` is.
    ids: Vec<RowId>,
    /// Limit rows in the QP.
    linear_in: HashSet<RowRef>,
    /// Every clearance row of the linearisation (the candidates).
    clearance: &'c [ClearanceRow],
    /// The optimisation phases the clearance rows are taken at.
    rows: &'c PhaseRows,
    /// Which of `clearance` are in the QP.
    clearance_in: Vec<bool>,
}

impl<'c> WorkingQp<'c> {
    /// `qp`'s own inequalities count as [`RowId::Other`].
    fn new(qp: Qp, clearance: &'c [ClearanceRow], rows: &'c PhaseRows) -> Self {
        WorkingQp {
            ids: vec![RowId::Other; qp.inequalities.len()],
            qp,
            linear_in: HashSet::new(),
            clearance,
            rows,
            clearance_in: vec![false; clearance.len()],
        }
    }

    /// Add the clearance rows `chosen` (indices into the candidates).
    fn add_clearance(&mut self, chosen: &[usize]) {
        for &i in chosen {
            if !self.clearance_in[i] {
                self.clearance_in[i] = true;
                self.qp
                    .inequalities
                    .push(self.clearance[i].inequality(self.rows));
                self.ids.push(RowId::Clearance(i));
            }
        }
    }

    /// (index, violation) of the candidate clearance rows outside the QP
    /// that `z` breaks.
    fn violated_clearance(&self, z: &DVector<f64>) -> Vec<(usize, f64)> {
        let mut qz: Vec<Option<DVector<f64>>> = vec![None; self.rows.len()];
        (0..self.clearance.len())
            .filter(|&i| !self.clearance_in[i])
            .map(|i| {
                let row = &self.clearance[i];
                let q = qz[row.phase_index]
                    .get_or_insert_with(|| self.rows.linear_position(row.phase_index, z));
                (i, row.violation(q))
            })
            .filter(|&(_, v)| v > GENERATION_TOLERANCE)
            .collect()
    }

    /// Slack at the iterate of the candidate clearance rows outside the QP.
    fn left_out_shortfall(&self) -> f64 {
        (0..self.clearance.len())
            .filter(|&i| !self.clearance_in[i])
            .map(|i| self.clearance[i].shortfall)
            .sum()
    }

    /// The rows active at `sol` (positive multiplier).
    fn active_rows(&self, sol: &QpSolution) -> ActiveRows {
        let largest = sol
            .inequality_duals
            .iter()
            .fold(0.0f64, |m, &d| m.max(d.abs()));
        let threshold = ACTIVE_DUAL_FRACTION * largest.max(1e-12);
        let mut out = ActiveRows::default();
        for (k, id) in self.ids.iter().enumerate() {
            let active = sol.inequality_duals[k] > threshold;
            match (*id, active) {
                (RowId::Linear(r), true) => out.linear.push(r),
                (RowId::Clearance(i), true) => {
                    out.clearance.insert(self.clearance[i].id());
                }
                _ => {}
            }
        }
        if let Some(states) = &sol.row_states {
            for &k in &states.saturated {
                if let RowId::Clearance(i) = self.ids[k] {
                    out.saturated.insert(self.clearance[i].id());
                }
            }
        }
        out
    }

    /// The previous QP's row states carried to this one by row identity:
    /// its saturated clearance rows start saturated, its other active rows
    /// are made feasible first.
    fn carried_states(&self, hint: &ActiveRows) -> WarmStart {
        let mut warm = WarmStart::default();
        for (k, id) in self.ids.iter().enumerate() {
            match *id {
                RowId::Clearance(i) if hint.saturated.contains(&self.clearance[i].id()) => {
                    warm.saturated.push(k)
                }
                RowId::Clearance(i) if hint.clearance.contains(&self.clearance[i].id()) => {
                    warm.active.push(k)
                }
                RowId::Linear(r) if hint.linear.contains(&r) => warm.active.push(k),
                _ => {}
            }
        }
        warm
    }
}

fn certifying_solve(qp: &Qp, settings: &QpSettings) -> Result<QpSolution, QpFailure> {
    let tight = QpSettings {
        tolerance: (settings.tolerance * CERTIFY_TIGHTENING).max(1e-12),
        ..settings.clone()
    };
    match qp.solve(&tight) {
        Err(QpFailure::Numerical(_)) => qp.solve(settings),
        other => other,
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
pub(in crate::optim) struct ActiveRows {
    linear: Vec<RowRef>,
    /// (phase index, robot shape, obstacle).
    clearance: HashSet<(usize, usize, usize)>,
    /// Clearance rows whose multiplier was at its cap (the active-set
    /// path's saturated rows): the next QP starts them saturated.
    saturated: HashSet<(usize, usize, usize)>,
}

/// Where a subproblem is linearised.
#[derive(Clone, Copy)]
pub(in crate::optim) struct Linearisation<'a> {
    /// Generate clearance rows until none is violated (else
    /// [`WORKING_SET_ROUNDS`] rounds).
    pub(in crate::optim) exact: bool,
    /// Solve with Clarabel (the final, certifying QP) instead of the dual
    /// active-set method.
    pub(in crate::optim) certify: bool,
    pub(in crate::optim) rows: &'a PhaseRows,
    pub(in crate::optim) eval: &'a GridEval,
    pub(in crate::optim) centre: &'a DVector<f64>,
    pub(in crate::optim) rho: f64,
    pub(in crate::optim) trust: Option<f64>,
    /// The trust ball's multiplier of the previous active-set QP: where
    /// this one's search starts.
    pub(in crate::optim) proximal_hint: f64,
    /// A second-order correction: the trial point of this linearisation's
    /// rejected step. Its pairs short of the target join the QP linearised
    /// where they were measured, so the corrected step bends around the
    /// curvature the first step's rows could not see (Maratos effect).
    pub(in crate::optim) correction: Option<&'a GridEval>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{typical_request, ExampleSettings};

    /// The QP of every candidate row, built without the working set.
    fn full_qp(p: &Problem, at: &Linearisation) -> Qp {
        let target = p.clearance_m + CLEARANCE_BUFFER_M;
        let mut qp = Qp::new(p.whitening.dim());
        qp.center = at.centre.clone();
        qp.equalities = p.linear.equalities(&p.ends, &p.prior.mean);
        qp.inequalities = p
            .linear
            .all_rows(at.rows)
            .map(|r| p.linear.inequality(at.rows, &p.prior.mean, r))
            .collect();
        qp.inequalities.extend(
            p.clearance_rows(at.rows, at.eval, target, at.rho)
                .into_iter()
                .map(|c| c.inequality(at.rows)),
        );
        for (c, e) in p.end_constraints.iter().zip(&at.eval.ends) {
            let jacobian = p.ends.position_jacobian(c.phase());
            let rows = c.linearise(&p.robot, &jacobian, e, &at.eval.z, at.rho);
            qp.cones.extend(rows.cones);
            qp.inequalities.extend(rows.inequalities);
        }
        qp.trust = at.trust.map(|r| (at.eval.z.clone(), r));
        qp
    }

    #[test]
    fn a_phase_margin_moves_its_rows_and_the_merit_by_exactly_the_margin() {
        let robot = crate::robot::Robot::panda().unwrap();
        let p = typical_request(&robot, 4, &ExampleSettings::default())
            .unwrap()
            .validate(&robot)
            .unwrap();
        let centre = DVector::zeros(p.whitening.dim());
        let z0 = DVector::from_fn(p.whitening.dim(), |i, _| 0.05 * ((i % 5) as f64 - 2.0));
        let ctl = SolveControl::default();
        let plain = p.evaluate_grid(&p.grid, z0.clone(), &centre, &ctl);
        // The phase with the closest pair, so that the margin binds there.
        let closest = (0..plain.pairs.len())
            .min_by(|&a, &b| {
                let d = |k: usize| {
                    plain.pairs[k]
                        .list
                        .iter()
                        .map(|c| c.distance)
                        .fold(f64::INFINITY, f64::min)
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        let phase = plain.pairs[closest].phase;
        let margin = 0.005;
        let mut rows = p.grid.clone();
        assert!(rows.raise_margin(phase, margin, 0.005));
        let held = p.evaluate_grid(&rows, z0, &centre, &ctl);
        let target = p.clearance_m + CLEARANCE_BUFFER_M;
        // The merit counts the phase's pairs against the raised target,
        // the true violation against the request's clearance as before.
        let extra: f64 = plain.pairs[closest]
            .list
            .iter()
            .map(|c| (target + margin - c.distance).max(0.0) - (target - c.distance).max(0.0))
            .sum();
        assert!(extra > 0.0, "the margin must bind somewhere");
        let gained = held.buffered_violation - plain.buffered_violation;
        assert!((gained - extra).abs() < 1e-12, "{gained} vs {extra}");
        assert_eq!(held.true_violation, plain.true_violation);
        // Each row at the iterate is short by its target less its distance:
        // the margin at that phase, the plain target elsewhere.
        let plain_rows = p.clearance_rows(&p.grid, &plain, target, 1.0);
        let held_rows = p.clearance_rows(&rows, &held, target, 1.0);
        assert_eq!(plain_rows.len(), held_rows.len());
        for (a, b) in plain_rows.iter().zip(&held_rows) {
            let qz = rows.linear_position(b.phase_index, &held.z);
            let expected = if b.phase_index == phase { margin } else { 0.0 };
            assert!((b.violation(&qz) - a.violation(&qz) - expected).abs() < 1e-12);
            let at_iterate = b.violation(&qz);
            let own_target = target + rows.margin(b.phase_index);
            assert!((at_iterate - (own_target - b.distance)).abs() < 1e-12);
        }
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
            let eval = p.evaluate_grid(&p.grid, z0, &centre, &SolveControl::default());
            assert!(!eval.pairs.is_empty(), "seed {seed}: no clearance pair");
            let at = Linearisation {
                exact: true,
                certify: true,
                rows: &p.grid,
                eval: &eval,
                centre: &centre,
                rho: 1e3,
                trust: Some(2.0),
                proximal_hint: 0.0,
                correction: None,
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
