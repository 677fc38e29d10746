//! Request layers every route passes through first.
//!
//! - [`stamp_arrival`]: the instant the request's headers were in, as an
//!   [`Arrival`] extension; a request's deadline counts from it, so the
//!   time spent reading the body, waiting for a solver and decoding is all
//!   inside the deadline.
//! - [`track`]: every request counted in the metrics by its route template.
//! - [`shutdown_gate`]: once a shutdown has begun, every route but
//!   `/healthz` and `/readyz` answers 503 `shutting_down`, and every answer
//!   carries `connection: close`.

use crate::service::error::ApiError;
use crate::service::state::{AppState, Arrival};
use axum::extract::{MatchedPath, Request, State};
use axum::http::{header, HeaderValue};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::time::Instant;

/// Routes that keep answering during a shutdown (probes).
const PROBES: [&str; 2] = ["/healthz", "/readyz"];

/// Record the request's [`Arrival`].
pub async fn stamp_arrival(mut request: Request, next: Next) -> Response {
    request.extensions_mut().insert(Arrival(Instant::now()));
    next.run(request).await
}

/// Refuse work once a shutdown has begun (see the module docs).
pub async fn shutdown_gate(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Response {
    if !state.is_shutting_down() {
        return next.run(request).await;
    }
    let mut response = if PROBES.contains(&request.uri().path()) {
        next.run(request).await
    } else {
        ApiError::shutting_down().into_response()
    };
    response
        .headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
    response
}

/// Middleware: count every request by its route template (never the raw
/// path, so label cardinality stays bounded; unknown routes count as
/// `unmatched`).
pub async fn track(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| "unmatched".to_string());
    let method = request.method().as_str().to_string();
    let response = next.run(request).await;
    let status = response.status().as_u16();
    let seconds = started.elapsed().as_secs_f64();
    state
        .metrics()
        .record_request(&route, &method, status, seconds);
    tracing::info!(route = %route, method = %method, status, ms = seconds * 1e3, "request");
    response
}
