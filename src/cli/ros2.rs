//! `dpmp ros2`: run the planner as a ROS 2 node (see `dpmp::ros2`, cargo
//! feature `ros2`).
//!
//! ```text
//! dpmp ros2 [--params-file FILE] [--node-name dpmp] [--namespace NS]
//!           [--domain-id N] [--remap FROM:=TO]... [--model DIR]
//!           [--robot URDF --base LINK --tip LINK] [--log-json]
//! ```
//! Stops on SIGINT or SIGTERM, with its counts in the log.

use crate::Result;
use std::path::PathBuf;

/// Arguments of `dpmp ros2`.
#[derive(Debug, clap::Args)]
pub struct Ros2Args {
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
}

/// Run `dpmp ros2` until SIGINT or SIGTERM.
#[cfg(feature = "ros2")]
pub fn run(args: Ros2Args) -> Result<()> {
    use crate::ros2::NodeSettings;
    use std::sync::Arc;
    super::serve::init_logging(args.log_json);
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
    settings.validate().map_err(super::as_flag_error)?;
    let robot = Arc::new(args.robot.load()?);
    let model = Arc::new(crate::net::Model::load_or_shipped(args.model.as_deref())?);
    tracing::info!(model = model.name(), "model loaded");
    let node = crate::ros2::spawn(settings, model, robot)?;
    wait_for_signal()?;
    let counters = node.stop()?;
    tracing::info!(?counters, "stopped");
    Ok(())
}

/// Without the feature: say how to get it.
#[cfg(not(feature = "ros2"))]
pub fn run(_args: Ros2Args) -> Result<()> {
    Err(crate::Error::invalid(
        "ros2",
        "this dpmp was built without the ROS 2 node: build it with `cargo build --release --features ros2`",
    ))
}

/// Block until SIGINT or SIGTERM.
#[cfg(feature = "ros2")]
fn wait_for_signal() -> Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| crate::Error::Numerical(format!("cannot start a runtime: {e}")))?;
    runtime.block_on(async {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{signal, SignalKind};
            let mut term = signal(SignalKind::terminate())
                .map_err(|e| crate::Error::Numerical(format!("cannot wait for SIGTERM: {e}")))?;
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
        }
        #[cfg(not(unix))]
        let _ = tokio::signal::ctrl_c().await;
        Ok(())
    })
}
