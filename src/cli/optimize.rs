//! `dpmp optimize`: solve one request file (the HTTP request schema) and
//! print the response JSON; optionally plot prior band, prior mean and the
//! optimised trajectory per joint.

use crate::optim::finer_basis::on_answer_basis;
use crate::optim::{optimize, OptimizeRequest, OptimizeResponse, Problem};
use crate::plot::{format_of, prior_and_answer, PriorBand};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Arguments of `dpmp optimize`.
#[derive(Debug, clap::Args)]
pub struct OptimizeArgs {
    /// Request JSON file (same schema as `POST /v1/optimize`).
    #[arg(long)]
    pub request: PathBuf,
    /// Draw prior ±2σ band, prior mean and the optimised trajectory per
    /// joint into this `.png` or `.svg` file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Exit 3 (after printing the answer) when its status is not `optimal`.
    #[arg(long)]
    pub require_optimal: bool,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Run `dpmp optimize`.
pub fn run(args: OptimizeArgs) -> Result<()> {
    // The optimiser's stages log at `debug`; `RUST_LOG=dpmp=debug` shows them.
    super::serve::init_logging_with(false, "warn");
    if let Some(plot) = &args.plot {
        format_of(plot, "--plot")?;
    }
    let robot = args.robot.load()?;
    let request = read_request(&args.request)?;
    let response = optimize(&request, &robot).map_err(|e| in_file(e, &args.request))?;
    if let Some(plot) = &args.plot {
        let problem = on_answer_basis(&request, &response)
            .validate(&robot)
            .map_err(|e| in_file(e, &args.request))?;
        plot_response(plot, &problem, &response)?;
    }
    super::print_json(&response)?;
    super::require_optimal(args.require_optimal, response.stop_reason)
}

/// Parse a request file; malformed JSON or unknown fields are invalid input
/// (exit code 2) naming the file and serde's location.
pub fn read_request(path: &Path) -> Result<OptimizeRequest> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
    if let Some(d) = crate::strict_json::find_duplicate_key(text.as_bytes()) {
        return Err(Error::invalid(
            d.path.clone(),
            format!("{}: malformed request: {d}", path.display()),
        ));
    }
    serde_json::from_str(&text).map_err(|e| {
        Error::invalid(
            "--request",
            format!("{}: malformed request: {e}", path.display()),
        )
    })
}

/// Add the file name to a validation error's message.
fn in_file(e: Error, path: &Path) -> Error {
    match e {
        Error::Invalid { field, message } => Error::Invalid {
            field,
            message: format!("{message} (in {})", path.display()),
        },
        other => other,
    }
}

/// Prior band and mean, optimised trajectory, joint limits.
pub fn plot_response(path: &Path, problem: &Problem, response: &OptimizeResponse) -> Result<()> {
    let basis = problem.basis();
    let prior = problem.prior();
    let band = PriorBand {
        mean: prior.trajectory_mean(basis),
        std: prior.trajectory_std(basis, 0.0),
    };
    let title = format!(
        "dPMP optimise: Mahalanobis {:.3}, status {}",
        response.mahalanobis,
        response.status.as_str()
    );
    prior_and_answer(
        path,
        &title,
        (basis, problem.duration()),
        band,
        response,
        problem.robot(),
    )
}
