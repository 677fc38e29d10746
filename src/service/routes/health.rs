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
    /// The robot (always loaded: the service does not start without it).
    pub robot: RobotStatus,
    /// The network model (optional; `/v1/plan` needs it).
    pub model: ModelStatus,
}

/// Robot part of `/readyz`.
#[derive(Debug, Serialize)]
pub struct RobotStatus {
    /// Always true.
    pub loaded: bool,
    /// Robot name.
    pub name: String,
    /// Number of actuated joints.
    pub dof: usize,
}

/// Model part of `/readyz`.
#[derive(Debug, Serialize)]
pub struct ModelStatus {
    /// Whether a model is loaded.
    pub loaded: bool,
    /// Its name.
    pub name: Option<String>,
    /// Where it was loaded from: `shipped` (the model the binary carries)
    /// or the name of its folder (never the path: `/readyz` is open);
    /// `null` without a model (`--no-model`).
    pub source: Option<String>,
}

/// What an open route may say of a model's source: `shipped`, or the last
/// component of its folder.
pub fn public_source(source: &str) -> String {
    std::path::Path::new(source)
        .file_name()
        .map(|name| name.to_string_lossy().into_owned())
        .unwrap_or_else(|| source.to_string())
}

/// `GET /readyz`: 200 when ready, 503 with the same body otherwise.
pub async fn readyz(State(state): State<AppState>) -> (StatusCode, Json<Readiness>) {
    let shutting_down = state.is_shutting_down();
    let robot = state.robot();
    let model = state.model();
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
            robot: RobotStatus {
                loaded: true,
                name: robot.name().to_string(),
                dof: robot.dof(),
            },
            model: ModelStatus {
                loaded: model.is_some(),
                name: model.as_ref().map(|m| m.name().to_string()),
                source: model.map(|m| public_source(m.source())),
            },
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_open_source_names_no_path() {
        assert_eq!(public_source("shipped"), "shipped");
        assert_eq!(public_source("/home/me/models/my-model"), "my-model");
        assert_eq!(public_source("/home/me/models/my-model/"), "my-model");
        assert_eq!(public_source("models/rgb-only"), "rgb-only");
    }
}
