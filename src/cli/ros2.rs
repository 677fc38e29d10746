//! `dpmp ros2`: the planner as a ROS 2 node, and a stand-in cell to drive
//! one (see `dpmp::ros2`, cargo feature `ros2`).
//!
//! ```text
//! dpmp ros2 node   [--params-file FILE] [--node-name dpmp] [--namespace NS]
//!                  [--domain-id N] [--remap FROM:=TO]... [--model DIR] [--log-json]
//! dpmp ros2 replay [the same] [--targets 20] [--seed 7] [--with-node]
//! ```
//! `node` stops on SIGINT or SIGTERM, with its counts in the log. `replay`
//! publishes generated plants as a hand camera and a robot would, sends
//! each target, and prints what the node answered and how fast.

use crate::Result;
use clap::Subcommand;
use std::path::PathBuf;

/// `dpmp ros2` subcommands.
#[derive(Debug, Subcommand)]
pub enum Ros2Command {
    /// Run the node until SIGINT or SIGTERM.
    Node(NodeArgs),
    /// Drive a node with generated plants and print its answers and
    /// latencies (no camera or robot needed).
    Replay(ReplayArgs),
}

/// Which node, and how it is configured (ROS-style).
#[derive(Debug, clap::Args)]
pub struct NodeArgs {
    /// A ROS 2 parameters file (`<node>: ros__parameters: ...`): topics,
    /// QoS, matching rules, what to plan (docs/design.md, "ROS 2 node").
    #[arg(long)]
    pub params_file: Option<PathBuf>,
    /// The node's name.
    #[arg(long, default_value = "dpmp")]
    pub node_name: String,
    /// The node's namespace (relative topic names resolve in it).
    #[arg(long)]
    pub namespace: Option<String>,
    /// The DDS domain.
    #[arg(long, env = "ROS_DOMAIN_ID")]
    pub domain_id: Option<u16>,
    /// Rename a topic, ROS-style: `joint_states:=/franka/joint_states` (a
    /// topic setting or its current name on the left); repeatable.
    #[arg(long = "remap", value_name = "FROM:=TO")]
    pub remaps: Vec<String>,
    /// Trained network directory; default: the shipped model.
    #[arg(long, env = super::serve::MODEL_DIR_ENV)]
    pub model: Option<PathBuf>,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
    /// Log as JSON lines instead of text.
    #[arg(long)]
    pub log_json: bool,
    /// Show the DDS transport's own log (RustDDS, ros2-client): `-v` its
    /// warnings and errors, `-vv` its discovery steps. Quiet by default:
    /// its warnings are routine on a healthy run.
    #[arg(short, long, action = clap::ArgAction::Count)]
    pub verbose: u8,
}

/// Arguments of `dpmp ros2 replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The node to drive (its parameters give the topics and the domain).
    #[command(flatten)]
    pub node: NodeArgs,
    /// Targets to send (one generated plant each).
    #[arg(long, default_value_t = 20)]
    pub targets: usize,
    /// Seed of the generated plants.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Start the node in this process first (else one must be running).
    #[arg(long)]
    pub with_node: bool,
}

/// Run `dpmp ros2 ...`.
pub fn run(command: Ros2Command) -> Result<()> {
    match command {
        Ros2Command::Node(args) => node(args),
        Ros2Command::Replay(args) => replay(args),
    }
}

#[cfg(not(feature = "ros2"))]
fn without_the_feature() -> Result<()> {
    Err(crate::Error::invalid(
        "ros2",
        "this dpmp was built without the ROS 2 node: build it with `cargo build --release --features ros2`",
    ))
}

#[cfg(not(feature = "ros2"))]
fn node(_: NodeArgs) -> Result<()> {
    without_the_feature()
}

#[cfg(not(feature = "ros2"))]
fn replay(_: ReplayArgs) -> Result<()> {
    without_the_feature()
}

#[cfg(feature = "ros2")]
use with_ros2::{node, replay};

#[cfg(feature = "ros2")]
mod with_ros2 {
    use super::{NodeArgs, ReplayArgs};
    use crate::bench::report::Percentiles;
    use crate::net::Model;
    use crate::robot::Robot;
    use crate::ros2::msg::{DiagnosticStatus, Time};
    use crate::ros2::replay::{Answer, Cell, Frame};
    use crate::ros2::NodeSettings;
    use crate::synth::generate::Generator;
    use crate::synth::settings::SynthSettings;
    use crate::{Error, Result};
    use std::sync::Arc;
    use std::time::Duration;

    /// dpmp's log at `info`; the DDS stack's off unless `-v` (warnings)
    /// or `-vv` (its `info`, every discovery step) asks for it.
    fn init_logging(args: &NodeArgs) {
        let filter = match args.verbose {
            0 => "info,rustdds=off,ros2_client=off",
            1 => "info,rustdds=warn,ros2_client=warn",
            _ => "info,rustdds=info,ros2_client=info",
        };
        crate::cli::serve::init_logging_with(args.log_json, filter);
    }

    /// The settings the flags say.
    fn settings(args: &NodeArgs) -> Result<NodeSettings> {
        let mut settings = match &args.params_file {
            Some(path) => NodeSettings::from_params_file(path, &args.node_name)?,
            None => NodeSettings {
                node_name: args.node_name.clone(),
                ..NodeSettings::default()
            },
        };
        if let Some(ns) = &args.namespace {
            settings.namespace = ns.clone();
        }
        if let Some(domain) = args.domain_id {
            settings.domain_id = domain;
        }
        for rule in &args.remaps {
            settings.remap(rule)?;
        }
        settings.validate().map_err(crate::cli::as_flag_error)?;
        Ok(settings)
    }

    fn model_and_robot(args: &NodeArgs) -> Result<(Arc<Model>, Arc<Robot>)> {
        let robot = Arc::new(args.robot.load()?);
        let model = Arc::new(Model::load_or_shipped(args.model.as_deref())?);
        tracing::info!(model = model.name(), "model loaded");
        Ok((model, robot))
    }

    /// `dpmp ros2 node`.
    pub fn node(args: NodeArgs) -> Result<()> {
        init_logging(&args);
        let settings = settings(&args)?;
        let (model, robot) = model_and_robot(&args)?;
        let node = crate::ros2::spawn(settings, model, robot)?;
        runtime()?.block_on(async { crate::service::Signals::new().next().await });
        let counters = node.stop()?;
        tracing::info!(?counters, "stopped");
        Ok(())
    }

    /// `dpmp ros2 replay`.
    pub fn replay(args: ReplayArgs) -> Result<()> {
        if !(1..=10_000).contains(&args.targets) {
            return Err(Error::invalid("--targets", "must be in 1..=10000"));
        }
        init_logging(&args.node);
        let settings = settings(&args.node)?;
        let (model, robot) = model_and_robot(&args.node)?;
        let frames = frames(&model, &robot, args.targets, args.seed)?;
        let _node = match args.with_node {
            true => Some(crate::ros2::spawn(settings.clone(), model, robot)?),
            false => None,
        };
        let timeout = settings.deadline() + Duration::from_secs(30);
        let answers = runtime()?.block_on(async {
            let mut cell = Cell::new(&settings)?;
            cell.wait_for_node(Duration::from_secs(30)).await?;
            let bar = crate::progress::bar(true, frames.len() as u64, "targets");
            let mut answers = Vec::with_capacity(frames.len());
            for (i, frame) in frames.iter().enumerate() {
                let stamp = Time {
                    sec: i as i32 + 1,
                    nanosec: 0,
                };
                cell.sensors(frame, (stamp, stamp), Duration::from_millis(100))
                    .await?;
                answers.push(cell.request(frame.roi, timeout).await?);
                bar.inc(1);
            }
            bar.finish_and_clear();
            cell.close().await;
            Ok::<_, Error>(answers)
        })?;
        crate::cli::write_stdout(&summary(&answers))
    }

    /// One generated plant per target, the robot at home.
    fn frames(model: &Model, robot: &Robot, targets: usize, seed: u64) -> Result<Vec<Frame>> {
        let generator = Generator::new(SynthSettings::new(targets, 1), robot.clone())?;
        let camera = model.config().camera_model();
        let bar = crate::progress::bar(true, targets as u64, "plants");
        let frames = (0..targets)
            .map(|i| {
                let out = generator.config(seed, i)?;
                bar.inc(1);
                let depth = out.depths[0]
                    .as_ref()
                    .ok_or_else(|| Error::Numerical("the generator made no depth image".into()))?;
                Frame::new(
                    &out.images[0],
                    depth,
                    &camera,
                    out.records[0].bbox,
                    robot.joint_names(),
                    &robot.home(),
                )
            })
            .collect();
        bar.finish_and_clear();
        frames
    }

    /// The answers in a few lines: counts, then latencies.
    fn summary(answers: &[Answer]) -> String {
        let count = |level| answers.iter().filter(|a| a.status.level == level).count();
        let column =
            |key: &str| -> Vec<f64> { answers.iter().filter_map(|a| a.value(key)).collect() };
        let (latency, plan) = (column("target_to_publish_ms"), column("plan_ms"));
        let overhead: Vec<f64> = answers
            .iter()
            .filter_map(|a| Some(a.value("target_to_publish_ms")? - a.value("plan_ms")?))
            .collect();
        let round_trip: Vec<f64> = answers.iter().map(|a| a.round_trip_s * 1e3).collect();
        let mut out = format!(
            "targets {}: optimal {}, not optimal {}, refused {}\n\
             | ms | p50 | p95 | max |\n|---|---|---|---|\n",
            answers.len(),
            count(DiagnosticStatus::OK),
            count(DiagnosticStatus::WARN),
            count(DiagnosticStatus::ERROR),
        );
        for (name, values) in [
            ("target received → trajectory published", &latency),
            ("plan (messages → answer)", &plan),
            ("difference (the node's own time)", &overhead),
            ("target sent → diagnostics received", &round_trip),
        ] {
            let p = Percentiles::of(values);
            out.push_str(&format!(
                "| {name} | {:.2} | {:.2} | {:.2} |\n",
                p.p50, p.p95, p.max
            ));
        }
        out
    }

    fn runtime() -> Result<tokio::runtime::Runtime> {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| Error::Numerical(format!("cannot start a runtime: {e}")))
    }
}
