//! The SCP driver's state and its named steps.
//!
//! [`Scp`] holds everything that changes between iterations (the iterate,
//! trust radius, penalty, working-set hint, phase set, counters, and where
//! the run stands: a `Phase` — descending, converged, certifying,
//! certified — and a `Generation`, thinned or exact) and each decision of
//! the loop is one method returning a `Flow` (continue, or the answer):
//!
//! 1. [`Scp::finish_or_certify`] — a converged feasible iterate is
//!    *certified* first (the next QP is Clarabel's: see below), then
//!    verified densely; flagged phases join the optimisation set. Once a
//!    verification has flagged phases (the trajectory dipped between
//!    them), a converged iterate is verified first ([`Scp::screen`]) and
//!    certified only when clean, so a point that would be flagged costs no
//!    certifying QPs;
//! 2. [`Scp::out_of_budget`] — the caller's deadline / cancel flag and the
//!    iteration limit;
//! 3. [`Scp::generate_and_solve`] — linearise, build the working set,
//!    solve by constraint generation (the dual active-set method, or
//!    Clarabel when certifying);
//! 4. [`Scp::accept`] / [`Scp::shrink`] — the merit test and the trust
//!    radius;
//! 5. [`Scp::stall`] — a stall short of feasibility switches to exact
//!    generation, then raises the penalty, then gives up.
//!
//! **Certification.** Intermediate QPs are solved by the warm-startable
//! [dual active-set method](crate::optim::qp::dual_active_set); the weights returned as
//! `optimal` always come from a QP solved by Clarabel (the solver of
//! record) at the converged point: exact goal cone, exact constraint
//! generation, the trust ball reset to at least its initial radius. When
//! Clarabel's step is accepted, tiny by the usual rule and strictly inside
//! the ball, the point is a KKT point of the linearised problem (on a
//! convex problem: its optimum) and goes to dense verification; otherwise
//! the loop goes on (back to the active-set method if the step was not
//! tiny). A rejected step that Clarabel predicts to gain less than the
//! optimality tolerance, inside the ball, certifies the point where it
//! stands ([`Scp::stands`]). Clarabel's status and residuals go into the
//! report's `final_qp`.

mod verification;

use crate::optim::problem::phases::PhaseRows;
use crate::optim::problem::Problem;
use crate::optim::qp::{ClarabelInfo, QpFailure, QpSolution};
use crate::optim::report::FinalQp;
use crate::optim::scp::evaluate::GridEval;
use crate::optim::scp::line_search::{Correction, StepTrial};
use crate::optim::scp::subproblem::{ActiveRows, Linearisation};
use crate::optim::solution::{timed, Solution, SolveControl, SolveStats};
use crate::optim::stop_reason::{Interruption, StopReason};
use crate::optim::tolerances::{
    BALL_ACTIVE_FRACTION, MAX_PENALTY, MAX_TRUST_REGION, MIN_TRUST_REGION, OPTIMALITY_TOLERANCE,
};
use crate::optim::verify::Verification;
use crate::Result;
use nalgebra::DVector;
use std::borrow::Cow;
use std::time::Instant;

/// What one iteration's QP produced.
struct Step {
    sol: QpSolution,
    /// The model's value at the current iterate.
    model_here: f64,
}

/// Where the run stands between two iterations: what
/// [`Scp::finish_or_certify`] and [`Scp::stall`] decide on.
#[derive(Clone, Debug)]
enum Phase {
    /// The run starts at its centre, which is feasible: its own answer
    /// (0 QPs, cost 0) once dense verification passes.
    Centre,
    /// Steps towards the centre on the active-set method.
    Descend,
    /// The last active-set step was tiny, or the trust radius collapsed: a
    /// feasible iterate goes to certification, an infeasible one stalled.
    Converged,
    /// The next QP is Clarabel's certifying one.
    Certify,
    /// Clarabel certified the current iterate: dense verification next.
    Certified(FinalQp),
}

impl Phase {
    /// Whether the last step ended the search at the current iterate.
    fn converged(&self) -> bool {
        matches!(self, Phase::Centre | Phase::Converged | Phase::Certified(_))
    }

    /// The phase a new iteration starts in: a candidate that neither
    /// finished nor stalled is searched on (a certified iterate that is
    /// not feasible is certified again).
    fn next_iteration(self) -> Phase {
        match self {
            Phase::Certify | Phase::Certified(_) => Phase::Certify,
            Phase::Centre | Phase::Descend | Phase::Converged => Phase::Descend,
        }
    }
}

/// Which violated clearance rows join an iteration's QP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Generation {
    /// Rows near the target, for a bounded number of rounds.
    Thinned,
    /// Every violated row (after a stall, and when certifying).
    Exact,
}

/// What a step of the loop decided.
enum Flow {
    /// Go on to the next step.
    Continue,
    /// The run's answer.
    Done(Box<Solution>),
}

/// What [`Scp::advance`] returns.
pub(in crate::optim) enum Progress {
    /// The run took the iterations it was given and can go on.
    Paused,
    /// The run ended with this answer.
    Done(Box<Solution>),
}

/// The state of one SCP run (see the module docs).
pub(in crate::optim) struct Scp<'a> {
    problem: &'a Problem,
    centre: &'a DVector<f64>,
    ctl: &'a SolveControl,
    max_iterations: usize,
    started: Instant,
    /// The optimisation phases: the problem's grid, copied only when
    /// verification adds phases to it.
    rows: Cow<'a, PhaseRows>,
    stats: SolveStats,
    rho: f64,
    radius: f64,
    eval: GridEval,
    hint: ActiveRows,
    phase: Phase,
    generation: Generation,
    /// The trust ball's multiplier in the last active-set QP.
    proximal_weight: f64,
    /// Never accept a step from a feasible iterate to an infeasible one
    /// ([`Scp::keeping_feasibility`]).
    keep_feasible: bool,
    /// A dense verification has flagged phases in this run: later converged
    /// iterates are screened before Clarabel certifies them
    /// ([`Scp::screen`]).
    dipped: bool,
    /// The last screened iterate's weights and its clean verification,
    /// kept for the answer when certification leaves the point where it is.
    screened: Option<(DVector<f64>, Verification)>,
}

impl<'a> Scp<'a> {
    pub(in crate::optim) fn new(
        problem: &'a Problem,
        start: &DVector<f64>,
        centre: &'a DVector<f64>,
        max_iterations: usize,
        ctl: &'a SolveControl,
    ) -> Self {
        let started = Instant::now();
        let rows = Cow::Borrowed(&problem.grid);
        let mut stats = SolveStats::default();
        let eval = timed(&mut stats.evaluation_ms, || {
            problem.evaluate_grid(&rows, start.clone(), centre, ctl)
        });
        let phase = if start == centre && eval.feasible() {
            Phase::Centre
        } else {
            Phase::Descend
        };
        Scp {
            problem,
            centre,
            ctl,
            max_iterations,
            started,
            rows,
            stats,
            rho: problem.options.penalty,
            radius: problem.options.trust_region,
            eval,
            hint: ActiveRows::default(),
            // A feasible start elsewhere still has to move towards the centre.
            phase,
            generation: Generation::Thinned,
            proximal_weight: 0.0,
            keep_feasible: false,
            dipped: false,
            screened: None,
        }
    }

    /// This run never trades feasibility for cost: from a feasible iterate
    /// a step is accepted only onto a feasible one (the L1 merit at a small
    /// penalty would accept a step that gains more cost than it loses
    /// clearance). For a run from a feasible start that must stay near it
    /// (the pinned goal start of `optim::seeds`); it may crawl along
    /// the clearance, so give it iterations.
    pub(in crate::optim) fn keeping_feasibility(mut self) -> Self {
        self.keep_feasible = true;
        self
    }

    /// Iterate until a step returns the answer.
    pub(in crate::optim) fn run(mut self) -> Result<Solution> {
        loop {
            if let Progress::Done(done) = self.advance(usize::MAX) {
                return Ok(*done);
            }
        }
    }

    /// Iterate until a step returns the answer, or pause once the run has taken `iterations` QP iterations in all; a paused
    /// run goes on where it stopped at the next call. The pause falls
    /// between two iterations, after a converged iterate was verified, so
    /// that pausing never changes the run: the same iterations in the same
    /// order, however they are split between calls.
    pub(in crate::optim) fn advance(&mut self, iterations: usize) -> Progress {
        loop {
            if let Flow::Done(done) = self.finish_or_certify() {
                return Progress::Done(done);
            }
            if self.stats.iterations >= iterations {
                return Progress::Paused;
            }
            self.phase = std::mem::replace(&mut self.phase, Phase::Descend).next_iteration();
            if let Flow::Done(done) = self.out_of_budget() {
                return Progress::Done(done);
            }
            let step = match self.generate_and_solve() {
                Ok(step) => step,
                Err(done) => return Progress::Done(done),
            };
            self.stats.iterations += 1;
            self.judge(step);
            if let Flow::Done(done) = self.stall() {
                return Progress::Done(done);
            }
        }
    }

    /// The current iterate's evaluation on the optimisation phases (its
    /// true violation, whether it collides).
    pub(in crate::optim) fn iterate(&self) -> &GridEval {
        &self.eval
    }

    /// The counters of the work done so far.
    pub(in crate::optim) fn stats(&self) -> &SolveStats {
        &self.stats
    }

    /// Step 2: the caller's deadline / cancel flag and the iteration limit.
    fn out_of_budget(&mut self) -> Flow {
        if let Some(why) = self.ctl.stop_reason() {
            return self.stopped_early(why, None);
        }
        if self.stats.iterations >= self.max_iterations {
            let reason = format!(
                "no converged feasible solution within {} iterations ({})",
                self.max_iterations,
                self.problem.worst_constraint(&self.eval)
            );
            return self.answer(StopReason::IterationLimit, None, Some(reason), &[]);
        }
        Flow::Continue
    }

    /// Step 3: the QP at the iterate, by constraint generation. A failure
    /// is the run's answer.
    fn generate_and_solve(&mut self) -> std::result::Result<Step, Box<Solution>> {
        let mut stats = std::mem::take(&mut self.stats);
        let outcome = self.solve_subproblem(None, &mut stats);
        self.stats = stats;
        match outcome {
            Ok((sol, model_here, active)) => {
                self.hint = active;
                Ok(Step { sol, model_here })
            }
            Err(QpFailure::Infeasible) => {
                let reason = "joint position limits (minus the margin), velocity limits and the start / final configuration cannot all hold".to_string();
                Err(Box::new(self.solution(
                    StopReason::LimitsIncompatible,
                    None,
                    Some(reason),
                    &[],
                )))
            }
            Err(QpFailure::OutOfTime) => {
                let warnings = [format!("solver stopped early: {}", Interruption::Deadline)];
                Err(Box::new(self.solution(
                    Interruption::Deadline.stop_reason(),
                    None,
                    Some(warnings[0].clone()),
                    &warnings,
                )))
            }
            Err(QpFailure::Numerical(what)) => {
                let reason = format!("QP solver failed ({what}); best iterate returned");
                Err(Box::new(self.solution(
                    StopReason::QpNumericalFailure,
                    None,
                    Some(reason),
                    &[],
                )))
            }
        }
    }

    /// The QP at the iterate (see [`Problem::subproblem`]), timed into
    /// `stats`; `correction`: a rejected trial point whose short pairs join
    /// (the second-order correction).
    fn solve_subproblem(
        &self,
        correction: Option<&GridEval>,
        stats: &mut SolveStats,
    ) -> std::result::Result<(QpSolution, f64, ActiveRows), QpFailure> {
        let at = Linearisation {
            exact: self.generation == Generation::Exact || self.certifying(),
            certify: self.certifying()
                || self.problem.options.inner_solver == crate::optim::task::InnerSolver::Clarabel,
            rows: &self.rows,
            eval: &self.eval,
            centre: self.centre,
            rho: self.rho,
            trust: self.eval.linear_ok.then_some(self.radius),
            proximal_hint: self.proximal_weight,
            correction,
        };
        let mut qp_ms = 0.0;
        let outcome = timed(&mut qp_ms, || {
            self.problem.subproblem(&at, &self.hint, self.ctl, stats)
        });
        stats.qp_ms += qp_ms;
        outcome
    }

    /// Step 4: the merit test on the QP's step (with its halvings), then
    /// [`Scp::accept`] or [`Scp::shrink`].
    fn judge(&mut self, step: Step) {
        let merit_here = self.eval.merit(self.rho);
        let trial = StepTrial {
            problem: self.problem,
            eval: &self.eval,
            merit: merit_here,
            target: &step.sol.z,
            rows: &self.rows,
            centre: self.centre,
            rho: self.rho,
            predicted: step.model_here - step.sol.objective,
            ctl: self.ctl,
            keep_feasible: self.keep_feasible,
        };
        let full_step = (&step.sol.z - &self.eval.z).norm();
        if step.sol.clarabel.is_none() {
            self.proximal_weight = step.sol.proximal_weight;
        }
        let mut stats = std::mem::take(&mut self.stats);
        let correct = |rejected: &GridEval, stats: &mut SolveStats| {
            let solved = self.solve_subproblem(Some(rejected), stats);
            solved.ok().map(|(sol, _, _)| sol.z)
        };
        // The active-set steps from a point inside the limits are
        // corrected: a step along curved clearance constraints breaks them
        // by its square, and the L1 merit rejects it although it is a good
        // step (the Maratos effect). Clarabel's certifying step is judged
        // as it is.
        let correction: Option<&Correction> =
            (!self.certifying() && self.eval.linear_ok && step.sol.clarabel.is_none())
                .then_some(&correct);
        let (accepted, alpha) = trial.search(correction, &mut stats);
        self.stats = stats;
        tracing::debug!(
            iteration = self.stats.iterations,
            rows = step.sol.rows,
            merit = merit_here,
            predicted = trial.predicted,
            step = full_step,
            alpha,
            radius = self.radius,
            rho = self.rho,
            violation = self.eval.true_violation,
            certify = self.certifying(),
            accept = accepted.is_some(),
            "scp step"
        );
        match accepted {
            Some((next, predicted, actual)) => {
                let scale = 1.0 + merit_here.abs();
                self.accept(next, predicted, actual, alpha, full_step, scale, &step.sol);
            }
            None => match self.stands(trial.predicted, merit_here, full_step, &step.sol) {
                Some(final_qp) => {
                    self.stats.rejected_steps += 1;
                    self.phase = Phase::Certified(final_qp);
                }
                None => self.shrink(full_step, step.sol.clarabel.as_ref()),
            },
        }
    }

    /// Whether a rejected certifying step certifies the point where it
    /// stands: Clarabel's exact QP, its ball not holding it, predicts less
    /// than the optimality tolerance from any step, so the point is a
    /// minimiser of the linearised problem to that tolerance (the merit
    /// test rejected a step worth less than it). Without this, the ball
    /// shrank until it collapsed and certified the same point, "held by the
    /// ball", after two to four more Clarabel QPs.
    fn stands(
        &self,
        predicted: f64,
        merit_here: f64,
        full_step: f64,
        sol: &QpSolution,
    ) -> Option<FinalQp> {
        let info = sol.clarabel.as_ref()?;
        let free = full_step < BALL_ACTIVE_FRACTION * self.radius;
        let small = predicted <= OPTIMALITY_TOLERANCE * (1.0 + merit_here.abs());
        (self.certifying() && free && small).then(|| FinalQp::from(info, false))
    }

    /// An accepted step: move, adapt the radius, and decide convergence. A
    /// step that barely moves the merit, is predicted to gain less than
    /// the optimality tolerance, or gains less than it from one feasible
    /// iterate to another, has converged when feasible and stalled when
    /// not (an infeasible crawl goes on to [`Scp::stall`]). The last case
    /// is a crawl along curved clearance constraints: the model predicts
    /// clearing the clearance buffer's slack, the curvature keeps it, the
    /// ratio stays near 0.2 and the radius never grows (MotionBenchMaker's
    /// `iteration_limit` answers crawled for 60 iterations at 0.1 % of the
    /// cost each). Converged is not certified: Clarabel's exact QP must
    /// still find no step from the point.
    #[allow(clippy::too_many_arguments)]
    fn accept(
        &mut self,
        next: GridEval,
        predicted: f64,
        actual: f64,
        alpha: f64,
        full_step: f64,
        scale: f64,
        sol: &QpSolution,
    ) {
        let step = alpha * full_step;
        let tiny = step <= 1e-6 * (1.0 + next.z.amax())
            || actual.abs() <= 1e-6 * scale
            || predicted <= OPTIMALITY_TOLERANCE * scale
            || (next.feasible() && self.eval.feasible() && actual <= OPTIMALITY_TOLERANCE * scale);
        let radius_before = self.radius;
        let certifying = self.certifying();
        let ball_held = full_step >= BALL_ACTIVE_FRACTION * radius_before;
        // The active-set path holds the ball only approximately: a bound
        // ball shows as a positive proximal weight.
        let reached_ball = step >= 0.9 * self.radius || sol.proximal_weight > 0.0;
        if alpha < 1.0 {
            self.radius = (0.25 * self.radius).min(0.5 * full_step);
        } else if self.eval.linear_ok
            && ((actual >= 0.75 * predicted && reached_ball) || (certifying && tiny && ball_held))
        {
            self.radius = (self.radius * 2.0).min(MAX_TRUST_REGION);
        }
        self.eval = next;
        self.phase = if !certifying {
            if tiny {
                Phase::Converged
            } else {
                Phase::Descend
            }
        } else if !tiny {
            Phase::Descend
        } else if alpha < 1.0 {
            // Clarabel's step had to be cut back and the rest is tiny:
            // the point stands, with the ball (the cut) holding it.
            Phase::Certified(FinalQp::held_by_ball(sol.clarabel.as_ref()))
        } else {
            let free = !ball_held || radius_before >= MAX_TRUST_REGION;
            match (&sol.clarabel, free) {
                (Some(info), true) => Phase::Certified(FinalQp::from(info, false)),
                _ => Phase::Certify,
            }
        };
    }

    /// A rejected step: shrink the trust region; a collapsed radius counts
    /// as converged (a certifying QP that cannot move certifies the point
    /// with the ball held; `clarabel` is that QP's account).
    fn shrink(&mut self, full_step: f64, clarabel: Option<&ClarabelInfo>) {
        self.stats.rejected_steps += 1;
        self.radius = (0.25 * self.radius).min(0.5 * full_step);
        if self.radius < MIN_TRUST_REGION {
            self.radius = self.problem.options.trust_region;
            self.phase = if self.certifying() {
                Phase::Certified(FinalQp::held_by_ball(clarabel))
            } else {
                Phase::Converged
            };
        }
    }

    /// Whether the current iteration's QP is Clarabel's certifying one.
    fn certifying(&self) -> bool {
        matches!(self.phase, Phase::Certify)
    }

    /// Step 5: a stall short of feasibility changes the model (exact
    /// generation, then a larger penalty; each switch resets the trust
    /// region, which belongs to the old model); past [`MAX_PENALTY`] the
    /// run gives up. `infeasible` is kept for proofs (the diagnosis and a
    /// QP whose hard rows are incompatible): this is a local minimum.
    fn stall(&mut self) -> Flow {
        if !(self.phase.converged() && !self.eval.feasible() && self.eval.linear_ok) {
            return Flow::Continue;
        }
        self.phase = Phase::Descend;
        self.radius = self.radius.max(self.problem.options.trust_region);
        if self.generation == Generation::Thinned {
            self.generation = Generation::Exact;
            return Flow::Continue;
        }
        self.rho *= 10.0;
        if self.rho <= MAX_PENALTY {
            return Flow::Continue;
        }
        self.stats.final_penalty = self.rho;
        let reason = format!(
            "no feasible solution found: {} could not be reduced further at the largest penalty (a local minimum of the violation; the problem may be infeasible)",
            self.problem.worst_constraint(&self.eval)
        );
        self.answer(StopReason::LocalMinimum, None, Some(reason), &[])
    }

    /// Finish as `max_iterations` because the caller stopped the solver;
    /// the reason is also a warning.
    /// A dense verification interrupted by the stop is its report; without
    /// one, the answer's verification stops at once too, so a stopped run
    /// costs only the matrix products of the limit figures.
    fn stopped_early(&mut self, why: Interruption, verification: Option<Verification>) -> Flow {
        let warn = format!("solver stopped early: {why}");
        let warnings = [warn.clone()];
        self.answer(why.stop_reason(), verification, Some(warn), &warnings)
    }

    /// The run ends with its answer at the current iterate.
    fn answer(
        &mut self,
        stop: StopReason,
        verification: Option<Verification>,
        reason: Option<String>,
        extra_warnings: &[String],
    ) -> Flow {
        Flow::Done(Box::new(self.solution(
            stop,
            verification,
            reason,
            extra_warnings,
        )))
    }

    /// The run's answer at the current iterate: its dense verification
    /// (`verification`, or one made now), the work done and the warnings.
    fn solution(
        &mut self,
        stop: StopReason,
        verification: Option<Verification>,
        reason: Option<String>,
        extra_warnings: &[String],
    ) -> Solution {
        let p = self.problem;
        let stats = std::mem::take(&mut self.stats);
        let v = verification.unwrap_or_else(|| p.verifier().verify(&self.eval.w, self.ctl));
        let mut report = v.report;
        report.iterations = stats.iterations;
        report.warnings = p.warnings.clone();
        report.warnings.extend(extra_warnings.iter().cloned());
        if stats.added_phases > 0 {
            report.warnings.push(format!(
                "dense verification added {} phases to the optimisation set",
                stats.added_phases
            ));
        }
        report.solve_ms = self.started.elapsed().as_secs_f64() * 1e3;
        Solution {
            status: stop.status(),
            stop_reason: stop,
            weights: self.eval.w.as_slice().to_vec(),
            mahalanobis: p.whitening.mahalanobis(&self.eval.w),
            report,
            reason,
            stats,
        }
    }
}
