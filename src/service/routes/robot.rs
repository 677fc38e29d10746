//! `GET /v1/robot`: the loaded robot's joints, limits, home configuration,
//! links and collision shapes ([`crate::service::describe::RobotInfo`]).

use crate::service::state::AppState;
use axum::extract::State;
use axum::Json;

/// `GET /v1/robot`.
pub async fn robot(State(state): State<AppState>) -> Json<serde_json::Value> {
    Json(state.robot_info().clone())
}
