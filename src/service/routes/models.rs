//! `GET /v1/models`: the loaded network models and their configurations.

use crate::service::state::AppState;
use axum::extract::State;
use axum::Json;
use serde::Serialize;

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
pub fn describe(model: Option<&crate::net::Model>) -> ModelList<'_> {
    let models = model
        .map(|m| ModelInfo {
            name: m.name(),
            config: m.config(),
        })
        .into_iter()
        .collect();
    ModelList { models }
}

/// `GET /v1/models`.
pub async fn models(State(state): State<AppState>) -> Json<serde_json::Value> {
    Json(state.models_info().clone())
}
