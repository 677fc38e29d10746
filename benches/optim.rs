//! Optimiser benchmark: ≥ 100 generated typical problems (real-like prior,
//! 10-obstacle berry cluster near the path, 150 samples, 2 cm clearance).
//! Prints median / p99 solve time, iterations, QP sizes, status counts and
//! peak RSS, then runs criterion on a few representative problems.
//!
//! `cargo bench --bench optim` (set `DPMP_BENCH_PROBLEMS` to change the
//! number of problems, default 100; `DPMP_BENCH_RESTARTS` to override
//! `options.restarts`, e.g. 0 for the run from the prior mean alone;
//! `DPMP_BENCH_SWEEP_ONLY=1` skips the criterion part). The sweep runs
//! twice in one process, so the ratio holds on a noisy machine: with the
//! default inner solver (the dual active-set method) and with
//! `inner_solver: clarabel` (every QP by Clarabel); `DPMP_BENCH_INNER=
//! active_set` or `clarabel` runs one of them only.
//!
//! The problems are rest-to-rest with the Panda's acceleration and jerk
//! limits (the request defaults). `DPMP_BENCH_LIMITS=compare` first runs
//! them without those rows (`boundary: free`, a robot without acceleration
//! and jerk limits), in the same process, for the time ratio.

use criterion::{black_box, Criterion};
use dpmp::optim::example::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, Boundary, InnerSolver, OptimizeRequest, SolveControl, Status};
use dpmp::robot::Robot;
use std::time::Instant;

fn problems(robot: &Robot, n: usize, restarts: Option<usize>) -> Vec<OptimizeRequest> {
    let settings = ExampleSettings::default();
    (0..n as u64)
        .map(|seed| {
            let mut request = typical_request(robot, seed, &settings).expect("example request");
            if let Some(r) = restarts {
                request.options.restarts = r;
            }
            request
        })
        .collect()
}

fn env_number(name: &str) -> Option<usize> {
    let value = std::env::var(name).ok()?;
    match value.parse() {
        Ok(n) => Some(n),
        Err(_) => {
            eprintln!("error: {name}={value:?} is not a non-negative integer");
            std::process::exit(2);
        }
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// The Panda without acceleration and jerk limits, for the comparison.
fn panda_without_rate_limits(robot: &Robot) -> Robot {
    let mut yaml = String::from("joint_limits:\n");
    for name in robot.joint_names() {
        yaml += &format!("  {name}:\n    has_acceleration_limits: false\n");
    }
    robot.clone().with_limits_yaml(&yaml).expect("limits yaml")
}

fn sweep(robot: &Robot, requests: &[OptimizeRequest], inner: InnerSolver, boundary: Boundary) {
    let requests: Vec<OptimizeRequest> = requests
        .iter()
        .map(|r| {
            let mut r = r.clone();
            r.options.inner_solver = inner;
            r.boundary = boundary;
            r
        })
        .collect();
    let rate_limited = robot.limits().iter().any(|l| l.acceleration.is_some());
    let mut active_set_steps = Vec::new();
    let mut ms_per_qp = Vec::new();
    let mut solve_ms = Vec::new();
    let mut total_ms = Vec::new();
    let mut iterations = Vec::new();
    let mut rows = Vec::new();
    let mut solves = Vec::new();
    let mut ipm_per_qp = Vec::new();
    let mut split = [0.0f64; 3];
    let (mut optimal, mut infeasible, mut max_iter, mut mean_feasible) = (0, 0, 0, 0);
    for req in &requests {
        let t0 = Instant::now();
        let resp = optimize(req, robot).expect("optimize");
        total_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        let problem = req.validate(robot).expect("validate");
        if problem.is_feasible(&resp.prior_mean_report) {
            mean_feasible += 1;
        }
        let t1 = Instant::now();
        let sol = problem.solve(&SolveControl::default()).expect("solve");
        solve_ms.push(t1.elapsed().as_secs_f64() * 1e3);
        iterations.push(sol.stats.iterations as f64);
        rows.push(sol.stats.max_qp_rows as f64);
        solves.push(sol.stats.qp_solves as f64);
        if sol.stats.active_set_solves > 0 {
            active_set_steps
                .push(sol.stats.active_set_steps as f64 / sol.stats.active_set_solves as f64);
        }
        if sol.stats.qp_solves > sol.stats.active_set_solves {
            ipm_per_qp.push(
                sol.stats.ipm_iterations as f64
                    / (sol.stats.qp_solves - sol.stats.active_set_solves) as f64,
            );
        }
        if sol.stats.qp_solves > 0 {
            ms_per_qp.push(sol.stats.qp_ms / sol.stats.qp_solves as f64);
        }
        split[0] += sol.stats.qp_ms;
        split[1] += sol.stats.evaluation_ms;
        split[2] += sol.stats.verification_ms;
        match resp.status {
            Status::Optimal => optimal += 1,
            Status::Infeasible => infeasible += 1,
            Status::MaxIterations => max_iter += 1,
        }
    }
    for v in [
        &mut solve_ms,
        &mut total_ms,
        &mut iterations,
        &mut rows,
        &mut solves,
        &mut ipm_per_qp,
        &mut active_set_steps,
        &mut ms_per_qp,
    ] {
        v.sort_by(|a, b| a.total_cmp(b));
    }
    let n = requests.len();
    println!("optim sweep over {n} typical problems (10 obstacles, 150 samples, clearance 0.02 m), inner solver {inner:?}, boundary {boundary:?}, acceleration/jerk limits {rate_limited}");
    println!(
        "  status: optimal {optimal}, infeasible {infeasible}, max_iterations {max_iter}; prior mean already feasible: {mean_feasible}"
    );
    println!(
        "  Problem::solve   median {:.2} ms  p99 {:.2} ms  max {:.2} ms",
        percentile(&solve_ms, 0.5),
        percentile(&solve_ms, 0.99),
        solve_ms[n - 1]
    );
    println!(
        "  optimize (validate + diagnose + solve + prior report)  median {:.2} ms  p99 {:.2} ms",
        percentile(&total_ms, 0.5),
        percentile(&total_ms, 0.99)
    );
    println!(
        "  iterations median {} p99 {} max {}; largest QP rows median {} p99 {} max {} (Clarabel variables: the 56 weights less one per start equality, plus slacks)",
        percentile(&iterations, 0.5),
        percentile(&iterations, 0.99),
        iterations[n - 1],
        percentile(&rows, 0.5),
        percentile(&rows, 0.99),
        rows[n - 1]
    );
    if !ipm_per_qp.is_empty() {
        println!(
            "  QP solves per problem median {} p99 {}; Clarabel interior-point iterations per solve median {:.1}",
            percentile(&solves, 0.5),
            percentile(&solves, 0.99),
            percentile(&ipm_per_qp, 0.5)
        );
    }
    println!(
        "  QP linearisation + assembly + solve per QP: median {:.3} ms p99 {:.3} ms",
        percentile(&ms_per_qp, 0.5),
        percentile(&ms_per_qp, 0.99)
    );
    if !active_set_steps.is_empty() {
        println!(
            "  active-set multiplier steps per solve median {:.1} p99 {:.1}",
            percentile(&active_set_steps, 0.5),
            percentile(&active_set_steps, 0.99)
        );
    }
    let total: f64 = solve_ms.iter().sum();
    println!(
        "  time split: QP build+solve {:.0} %, iterate evaluation {:.0} %, dense verification {:.0} %",
        100.0 * split[0] / total,
        100.0 * split[1] / total,
        100.0 * split[2] / total
    );
    println!("  peak RSS (VmHWM) {:.1} MB", peak_rss_mb());
}

fn main() {
    let robot = Robot::panda().expect("panda");
    let n = env_number("DPMP_BENCH_PROBLEMS").unwrap_or(100);
    let requests = problems(&robot, n, env_number("DPMP_BENCH_RESTARTS"));
    let inners = match std::env::var("DPMP_BENCH_INNER").as_deref() {
        Ok("clarabel") => vec![InnerSolver::Clarabel],
        Ok("active_set") => vec![InnerSolver::ActiveSet],
        _ => vec![InnerSolver::ActiveSet, InnerSolver::Clarabel],
    };
    let compare = std::env::var("DPMP_BENCH_LIMITS").as_deref() == Ok("compare");
    for inner in inners {
        if compare {
            let plain = panda_without_rate_limits(&robot);
            sweep(&plain, &requests, inner, Boundary::Free);
        }
        sweep(&robot, &requests, inner, Boundary::Rest);
    }
    if std::env::var_os("DPMP_BENCH_SWEEP_ONLY").is_some() {
        return;
    }
    let mut c = Criterion::default().sample_size(20).configure_from_args();
    let solvable: Vec<_> = requests.iter().take(3).collect();
    let validated: Vec<_> = solvable
        .iter()
        .map(|r| r.validate(&robot).expect("validate"))
        .collect();
    c.bench_function("optim/solve_typical_3", |b| {
        b.iter(|| {
            for p in &validated {
                black_box(p.solve(&SolveControl::default()).expect("solve"));
            }
        })
    });
    c.final_summary();
}
