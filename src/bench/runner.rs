//! The parallel runner: every problem x every method on a rayon pool with
//! an indicatif progress bar. A problem that fails to parse or validate, a
//! method that errors or panics: each is recorded as an `error` row and the
//! run goes on.

use super::methods::{Case, Method, Outcome};
use super::problem_file::ProblemFile;
use crate::optim::{OptimizeRequest, Problem, FEASIBILITY_TOLERANCE};
use crate::robot::Robot;
use crate::{Error, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

/// Runner settings.
#[derive(Clone, Debug, Default)]
pub struct RunSettings {
    /// Worker threads (default: all cores).
    pub workers: Option<usize>,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// One (problem, method) row of the report.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct RunRecord {
    /// Problem name (file stem).
    pub problem: String,
    /// `meta.category` (`"unknown"` when the file did not parse).
    pub category: String,
    /// Method name.
    pub method: String,
    /// `expect.feasible` (`None`: unknown, counted in no success rate).
    pub expect_feasible: Option<bool>,
    /// The method's error, when it failed (parse, validation, solver, panic).
    pub error: Option<String>,
    /// The method returned a trajectory as feasible.
    pub found: bool,
    /// That trajectory passed the dense verification.
    pub verified_feasible: bool,
    /// Correct answer: a verified trajectory on a feasible problem, no
    /// trajectory on an infeasible one.
    pub success: bool,
    /// Mahalanobis distance of the returned weights to the prior.
    pub mahalanobis: Option<f64>,
    /// Minimum signed clearance of the returned trajectory (m).
    pub min_clearance_m: Option<f64>,
    /// `max(0, clearance_m - min clearance)` (m).
    pub clearance_violation_m: f64,
    /// Largest joint-limit excursion (rad).
    pub limit_violation_rad: f64,
    /// `max(0, max |dq/dt| / v_max - 1)`.
    pub velocity_excess: f64,
    /// TCP distance to the goal at the end (m).
    pub goal_error_m: Option<f64>,
    /// TCP distance at the end to the problem's `meta.reference_final_tcp`
    /// (model mode: the demonstrations' mean final TCP), when it has one (m).
    pub final_tcp_error_m: Option<f64>,
    /// `max(0, goal error - tolerance)` (m).
    pub goal_excess_m: f64,
    /// Wall-clock time of the method (ms).
    pub time_ms: f64,
    /// QPs, gradient steps or densely checked draws.
    pub iterations: usize,
    /// Why the method found nothing, when it says.
    pub reason: Option<String>,
}

impl RunRecord {
    /// Sum of the constraint excesses (clearance m + limit rad + velocity
    /// ratio + goal m): 0 for a feasible trajectory.
    pub fn total_violation(&self) -> f64 {
        self.clearance_violation_m
            + self.limit_violation_rad
            + self.velocity_excess
            + self.goal_excess_m
    }
}

/// Run every method on every problem; never aborts on a problem's failure.
pub fn run_benchmark(
    problems: &[(String, Result<ProblemFile>)],
    methods: &[Box<dyn Method>],
    robot: &Robot,
    settings: &RunSettings,
) -> Result<Vec<RunRecord>> {
    let pairs: Vec<(usize, usize)> = (0..problems.len())
        .flat_map(|p| (0..methods.len()).map(move |m| (p, m)))
        .collect();
    let bar = progress_bar(pairs.len(), settings.progress, "problem x method");
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(k) = settings.workers {
        builder = builder.num_threads(k);
    }
    let pool = builder
        .build()
        .map_err(|e| Error::invalid("--workers", format!("cannot start the thread pool: {e}")))?;
    let records = pool.install(|| {
        pairs
            .par_iter()
            .map(|&(p, m)| {
                let (name, problem) = &problems[p];
                let record = run_pair(name, problem, methods[m].as_ref(), robot);
                bar.inc(1);
                record
            })
            .collect::<Vec<_>>()
    });
    bar.finish_and_clear();
    Ok(records)
}

/// A progress bar over `len` items named `what` (hidden unless `visible`).
pub fn progress_bar(len: usize, visible: bool, what: &str) -> ProgressBar {
    if !visible {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len as u64);
    let template = format!("{{bar:40}} {{pos}}/{{len}} {what}  [{{elapsed}} < {{eta}}]");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar
}

/// One (problem, method) pair, errors and panics turned into a record.
pub fn run_pair(
    name: &str,
    problem: &Result<ProblemFile>,
    method: &dyn Method,
    robot: &Robot,
) -> RunRecord {
    let (category, expect) = match problem {
        Ok(p) => (p.meta.category.clone(), p.expect.feasible),
        Err(_) => ("unknown".to_string(), Some(true)),
    };
    let mut record = empty_record(name, &category, &method.name(), expect);
    let result = catch_unwind(AssertUnwindSafe(|| -> Result<Timed> {
        let p = problem
            .as_ref()
            .map_err(|e| Error::Numerical(e.to_string()))?;
        let request: OptimizeRequest = serde_json::from_value(p.request.clone())
            .map_err(|e| Error::invalid("request", e.to_string()))?;
        let validated = request.validate(robot)?;
        let case = Case {
            request: &request,
            problem: &validated,
            robot,
        };
        let start = Instant::now();
        let outcome = method.run(&case)?;
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let mahalanobis = validated.mahalanobis(&outcome.weights);
        let final_tcp_error_m = p
            .meta
            .reference_final_tcp
            .map(|r| final_tcp_error(&validated, robot, &outcome.weights, &r));
        Ok(Timed {
            outcome,
            ms,
            mahalanobis,
            final_tcp_error_m,
            request,
        })
    }));
    match result {
        Ok(Ok(timed)) => fill(&mut record, p_min(problem), &timed),
        Ok(Err(e)) => record.error = Some(e.to_string()),
        Err(_) => record.error = Some("the method panicked".to_string()),
    }
    record
}

fn p_min(problem: &Result<ProblemFile>) -> Option<f64> {
    problem.as_ref().ok().and_then(|p| p.expect.min_clearance_m)
}

fn empty_record(name: &str, category: &str, method: &str, expect: Option<bool>) -> RunRecord {
    RunRecord {
        problem: name.to_string(),
        category: category.to_string(),
        method: method.to_string(),
        expect_feasible: expect,
        error: None,
        found: false,
        verified_feasible: false,
        success: false,
        mahalanobis: None,
        min_clearance_m: None,
        clearance_violation_m: 0.0,
        limit_violation_rad: 0.0,
        velocity_excess: 0.0,
        goal_error_m: None,
        final_tcp_error_m: None,
        goal_excess_m: 0.0,
        time_ms: 0.0,
        iterations: 0,
        reason: None,
    }
}

/// A method's outcome with its wall-clock time and Mahalanobis cost.
struct Timed {
    outcome: Outcome,
    ms: f64,
    mahalanobis: f64,
    final_tcp_error_m: Option<f64>,
    request: OptimizeRequest,
}

/// Distance of the TCP at the end of `weights`' trajectory to `reference`.
pub fn final_tcp_error(
    problem: &Problem,
    robot: &Robot,
    weights: &[f64],
    reference: &[f64; 3],
) -> f64 {
    let psi = problem.basis().row_at(1.0);
    let nb = psi.len();
    let q_end: Vec<f64> = weights
        .chunks(nb)
        .map(|w| w.iter().zip(psi.iter()).map(|(a, b)| a * b).sum())
        .collect();
    let tcp = robot.tcp_pose(&q_end).translation.vector;
    (tcp - nalgebra::Vector3::from(*reference)).norm()
}

fn fill(r: &mut RunRecord, min_expected: Option<f64>, t: &Timed) {
    let (o, req) = (&t.outcome, &t.request);
    let rep = &o.report;
    let tol = FEASIBILITY_TOLERANCE;
    r.found = o.found;
    r.mahalanobis = Some(t.mahalanobis);
    r.min_clearance_m = rep.min_clearance_m;
    r.clearance_violation_m = rep
        .min_clearance_m
        .map_or(0.0, |d| (req.task.clearance_m - d).max(0.0));
    r.limit_violation_rad = rep.max_joint_limit_violation_rad.max(0.0);
    r.velocity_excess = (rep.max_velocity_ratio - 1.0).max(0.0);
    r.goal_error_m = rep.goal_error_m;
    r.final_tcp_error_m = t.final_tcp_error_m;
    r.goal_excess_m = match (&req.task.goal, rep.goal_error_m) {
        (Some(g), Some(e)) => (e - g.tolerance_m).max(0.0),
        _ => 0.0,
    };
    let clear_enough = match (min_expected, rep.min_clearance_m) {
        (Some(m), Some(d)) => d >= m - tol,
        _ => true,
    };
    r.verified_feasible =
        r.total_violation() <= tol && rep.equality_error_rad <= tol && clear_enough;
    r.success = match r.expect_feasible {
        Some(true) => o.found && r.verified_feasible,
        Some(false) => !o.found,
        None => false,
    };
    r.time_ms = t.ms;
    r.iterations = o.iterations;
    r.reason = o.reason.clone();
}
