//! The bodies of `GET /v1/robot` and `GET /v1/models`: what the service
//! says about the loaded robot and model, computed once at start-up
//! ([`super::state::AppState::new`]) and served as they are.

use crate::robot::{JointLimit, LinkShape};
use serde::Serialize;

/// One actuated joint with its limits.
#[derive(Debug, Serialize)]
pub struct JointInfo {
    /// Joint name from the URDF.
    pub name: String,
    /// Position, velocity, acceleration and jerk limits.
    #[serde(flatten)]
    pub limit: JointLimit,
}

/// Body of `/v1/robot`.
#[derive(Debug, Serialize)]
pub struct RobotInfo {
    /// Robot name from the URDF.
    pub name: String,
    /// Number of actuated joints.
    pub dof: usize,
    /// Actuated joint names, base to tip (the order of every joint vector).
    pub joint_names: Vec<String>,
    /// Joints with limits, in the same order.
    pub joints: Vec<JointInfo>,
    /// Home configuration (rad).
    pub home: Vec<f64>,
    /// Every link along the chain, base to tip.
    pub link_names: Vec<String>,
    /// The tool-centre-point link.
    pub tcp_link: String,
    /// Convex collision primitives in their link frames.
    pub collision_shapes: Vec<LinkShape>,
}

/// Describe `robot` (computed once at start-up).
pub fn robot(robot: &crate::robot::Robot) -> RobotInfo {
    let joints = robot
        .joint_names()
        .iter()
        .zip(robot.limits())
        .map(|(name, limit)| JointInfo {
            name: name.clone(),
            limit: *limit,
        })
        .collect();
    RobotInfo {
        name: robot.name().to_string(),
        dof: robot.dof(),
        joint_names: robot.joint_names().to_vec(),
        joints,
        home: robot.home(),
        link_names: robot.link_names().to_vec(),
        tcp_link: robot
            .link_names()
            .get(robot.tcp_link())
            .cloned()
            .unwrap_or_default(),
        collision_shapes: robot.collision_shapes().to_vec(),
    }
}

/// One loaded model.
#[derive(Debug, Serialize)]
pub struct ModelInfo<'a> {
    /// Model name (the `model` field of `/v1/plan` answers).
    pub name: &'a str,
    /// Its configuration (architecture, ProMP settings, preprocessing, ...).
    pub config: &'a crate::net::ModelConfig,
}

/// Body of `/v1/models`.
#[derive(Debug, Serialize)]
pub struct ModelList<'a> {
    /// Loaded models; empty when the service runs without one.
    pub models: Vec<ModelInfo<'a>>,
}

/// Describe the loaded model (computed once at start-up).
pub fn models(model: Option<&crate::net::Model>) -> ModelList<'_> {
    let models = model
        .map(|m| ModelInfo {
            name: m.name(),
            config: m.config(),
        })
        .into_iter()
        .collect();
    ModelList { models }
}
