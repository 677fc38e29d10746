//! `GET /healthz` (the process answers) and `GET /readyz` (robot and
//! optional model loaded, not shutting down).

use crate::service::state::AppState;
use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use serde::Serialize;

/// Body of `/healthz`.
#[derive(Debug, Serialize)]
pub struct Health {
    /// Always `"ok"`.
    pub status: &'static str,
    /// Crate version.
    pub version: &'static str,
}

/// `GET /healthz`.
pub async fn healthz() -> Json<Health> {
    Json(Health {
        status: "ok",
        version: env!("CARGO_PKG_VERSION"),
    })
}

/// Body of `/readyz`.
#[derive(Debug, Serialize)]
pub struct Readiness {
    /// Whether the service takes work (`/v1/optimize` at least).
    pub ready: bool,
    /// Whether a graceful shutdown has begun.
    pub shutting_down: bool,
}

/// `GET /readyz`: 200 when ready, 503 with the same body otherwise.
pub async fn readyz(State(state): State<AppState>) -> (StatusCode, Json<Readiness>) {
    let shutting_down = state.is_shutting_down();
    let ready = !shutting_down;
    let status = if ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (
        status,
        Json(Readiness {
            ready,
            shutting_down,
        }),
    )
}
