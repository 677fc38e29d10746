//! Request layers every route passes through first.
//!
//! - [`stamp_arrival`]: the instant the request's headers were in, as an
//!   [`Arrival`] extension; a request's deadline counts from it, so the
//!   time spent reading the body, waiting for a solver and decoding is all
//!   inside the deadline.
//! - [`shutdown_gate`]: once a shutdown has begun, every route but
//!   `/healthz` and `/readyz` answers 503 `shutting_down`, and every answer
//!   carries `connection: close`.

use crate::service::error::ApiError;
use crate::service::state::AppState;
use axum::extract::{Request, State};
use axum::http::{header, HeaderValue};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::time::Instant;

/// When a request arrived (its headers were read).
#[derive(Clone, Copy, Debug)]
pub struct Arrival(pub Instant);

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
