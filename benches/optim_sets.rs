//! The optimiser's three benchmark sets with the default options, in one
//! run: the typical 100 (`fixtures::typical_request`, every one labelled
//! feasible in `problems/typical/labels.json`), the hard set
//! (`problems/hard/`, `dpmp bench make-problems --set hard`: intruders
//! beside the demonstrated path, labelled by a long search) and the
//! real-prior hard set (`problems/hard-real/`, `--set hard-real`: the same
//! on the paper's 25 real annotation priors, four families).
//!
//! `cargo bench --bench optim_sets` prints per set: labelled-feasible
//! solved, `optimal` answers that fail the dense verification of the
//! request (false `optimal`: must be 0), `Problem::solve` median / p99 /
//! max, SCP iterations, restarts run, the time split (QP, iterate
//! evaluation, dense verification), and what certifying each answer alone
//! costs (a dense verification of the answer, timed here, plus one of the
//! solve's certifying Clarabel QPs): the floor under any search; with a
//! request's own work (validation, the prior mean's report) that floor
//! bounds `/v1/optimize`'s throughput (run with `RAYON_NUM_THREADS=1` for
//! the CPU time a loaded service spends).
//! `DPMP_BENCH_SET=typical|hard|real` runs one set; `DPMP_BENCH_LIMIT=N` the
//! first N problems of each; `DPMP_BENCH_PER_PROBLEM=FILE` writes one CSV
//! row per problem (set, name, status, solved, ms, iterations, restarts)
//! for the time-vs-success plot (`scripts/plot_sets.py FILE OUT.svg`).

use dpmp::bench::{load_dir, ProblemFile};
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{OptimizeRequest, SolveControl, Status};
use dpmp::robot::Robot;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// One problem of a set: the request and whether it is labelled feasible.
struct Case {
    name: String,
    request: OptimizeRequest,
    feasible: bool,
}

/// One problem's measurement.
struct Row {
    name: String,
    status: Status,
    solved: bool,
    false_optimal: bool,
    ms: f64,
    iterations: usize,
    restarts: usize,
    split: [f64; 3],
    /// What certifying this answer alone costs: one dense verification of
    /// it plus one of the solve's certifying Clarabel QPs (ms).
    floor_ms: f64,
    /// Validation plus the prior mean's report (ms): a request's work
    /// besides the solve.
    request_ms: f64,
}

/// The repository root (the problem files live there).
fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn typical_cases(robot: &Robot, limit: usize) -> Vec<Case> {
    let path = repo().join("problems/typical/labels.json");
    let labels = dpmp::bench::typical_labels::TypicalLabels::load(&path).expect("typical labels");
    let settings = ExampleSettings::default();
    labels
        .labels
        .iter()
        .take(limit)
        .map(|l| Case {
            name: format!("typical-{:03}", l.seed),
            request: typical_request(robot, l.seed, &settings).expect("typical request"),
            feasible: l.feasible == Some(true),
        })
        .collect()
}

/// The labelled problem files of `problems/<dir>`.
fn file_cases(dir: &str, limit: usize) -> Vec<Case> {
    load_dir(&repo().join("problems").join(dir))
        .expect(dir)
        .into_iter()
        .take(limit)
        .map(|(name, file)| {
            let file: ProblemFile = file.expect("problem file");
            Case {
                name,
                request: serde_json::from_value(file.request).expect("problem request"),
                feasible: file.expect.feasible == Some(true),
            }
        })
        .collect()
}

fn measure(robot: &Robot, case: &Case) -> Row {
    let t = Instant::now();
    let problem = case.request.validate(robot).expect("validate");
    let validate_ms = t.elapsed().as_secs_f64() * 1e3;
    // What a request spends besides the solve: validation and the prior
    // mean's report (`optimize_with` verifies the mean for the response).
    let t = Instant::now();
    let _ = problem.evaluate(problem.prior().mean.as_slice());
    let request_ms = validate_ms + t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let sol = problem.solve(&SolveControl::default()).expect("solve");
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let optimal = sol.status == Status::Optimal;
    // The answer re-verified from its weights alone, independently of the
    // solver's own report.
    let t = Instant::now();
    let verified = problem.is_feasible(&problem.evaluate(&sol.weights));
    let verify_ms = t.elapsed().as_secs_f64() * 1e3;
    let clarabel_solves = sol.stats.qp_solves - sol.stats.active_set_solves;
    let clarabel_ms = sol.stats.clarabel_ms / clarabel_solves.max(1) as f64;
    Row {
        name: case.name.clone(),
        status: sol.status,
        solved: optimal && verified && case.feasible,
        false_optimal: optimal && !verified,
        ms,
        iterations: sol.stats.iterations,
        restarts: sol.stats.restarts,
        split: [
            sol.stats.qp_ms,
            sol.stats.evaluation_ms,
            sol.stats.verification_ms,
        ],
        floor_ms: verify_ms + clarabel_ms,
        request_ms,
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn sorted(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v
}

fn summarise(set: &str, cases: &[Case], rows: &[Row]) {
    let labelled = cases.iter().filter(|c| c.feasible).count();
    let solved = rows.iter().filter(|r| r.solved).count();
    let false_optimal = rows.iter().filter(|r| r.false_optimal).count();
    let ms = sorted(rows.iter().map(|r| r.ms));
    let it = sorted(rows.iter().map(|r| r.iterations as f64));
    let restarted = rows.iter().filter(|r| r.restarts > 0).count();
    let total: f64 = ms.iter().sum();
    let floor = sorted(rows.iter().map(|r| r.floor_ms));
    let request = sorted(rows.iter().map(|r| r.request_ms));
    let request_floor = sorted(rows.iter().map(|r| r.request_ms + r.floor_ms));
    let split = rows.iter().fold([0.0; 3], |a, r| {
        [a[0] + r.split[0], a[1] + r.split[1], a[2] + r.split[2]]
    });
    let misses: Vec<&str> = rows
        .iter()
        .zip(cases)
        .filter(|(r, c)| c.feasible && !r.solved)
        .map(|(r, _)| r.name.as_str())
        .collect();
    println!(
        "{set}: {} problems, {labelled} labelled feasible",
        rows.len()
    );
    println!(
        "  solved {solved}/{labelled} ({:.1} %); false optimal {false_optimal}; misses {misses:?}",
        100.0 * solved as f64 / labelled.max(1) as f64
    );
    println!(
        "  Problem::solve median {:.1} ms  p99 {:.1} ms  max {:.1} ms",
        percentile(&ms, 0.5),
        percentile(&ms, 0.99),
        ms[ms.len() - 1]
    );
    println!(
        "  SCP iterations median {} p99 {}; problems that ran restarts {restarted}",
        percentile(&it, 0.5),
        percentile(&it, 0.99)
    );
    println!(
        "  time split: QP {:.0} %, iterate evaluation {:.0} %, dense verification {:.0} %",
        100.0 * split[0] / total,
        100.0 * split[1] / total,
        100.0 * split[2] / total
    );
    println!(
        "  certifying the answer alone (one dense verification + one Clarabel QP): median {:.1} ms  p99 {:.1} ms",
        percentile(&floor, 0.5),
        percentile(&floor, 0.99)
    );
    println!(
        "  a request besides its solve (validate + prior-mean report): median {:.1} ms; with the certification above: median {:.1} ms",
        percentile(&request, 0.5),
        percentile(&request_floor, 0.5)
    );
}

fn main() {
    let robot = Robot::panda().expect("panda");
    let limit = std::env::var("DPMP_BENCH_LIMIT")
        .ok()
        .map(|v| v.parse().expect("DPMP_BENCH_LIMIT must be a count"))
        .unwrap_or(usize::MAX);
    let which = std::env::var("DPMP_BENCH_SET").unwrap_or_default();
    let mut csv = std::env::var_os("DPMP_BENCH_PER_PROBLEM")
        .map(|p| std::fs::File::create(p).expect("DPMP_BENCH_PER_PROBLEM file"));
    if let Some(f) = csv.as_mut() {
        writeln!(f, "set,problem,status,solved,ms,iterations,restarts").expect("csv");
    }
    let mut sets = Vec::new();
    if which.is_empty() || which == "typical" {
        sets.push(("typical", typical_cases(&robot, limit)));
    }
    if which.is_empty() || which == "hard" {
        sets.push(("hard", file_cases("hard", limit)));
    }
    if which.is_empty() || which == "real" {
        sets.push(("real", file_cases("hard-real", limit)));
    }
    for (set, cases) in sets {
        let rows: Vec<Row> = cases.iter().map(|c| measure(&robot, c)).collect();
        summarise(set, &cases, &rows);
        if let Some(f) = csv.as_mut() {
            for r in &rows {
                writeln!(
                    f,
                    "{set},{},{:?},{},{:.3},{},{}",
                    r.name, r.status, r.solved, r.ms, r.iterations, r.restarts
                )
                .expect("csv");
            }
        }
    }
}
