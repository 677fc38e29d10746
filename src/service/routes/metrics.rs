//! `GET /metrics`: Prometheus text exposition.

use crate::service::state::AppState;
use axum::extract::State;
use axum::http::header::CONTENT_TYPE;
use axum::response::IntoResponse;

/// Content type of the Prometheus text format.
pub const PROMETHEUS_CONTENT_TYPE: &str = "text/plain; version=0.0.4; charset=utf-8";

/// `GET /metrics`.
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    let text = state.metrics().render(state.limiter().load());
    ([(CONTENT_TYPE, PROMETHEUS_CONTENT_TYPE)], text)
}
