//! `GET /v1/models`: the loaded network models and their configurations
//! ([`crate::service::describe::ModelList`]).

use crate::service::state::AppState;
use axum::extract::State;
use axum::Json;

/// `GET /v1/models`.
pub async fn models(State(state): State<AppState>) -> Json<serde_json::Value> {
    Json(state.models_info().clone())
}
