//! The route table: one file per endpoint. [`table`] is the single list the
//! router is built from, so the contract test can compare it with
//! `api/openapi.yaml`.

use super::state::AppState;
use axum::http::Method;
use axum::routing::{get, post, MethodRouter};

pub mod health;
pub mod metrics;
pub mod models;
pub mod moveit;
pub mod optimize;
pub mod plan;
pub mod robot;

/// One route: method, path template, and whether the bearer token (when
/// configured) is required.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RouteSpec {
    /// HTTP method.
    pub method: Method,
    /// Path as written in the router and in `api/openapi.yaml`.
    pub path: &'static str,
    /// Requires the bearer token when one is configured.
    pub protected: bool,
}

fn spec(method: Method, path: &'static str, protected: bool) -> RouteSpec {
    RouteSpec {
        method,
        path,
        protected,
    }
}

/// Every route with its handler. `/healthz` and `/readyz` stay open for
/// orchestrator probes; everything else is protected.
pub fn table() -> Vec<(RouteSpec, MethodRouter<AppState>)> {
    vec![
        (
            spec(Method::POST, "/v1/optimize", true),
            post(optimize::optimize),
        ),
        (spec(Method::POST, "/v1/plan", true), post(plan::plan)),
        (
            spec(Method::POST, "/v1/moveit/plan", true),
            post(moveit::plan),
        ),
        (spec(Method::GET, "/v1/robot", true), get(robot::robot)),
        (spec(Method::GET, "/v1/models", true), get(models::models)),
        (spec(Method::GET, "/healthz", false), get(health::healthz)),
        (spec(Method::GET, "/readyz", false), get(health::readyz)),
        (spec(Method::GET, "/metrics", true), get(metrics::metrics)),
    ]
}

/// The route specs of [`table`] without handlers.
pub fn specs() -> Vec<RouteSpec> {
    table().into_iter().map(|(s, _)| s).collect()
}
