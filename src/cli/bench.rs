//! `dpmp bench`: run the offline benchmark suite, or generate it.
//!
//! - `dpmp bench --problems problems/ --out DIR [--methods a,b] [--workers K] [--limit N]`
//! - `dpmp bench --model DIR --data DIR [--split test] --out DIR [...]`: the
//!   plan pipeline on a generated dataset (network prior, then each method)
//! - `dpmp bench make-problems --out problems/ [--seed S] [--per-category N]`
//! - `dpmp bench make-problems --set hard --out problems/hard [--count N]`
//! - `dpmp bench make-problems --set hard-real --annotations DIR --out problems/hard-real [--count N]`
//! - `dpmp bench label-typical --out problems/typical/labels.json [--count N] [--restarts R]`
//! - `dpmp bench world --data DIR [--split test] [--model DIR] [--out FILE]`:
//!   plans with no world, the depth-sensed world and the true scene, each
//!   checked against the true scene
//! - `dpmp bench moveit --problems DIR [--out DIR] [--limit N]`:
//!   MotionBenchMaker's MoveIt problems, a table per scene

use crate::bench::hard_set::real;
use crate::bench::{
    self, method_from_name, HardSettings, MakeSettings, RunSettings, DEFAULT_METHODS,
};
use crate::{Error, Result};
use std::path::PathBuf;

/// Arguments of `dpmp bench`.
#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct BenchArgs {
    /// Generate problems instead of running them.
    #[command(subcommand)]
    pub command: Option<BenchCommand>,
    /// Directory of problem files (*.json).
    #[arg(long, default_value = "problems")]
    pub problems: PathBuf,
    /// Output directory for report.json, report.md and the plots.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Comma-separated methods: prior-mean, rejection-N, dpmp-qp, penalty-gd
    /// (default: prior-mean, rejection-100, rejection-1000, dpmp-qp, penalty-gd).
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Run only the first N problems (sorted by file name) or targets.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Model mode: trained model folder (config.json + model.safetensors);
    /// needs --data. Runs the plan pipeline (network prior, then each
    /// method) on the dataset's targets instead of --problems.
    #[arg(long, requires = "data")]
    pub model: Option<PathBuf>,
    /// Model mode: generated dataset (`dpmp data generate` output).
    #[arg(long, requires = "model")]
    pub data: Option<PathBuf>,
    /// Model mode: dataset split (train, val, test or all).
    #[arg(long, default_value = "test")]
    pub split: String,
    /// The robot (in model mode, the one the model was trained for).
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// `dpmp bench` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Generate the seeded problem suite.
    MakeProblems(MakeArgs),
    /// Label the typical optimiser-benchmark problems with witnesses.
    LabelTypical(LabelArgs),
    /// Plan a dataset's targets with no world, the world sensed from depth
    /// and the true scene; check each plan against the true scene.
    World(WorldArgs),
    /// Plan MotionBenchMaker's MoveIt problems (sceneNNNN.yaml /
    /// requestNNNN.yaml pairs) on default options; a table per scene.
    Moveit(MoveItBenchArgs),
}

/// Arguments of `dpmp bench moveit`.
#[derive(Debug, clap::Args)]
pub struct MoveItBenchArgs {
    /// A folder of sceneNNNN.yaml / requestNNNN.yaml pairs, or of such
    /// folders (one per scene family).
    #[arg(long)]
    pub problems: PathBuf,
    /// Output folder: report.json, report.md, plan_time.png, answers/.
    #[arg(long, default_value = "bench-moveit")]
    pub out: PathBuf,
    /// Run only the first N problems of each family.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Required clearance (m).
    #[arg(long, default_value_t = crate::moveit::plan::MOVEIT_DEFAULT_CLEARANCE_M)]
    pub clearance: f64,
    /// `auto` or seconds.
    #[arg(long, default_value = "auto")]
    pub duration: crate::moveit::DurationChoice,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Arguments of `dpmp bench world`.
#[derive(Debug, clap::Args)]
pub struct WorldArgs {
    /// Generated dataset with depth and intruders (`dpmp data generate
    /// --intruders 1`).
    #[arg(long)]
    pub data: PathBuf,
    /// Dataset split (train, val, test or all).
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Trained model folder [default: the shipped model].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Write every plan's outcome and the table as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The robot (the one the model was trained for).
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Arguments of `dpmp bench label-typical`.
#[derive(Debug, clap::Args)]
pub struct LabelArgs {
    /// Output file.
    #[arg(long, default_value = "problems/typical/labels.json")]
    pub out: PathBuf,
    /// Typical problems (seeds 0..count).
    #[arg(long, default_value_t = 100)]
    pub count: usize,
    /// Restarts per solve (the long search; at most 32).
    #[arg(long, default_value_t = 32)]
    pub restarts: usize,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Arguments of `dpmp bench make-problems`.
#[derive(Debug, clap::Args)]
pub struct MakeArgs {
    /// Output directory (created if missing).
    #[arg(long, default_value = "problems")]
    pub out: PathBuf,
    /// Master seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Problems per category (7 categories; the suite only).
    #[arg(long, default_value_t = 9)]
    pub per_category: usize,
    /// Which set: `suite` (the seven categories), `hard` (intruders beside
    /// the demonstrated path, labelled by a long search) or `hard-real`
    /// (the same on the paper's real annotation priors; needs
    /// --annotations).
    #[arg(long, default_value = "suite", value_parser = ["suite", "hard", "hard-real"])]
    pub set: String,
    /// Problems of the hard sets.
    #[arg(long, default_value_t = 200)]
    pub count: usize,
    /// hard-real: the annotation folder (J1..J7/K.json, the paper's
    /// `dpmp-annotation`).
    #[arg(long, required_if_eq("set", "hard-real"))]
    pub annotations: Option<PathBuf>,
    /// Hard set: skip the long-search labels (every label unknown).
    #[arg(long)]
    pub no_label: bool,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Run `dpmp bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    match args.command {
        Some(BenchCommand::MakeProblems(m)) => make(m),
        Some(BenchCommand::LabelTypical(l)) => label(l),
        Some(BenchCommand::World(w)) => world(w),
        Some(BenchCommand::Moveit(m)) => moveit(m),
        None => run_suite(args),
    }
}

fn make(args: MakeArgs) -> Result<()> {
    let robot = args.robot.load()?;
    let generator = bench::make_problems::generator(&robot)?;
    let hard = HardSettings {
        seed: args.seed,
        count: args.count,
        label: !args.no_label,
        progress: true,
    };
    let problems = match (args.set.as_str(), &args.annotations) {
        ("hard", _) => bench::make_hard_set(&generator, &hard),
        ("hard-real", Some(dir)) => real::make_real_set(&robot, &real::load_targets(dir)?, &hard),
        ("hard-real", None) => Err(Error::invalid(
            "--annotations",
            "--set hard-real needs the annotation folder",
        )),
        _ => {
            let settings = MakeSettings {
                seed: args.seed,
                per_category: args.per_category,
                progress: true,
            };
            bench::make_problems(&generator, &settings)
        }
    }
    .map_err(super::as_flag_error)?;
    std::fs::create_dir_all(&args.out).map_err(|e| Error::write(&args.out, e.to_string()))?;
    for p in &problems {
        p.save(&args.out)?;
    }
    eprintln!(
        "wrote {} problems to {}",
        problems.len(),
        args.out.display()
    );
    Ok(())
}

fn label(args: LabelArgs) -> Result<()> {
    if args.count == 0 {
        return Err(Error::invalid("--count", "must be at least 1"));
    }
    let most = crate::optim::seeds::restart::MAX_RESTARTS;
    if args.restarts > most {
        return Err(Error::invalid(
            "--restarts",
            format!("must be in 0..={most}, got {}", args.restarts),
        ));
    }
    let robot = args.robot.load()?;
    let labels = bench::typical_labels::label_typical(&robot, args.count, args.restarts, true)
        .map_err(super::as_flag_error)?;
    labels.save(&args.out)?;
    eprintln!(
        "{} of {} typical problems labelled feasible (with witnesses) in {}",
        labels.feasible(),
        args.count,
        args.out.display()
    );
    Ok(())
}

fn world(args: WorldArgs) -> Result<()> {
    let model = std::sync::Arc::new(crate::net::Model::load_or_shipped(args.model.as_deref())?);
    let robot = std::sync::Arc::new(args.robot.load()?);
    model.config().check_robot(&robot)?;
    let eval = bench::world_eval::evaluate_worlds(&model, &robot, &args.data, &args.split, true)?;
    if let Some(out) = &args.out {
        crate::synth::dataset::write_json_atomic(out, &eval)?;
    }
    eprintln!(
        "{} targets of split {:?} planned three ways ({} skipped: no depth or no intruder)",
        eval.targets, eval.split, eval.skipped
    );
    print!("{}", bench::world_eval::markdown(&eval));
    Ok(())
}

fn moveit(args: MoveItBenchArgs) -> Result<()> {
    use crate::bench::moveit_suite::{find_problems, run_moveit_bench, write_report};
    if args.limit == Some(0) {
        return Err(Error::invalid("--limit", "must be at least 1"));
    }
    let robot = args.robot.load()?;
    let mut problems = find_problems(&args.problems)?;
    if let Some(limit) = args.limit {
        let mut kept: std::collections::BTreeMap<String, usize> = Default::default();
        problems.retain(|p| {
            let n = kept.entry(p.family.clone()).or_default();
            *n += 1;
            *n <= limit
        });
    }
    let options = crate::moveit::MoveItPlanOptions {
        clearance_m: args.clearance,
        duration_s: args.duration,
        ..Default::default()
    };
    std::fs::create_dir_all(&args.out).map_err(|e| Error::write(&args.out, e.to_string()))?;
    let progress = crate::progress::bar(true, problems.len() as u64, "MoveIt problems");
    let report = run_moveit_bench(&problems, &options, &robot, &args.out, &progress)?;
    progress.finish_and_clear();
    write_report(&report, &args.out)?;
    print!("{}", crate::bench::moveit_suite::markdown(&report));
    eprintln!("report written to {}", args.out.display());
    Ok(())
}

fn run_suite(args: BenchArgs) -> Result<()> {
    if args.workers == Some(0) {
        return Err(Error::invalid("--workers", "must be at least 1"));
    }
    if args.limit == Some(0) {
        return Err(Error::invalid("--limit", "must be at least 1"));
    }
    let names: Vec<String> = if args.methods.is_empty() {
        DEFAULT_METHODS.iter().map(|s| s.to_string()).collect()
    } else {
        args.methods.clone()
    };
    let methods = names
        .iter()
        .map(|n| method_from_name(n.trim()))
        .collect::<Result<Vec<_>>>()?;
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let settings = RunSettings {
        workers: args.workers,
        progress: true,
    };
    let robot = args.robot.load()?;
    let report = match (&args.model, &args.data) {
        (Some(model), Some(data)) => bench::run_model_suite(
            &robot,
            bench::ModelSource {
                model,
                data,
                split: &args.split,
            },
            &args.out,
            methods,
            args.limit,
            &settings,
            &command,
        )?,
        (None, None) => bench::run_suite(
            &robot,
            &args.problems,
            &args.out,
            methods,
            args.limit,
            &settings,
            &command,
        )?,
        _ => return Err(Error::invalid("--model", "--model and --data go together")),
    };
    print!("{}", report.markdown());
    eprintln!("report written to {}", args.out.display());
    Ok(())
}
