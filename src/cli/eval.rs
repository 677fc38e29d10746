//! `dpmp eval`: the paper's tables for a trained model on a dataset split,
//! and the depth-aware planning figures when the dataset has depth.

use crate::net::{Model, Space};
use crate::train::baseline::evaluate_baseline;
use crate::train::data::load_split;
use crate::train::data::Targets;
use crate::train::eval::{evaluate, to_markdown, write_outputs};
use crate::train::final_point::{task_final_pose, TcpFk};
use crate::train::plan_eval::evaluate_plans;
use crate::Error;
use std::path::PathBuf;

/// Arguments of `dpmp eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Model directory (model.safetensors + config.json).
    #[arg(long)]
    pub model: PathBuf,
    /// Dataset directory (with manifest.json).
    #[arg(long)]
    pub data: PathBuf,
    /// Split: train, val, test or all.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Output: table (Markdown) or json.
    #[arg(long, default_value = "table")]
    pub format: String,
    /// Directory for eval.json, eval.md and embedding.png [default:
    /// `eval-<model name>-<split>` inside the dataset folder; never inside
    /// the model].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Covariance weight alpha of the Eq. 7 column (default: the model's).
    #[arg(long)]
    pub alpha: Option<f64>,
    /// The robot (must be the one the model was trained for).
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Run `dpmp eval`.
pub fn run(args: EvalArgs) -> crate::Result<()> {
    if !matches!(args.split.as_str(), "train" | "val" | "test" | "all") {
        return Err(Error::invalid("split", "expected train, val, test or all"));
    }
    if !matches!(args.format.as_str(), "table" | "json") {
        return Err(Error::invalid("format", "expected table or json"));
    }
    let model = std::sync::Arc::new(Model::load(&args.model)?);
    let alpha = match args.alpha {
        Some(a) if a.is_finite() && a >= 0.0 => a,
        Some(a) => {
            return Err(Error::invalid(
                "alpha",
                format!("must be finite and >= 0, got {a}"),
            ))
        }
        None => model.config().training.as_ref().map_or(1.0, |t| t.alpha),
    };
    let robot = std::sync::Arc::new(args.robot.load()?);
    model.config().check_robot(&robot)?;
    let space = model.config().space;
    let targets = Targets::of(space, &robot);
    let data = load_split(&args.data, &args.split, &model.config().preprocess, targets)?;
    let joint_fk = |q: &[f64]| robot.tcp_pose(q);
    let fk: TcpFk = match space {
        Space::Joint => &joint_fk,
        Space::Task => &task_final_pose,
    };
    let (mut report, embedding) = evaluate(&model, &data.samples, &args.split, alpha, fk)?;
    report.planning = evaluate_plans(&model, &robot, &args.data, &args.split)?;
    if matches!(args.split.as_str(), "val" | "test") {
        let train = load_split(&args.data, "train", &model.config().preprocess, targets)?;
        let basis = crate::promp::Basis::new(&data.promp)?;
        report.baseline = Some(evaluate_baseline(
            &train.samples,
            &data.samples,
            &basis,
            fk,
        )?);
    }
    let out = args.out.clone().unwrap_or_else(|| {
        args.data
            .join(format!("eval-{}-{}", model.name(), args.split))
    });
    write_outputs(&out, &report, &embedding)?;
    if args.format == "json" {
        crate::cli::print_json(&report)
    } else {
        crate::cli::write_stdout(&to_markdown(&report))
    }
}
