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
//! and jerk limits), in the same process and interleaved problem by problem,
//! for the time ratio; `DPMP_BENCH_LIMITS=factor` also runs the two halves
//! (rest-to-rest timing without the rate rows, the rate rows with free
//! ends), which separates what the timing and the rows each cost.
//! `DPMP_BENCH_PER_PROBLEM=1` prints every problem's iterations and time
//! per variant. `DPMP_BENCH_REPEAT=k` solves every problem k times
//! and keeps the fastest (the solve is deterministic; only the time varies).

use criterion::{black_box, Criterion};
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, Boundary, InnerSolver, OptimizeRequest, SolveControl, Status};
use dpmp::robot::Robot;
use std::time::Instant;

fn problems(robot: &Robot, n: usize, restarts: Option<usize>) -> Vec<OptimizeRequest> {
    let settings = ExampleSettings::default();
    (0..n as u64)
        .map(|seed| {
            let mut request = typical_request(robot, seed, &settings).expect("example request");
            if let Some(r) = restarts {
                request.task.options.restarts = r;
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

/// One problem's measurements.
struct Sample {
    solve_ms: f64,
    total_ms: f64,
    iterations: f64,
    rows: f64,
    solves: f64,
    ipm_per_qp: Option<f64>,
    active_set_steps: Option<f64>,
    ms_per_qp: Option<f64>,
    split: [f64; 3],
    status: Status,
    mean_feasible: bool,
}

/// Solves one request `repeat` times and keeps the fastest timing (the
/// solve is deterministic, so everything but the time is the same in
/// every repetition, and the minimum is the time least disturbed by the
/// machine).
fn measure(robot: &Robot, req: &OptimizeRequest, repeat: usize) -> Sample {
    let mut best: Option<Sample> = None;
    for _ in 0..repeat.max(1) {
        let sample = measure_once(robot, req);
        best = Some(match best {
            Some(b) if b.solve_ms <= sample.solve_ms => Sample {
                total_ms: b.total_ms.min(sample.total_ms),
                ..b
            },
            Some(b) => Sample {
                total_ms: b.total_ms.min(sample.total_ms),
                ..sample
            },
            None => sample,
        });
    }
    best.expect("at least one repetition")
}

fn measure_once(robot: &Robot, req: &OptimizeRequest) -> Sample {
    let t0 = Instant::now();
    let resp = optimize(req, robot).expect("optimize");
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;
    let problem = req.validate(robot).expect("validate");
    let mean_feasible = problem.is_feasible(&resp.prior_mean_report);
    let t1 = Instant::now();
    let sol = problem.solve(&SolveControl::default()).expect("solve");
    let solve_ms = t1.elapsed().as_secs_f64() * 1e3;
    let s = &sol.stats;
    let ipm_solves = s.qp_solves - s.active_set_solves;
    Sample {
        solve_ms,
        total_ms,
        iterations: s.iterations as f64,
        rows: s.max_qp_rows as f64,
        solves: s.qp_solves as f64,
        ipm_per_qp: (ipm_solves > 0).then(|| s.ipm_iterations as f64 / ipm_solves as f64),
        active_set_steps: (s.active_set_solves > 0)
            .then(|| s.active_set_steps as f64 / s.active_set_solves as f64),
        ms_per_qp: (s.qp_solves > 0).then(|| s.qp_ms / s.qp_solves as f64),
        split: [s.qp_ms, s.evaluation_ms, s.verification_ms],
        status: resp.status,
        mean_feasible,
    }
}

fn sorted(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(|a, b| a.total_cmp(b));
    v
}

/// One configuration of the sweep: a robot (with or without rate limits)
/// and the boundary condition, applied to every request.
struct Variant<'a> {
    robot: &'a Robot,
    requests: Vec<OptimizeRequest>,
    label: String,
}

impl<'a> Variant<'a> {
    fn new(
        robot: &'a Robot,
        requests: &[OptimizeRequest],
        inner: InnerSolver,
        boundary: Boundary,
    ) -> Self {
        let requests = requests
            .iter()
            .map(|r| {
                let mut r = r.clone();
                r.task.options.inner_solver = inner;
                r.task.boundary = boundary;
                r
            })
            .collect();
        let rate_limited = robot.limits().iter().any(|l| l.acceleration.is_some());
        Variant {
            robot,
            requests,
            label: format!("inner solver {inner:?}, boundary {boundary:?}, acceleration/jerk limits {rate_limited}"),
        }
    }
}

/// Runs every variant on every problem, interleaved problem by problem so
/// that a slow spell of the machine hits all variants alike.
fn sweep(variants: &[Variant], repeat: usize) -> Vec<Vec<Sample>> {
    let n = variants.first().map_or(0, |v| v.requests.len());
    let mut samples: Vec<Vec<Sample>> = variants.iter().map(|_| Vec::with_capacity(n)).collect();
    for i in 0..n {
        for (v, out) in variants.iter().zip(samples.iter_mut()) {
            out.push(measure(v.robot, &v.requests[i], repeat));
        }
    }
    samples
}

fn print_summary(label: &str, samples: &[Sample]) {
    let n = samples.len();
    let count = |s: Status| samples.iter().filter(|x| x.status == s).count();
    let mean_feasible = samples.iter().filter(|x| x.mean_feasible).count();
    let solve_ms = sorted(samples.iter().map(|x| x.solve_ms));
    let total_ms = sorted(samples.iter().map(|x| x.total_ms));
    let iterations = sorted(samples.iter().map(|x| x.iterations));
    let rows = sorted(samples.iter().map(|x| x.rows));
    let solves = sorted(samples.iter().map(|x| x.solves));
    let ipm_per_qp = sorted(samples.iter().filter_map(|x| x.ipm_per_qp));
    let active_set_steps = sorted(samples.iter().filter_map(|x| x.active_set_steps));
    let ms_per_qp = sorted(samples.iter().filter_map(|x| x.ms_per_qp));
    println!("optim sweep over {n} typical problems (10 obstacles, 150 samples, clearance 0.02 m), {label}");
    println!(
        "  status: optimal {}, infeasible {}, max_iterations {}; prior mean already feasible: {mean_feasible}",
        count(Status::Optimal),
        count(Status::Infeasible),
        count(Status::MaxIterations)
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
    if !ms_per_qp.is_empty() {
        println!(
            "  QP linearisation + assembly + solve per QP: median {:.3} ms p99 {:.3} ms",
            percentile(&ms_per_qp, 0.5),
            percentile(&ms_per_qp, 0.99)
        );
    }
    if !active_set_steps.is_empty() {
        println!(
            "  active-set multiplier steps per solve median {:.1} p99 {:.1}",
            percentile(&active_set_steps, 0.5),
            percentile(&active_set_steps, 0.99)
        );
    }
    let split = samples.iter().fold([0.0; 3], |acc, x| {
        [
            acc[0] + x.split[0],
            acc[1] + x.split[1],
            acc[2] + x.split[2],
        ]
    });
    let total: f64 = solve_ms.iter().sum();
    println!(
        "  time split: QP build+solve {:.0} %, iterate evaluation {:.0} %, dense verification {:.0} %",
        100.0 * split[0] / total,
        100.0 * split[1] / total,
        100.0 * split[2] / total
    );
}

/// Iterations and solve time of every problem, one column per variant.
fn print_per_problem(samples: &[Vec<Sample>]) {
    let n = samples.first().map_or(0, |s| s.len());
    for i in 0..n {
        let cells: Vec<String> = samples
            .iter()
            .map(|s| format!("{:>4} it {:>8.1} ms", s[i].iterations, s[i].solve_ms))
            .collect();
        println!("  problem {i:>3}: {}", cells.join(" | "));
    }
}

/// The time ratio of the last variant to the first, at the median and
/// the p99 of each one's solve times.
fn print_ratio(base: &[Sample], new: &[Sample]) {
    let b = sorted(base.iter().map(|x| x.solve_ms));
    let n = sorted(new.iter().map(|x| x.solve_ms));
    let per_problem = sorted(base.iter().zip(new).map(|(b, n)| n.solve_ms / b.solve_ms));
    println!(
        "  time ratio (with the rows / without): median {:.2}x, p99 {:.2}x; per-problem ratio median {:.2}x p90 {:.2}x",
        percentile(&n, 0.5) / percentile(&b, 0.5),
        percentile(&n, 0.99) / percentile(&b, 0.99),
        percentile(&per_problem, 0.5),
        percentile(&per_problem, 0.9)
    );
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
    let limits = std::env::var("DPMP_BENCH_LIMITS").unwrap_or_default();
    let repeat = env_number("DPMP_BENCH_REPEAT").unwrap_or(1);
    let plain = panda_without_rate_limits(&robot);
    for inner in inners {
        let mut variants = Vec::new();
        if limits == "compare" || limits == "factor" {
            variants.push(Variant::new(&plain, &requests, inner, Boundary::Free));
        }
        if limits == "factor" {
            variants.push(Variant::new(&plain, &requests, inner, Boundary::Rest));
            variants.push(Variant::new(&robot, &requests, inner, Boundary::Free));
        }
        variants.push(Variant::new(&robot, &requests, inner, Boundary::Rest));
        let samples = sweep(&variants, repeat);
        for (v, s) in variants.iter().zip(&samples) {
            print_summary(&v.label, s);
        }
        if std::env::var_os("DPMP_BENCH_PER_PROBLEM").is_some() {
            print_per_problem(&samples);
        }
        if let (Some(base), Some(new), true) = (samples.first(), samples.last(), samples.len() > 1)
        {
            print_ratio(base, new);
        }
    }
    println!("  peak RSS (VmHWM) {:.1} MB", peak_rss_mb());
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
