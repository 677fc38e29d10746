//! `dpmp plan-moveit`: plan a MoveIt query (a `PlanningScene` and a
//! `MotionPlanRequest`, YAML or JSON files) and print the answer JSON, the
//! same as `POST /v1/moveit/plan` gives.

use crate::moveit::{plan_moveit, DurationChoice, MoveItPlanOptions, MoveItQuery};
use crate::optim::{PriorSpec, SolveControl};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Arguments of `dpmp plan-moveit`.
#[derive(Debug, clap::Args)]
pub struct PlanMoveItArgs {
    /// `moveit_msgs/PlanningScene` file (YAML as `ros2 topic echo` writes
    /// it, or JSON).
    #[arg(long)]
    pub scene: PathBuf,
    /// `moveit_msgs/MotionPlanRequest` file (YAML or JSON).
    #[arg(long)]
    pub request: PathBuf,
    /// Required clearance (m).
    #[arg(long, default_value_t = crate::moveit::plan::MOVEIT_DEFAULT_CLEARANCE_M)]
    pub clearance: f64,
    /// `auto` (the shortest duration that keeps the rate limits) or seconds.
    #[arg(long, default_value = "auto")]
    pub duration: DurationChoice,
    /// A prior JSON file (`"smooth"`, `{"mean", "cov"}` or
    /// `{"annotation"}`, as the request's `prior`); default: smooth.
    #[arg(long)]
    pub prior: Option<PathBuf>,
    /// Exit 3 (after printing the answer) when its status is not `optimal`.
    #[arg(long)]
    pub require_optimal: bool,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Run `dpmp plan-moveit`.
pub fn run(args: PlanMoveItArgs) -> Result<()> {
    // The optimiser's stages log at `debug`; `RUST_LOG=dpmp=debug` shows them.
    super::serve::init_logging_with(false, "warn");
    let robot = args.robot.load()?;
    let options = MoveItPlanOptions {
        prior: match &args.prior {
            Some(path) => read_prior(path)?,
            None => PriorSpec::Smooth,
        },
        clearance_m: args.clearance,
        duration_s: args.duration,
        ..MoveItPlanOptions::default()
    };
    let scene = read_text(&args.scene)?;
    let request = read_text(&args.request)?;
    let query = MoveItQuery::read(&scene, &request, &robot)?;
    let answer =
        plan_moveit(&query, &options, &robot, &SolveControl::default()).map_err(flag_names)?;
    super::print_json(&answer)?;
    super::require_optimal(args.require_optimal, answer.result.stop_reason)
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))
}

fn read_prior(path: &Path) -> Result<PriorSpec> {
    let text = read_text(path)?;
    serde_json::from_str(&text)
        .map_err(|e| Error::invalid("--prior", format!("{}: not a prior: {e}", path.display())))
}

/// The options' fields as the flags that set them (`clearance_m` →
/// `--clearance`, `duration_s` → `--duration`).
fn flag_names(e: Error) -> Error {
    match e {
        Error::Invalid { field, message } => {
            let field = match field.as_str() {
                "clearance_m" => "--clearance".to_string(),
                "duration_s" => "--duration".to_string(),
                _ => field,
            };
            Error::Invalid { field, message }
        }
        other => other,
    }
}
