//! `GET /v1/robot`: the loaded robot's joints, limits, home configuration,
//! links and collision shapes.

use crate::robot::{JointLimit, LinkShape};
use crate::service::state::AppState;
use axum::extract::State;
use axum::Json;
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
pub fn describe(robot: &crate::robot::Robot) -> RobotInfo {
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

/// `GET /v1/robot`.
pub async fn robot(State(state): State<AppState>) -> Json<serde_json::Value> {
    Json(state.robot_info().clone())
}
