//! The offline benchmark suite: problem files ([`problem_file`]), their
//! seeded generator ([`make_problems`], drawing synthetic targets with
//! [`synth_target`] and checking feasibility claims with [`witness`]), the compared methods
//! ([`methods`]), the parallel runner ([`runner`]) and the reports
//! ([`report`], [`plots`]); [`world_eval`] checks plans made with and
//! without a sensed world against a dataset's true scene. `dpmp bench` (src/cli/bench.rs) is a thin shell
//! over [`run_suite`] and [`make_problems()`].

pub mod hard_set;
pub mod make_problems;
pub mod methods;
pub mod model_suite;
pub mod moveit_suite;
pub mod plots;
pub mod problem_file;
pub mod report;
pub mod runner;
pub mod synth_target;
pub mod typical_labels;
pub mod witness;
pub mod world_eval;

pub use hard_set::{make_hard_set, HardSettings};
pub use make_problems::{make_problems, MakeSettings};
pub use methods::{method_from_name, Method, DEFAULT_METHODS};
pub use problem_file::{load_dir, Expect, Meta, ProblemFile, CATEGORIES};
pub use report::Report;
pub use runner::{run_benchmark, RunRecord, RunSettings};

use crate::robot::Robot;
use crate::{Error, Result};
use std::path::Path;

/// Run `methods` on the first `limit` problems of `problems_dir` and write
/// `report.json`, `report.md` and the plots into `out`.
pub fn run_suite(
    robot: &Robot,
    problems_dir: &Path,
    out: &Path,
    methods: Vec<Box<dyn Method>>,
    limit: Option<usize>,
    settings: &RunSettings,
    command: &str,
) -> Result<Report> {
    let mut problems = load_dir(problems_dir)?;
    if let Some(n) = limit {
        problems.truncate(n);
    }
    run_and_report(robot, &problems, out, methods, settings, command)
}

/// Where model mode takes its targets and network from.
#[derive(Clone, Copy, Debug)]
pub struct ModelSource<'a> {
    /// Trained model folder (`config.json`, `model.safetensors`).
    pub model: &'a Path,
    /// Generated dataset folder.
    pub data: &'a Path,
    /// Split of the dataset (`train`, `val`, `test` or `all`).
    pub split: &'a str,
}

/// Model mode: the plan pipeline on the first `limit` targets of the
/// source's split (see [`model_suite`]); writes the same report files
/// into `out`.
pub fn run_model_suite(
    robot: &Robot,
    source: ModelSource,
    out: &Path,
    methods: Vec<Box<dyn Method>>,
    limit: Option<usize>,
    settings: &RunSettings,
    command: &str,
) -> Result<Report> {
    let model = crate::net::Model::load(source.model)?;
    model.config().check_robot(robot)?;
    let problems = model_suite::model_problems(&model, source.data, source.split, limit)?;
    run_and_report(robot, &problems, out, methods, settings, command)
}

/// Run `methods` on `problems` and write the report and plots into `out`.
pub fn run_and_report(
    robot: &Robot,
    problems: &[(String, Result<ProblemFile>)],
    out: &Path,
    methods: Vec<Box<dyn Method>>,
    settings: &RunSettings,
    command: &str,
) -> Result<Report> {
    std::fs::create_dir_all(out).map_err(|e| Error::write(out, e.to_string()))?;
    let records = run_benchmark(problems, &methods, robot, settings)?;
    let names: Vec<String> = methods.iter().map(|m| m.name()).collect();
    let report = Report::new(command, &names, records);
    report.write(out)?;
    plots::write_plots(&report, out)?;
    Ok(report)
}
