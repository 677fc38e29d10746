//! The `dpmp` command line: one subcommand group per stage of the data flow.
//!
//! Every subcommand is a thin shell over a library call: it parses flags
//! (clap), loads inputs, calls the library and prints JSON (or a table).
//! Errors go to stderr; the exit code is 2 for invalid input (a flag, a
//! field, or an input file that is missing, unreadable or malformed), 1 for
//! any other failure (an output that cannot be written, a numerical
//! failure), 3 when `--require-optimal` / `--require-converged` was given
//! and the printed answer is not that, and 0 otherwise (see the README's
//! "Exit codes").

use clap::{Parser, Subcommand};
use std::process::ExitCode;

pub mod bench;
pub mod data;
pub mod eval;
pub mod optimize;
pub mod plan;
pub mod plan_moveit;
pub mod prior;
pub mod promp_args;
pub mod robot;
pub mod robot_args;
pub mod ros2;
pub mod serve;
pub mod train;

pub use promp_args::PrompArgs;
pub use robot_args::RobotArgs;

/// dPMP: learned ProMP priors and constrained trajectory optimisation for
/// selective strawberry harvesting with a Franka Panda.
#[derive(Debug, Parser)]
#[command(name = "dpmp", version, about, long_about = None)]
pub struct Cli {
    /// The subcommand to run.
    #[command(subcommand)]
    pub command: Command,
}

/// Top-level subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit, inspect and plot ProMP priors (the paper's annotation format).
    #[command(subcommand)]
    Prior(prior::PriorCommand),
    /// Robot kinematics and clearance queries.
    #[command(subcommand)]
    Robot(robot::RobotCommand),
    /// Optimise a trajectory for a request file (the HTTP request schema).
    Optimize(optimize::OptimizeArgs),
    /// Generate and summarise synthetic datasets.
    #[command(subcommand)]
    Data(data::DataCommand),
    /// Train a dPMP network.
    Train(train::TrainArgs),
    /// Evaluate a trained network (the paper's tables).
    Eval(eval::EvalArgs),
    /// Plan from an image: network prior, then the optimiser.
    Plan(plan::PlanArgs),
    /// Plan a MoveIt query: a PlanningScene and a MotionPlanRequest.
    PlanMoveit(plan_moveit::PlanMoveItArgs),
    /// Run the HTTP service.
    Serve(serve::ServeArgs),
    /// The planner as a ROS 2 node, and a stand-in cell to drive one
    /// (built with `--features ros2`).
    #[command(subcommand)]
    Ros2(ros2::Ros2Command),
    /// Run offline benchmarks.
    Bench(bench::BenchArgs),
}

/// `Err(Unsolved)` (exit 3) when `required` and the answer that stopped
/// for `stop` is not `optimal`.
pub fn require_optimal(required: bool, stop: crate::optim::StopReason) -> crate::Result<()> {
    if required && stop.status() != crate::optim::Status::Optimal {
        return Err(crate::Error::Unsolved(format!(
            "the answer is `{}` (stop_reason `{stop}`), not `optimal` (--require-optimal)",
            stop.status().as_str()
        )));
    }
    Ok(())
}

/// Parse the command line, run it, and map errors to exit codes.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err}");
            match err {
                crate::Error::Invalid { .. } | crate::Error::File { .. } => ExitCode::from(2),
                crate::Error::Unsolved(_) => ExitCode::from(3),
                _ => ExitCode::from(1),
            }
        }
    }
}

/// Run one parsed command.
pub fn run(command: Command) -> crate::Result<()> {
    match command {
        Command::Prior(c) => prior::run(c),
        Command::Robot(c) => robot::run(c),
        Command::Optimize(a) => optimize::run(a),
        Command::Data(c) => data::run(c),
        Command::Train(a) => train::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Plan(a) => plan::run(a),
        Command::PlanMoveit(a) => plan_moveit::run(a),
        Command::Serve(a) => serve::run(a),
        Command::Ros2(c) => ros2::run(c),
        Command::Bench(a) => bench::run(a),
    }
}

/// Write `value` as pretty JSON to stdout.
pub fn print_json<T: serde::Serialize>(value: &T) -> crate::Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| crate::Error::Numerical(format!("cannot serialise output: {e}")))?;
    write_stdout(&text)
}

/// Write `text` and a newline to standard output. A reader that closed the
/// pipe early (`dpmp ... | head`) is not an error; any other write failure
/// is reported, never a panic.
pub(crate) fn write_stdout(text: &str) -> crate::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|_| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(crate::Error::file(
            std::path::Path::new("<stdout>"),
            format!("cannot write the output: {e}"),
        )),
        _ => Ok(()),
    }
}

pub use crate::fsio::read_json;

/// Rename the field of a validation error to the CLI flag that set it
/// (`n_samples` -> `--n-samples`).
pub fn as_flag_error(e: crate::Error) -> crate::Error {
    match e {
        crate::Error::Invalid { field, message } => crate::Error::Invalid {
            field: format!("--{}", field.replace('_', "-")),
            message,
        },
        other => other,
    }
}
