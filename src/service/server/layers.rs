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
//! - [`declared_length_gate`]: a request whose `content-length` declares
//!   more than the body limit is answered 413 `body_too_large` at once, from
//!   its head, without waiting for a body that would be refused anyway.

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

/// Answer 413 from the head when the declared body is over the limit (see
/// the module docs); the connection closes, since the body is never read.
pub async fn declared_length_gate(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Response {
    let limit = state.config().body_limit_bytes;
    if declared_length(request.headers()).is_some_and(|n| n > limit as u64) {
        let mut response = ApiError::body_too_large(limit).into_response();
        response
            .headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
        return response;
    }
    next.run(request).await
}

/// The body length a request's `content-length` header declares.
fn declared_length(headers: &axum::http::HeaderMap) -> Option<u64> {
    headers
        .get(header::CONTENT_LENGTH)?
        .to_str()
        .ok()?
        .trim()
        .parse()
        .ok()
}

/// The methods HTTP defines (RFC 9110 and PATCH): the `method` label's
/// values besides `other`.
const KNOWN_METHODS: [&str; 9] = [
    "GET", "HEAD", "POST", "PUT", "DELETE", "CONNECT", "OPTIONS", "TRACE", "PATCH",
];

/// The `method` label of a request: its method when HTTP defines it, else
/// `other` (a client may invent any token as a method; the label set must
/// stay closed).
pub fn method_label(method: &axum::http::Method) -> &'static str {
    KNOWN_METHODS
        .iter()
        .find(|known| **known == method.as_str())
        .copied()
        .unwrap_or("other")
}

/// Middleware: count every request by its route template and
/// [`method_label`] (never the raw path or method, so label cardinality
/// stays bounded; unknown routes count as `unmatched`).
pub async fn track(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| "unmatched".to_string());
    let method = method_label(request.method());
    let response = next.run(request).await;
    let status = response.status().as_u16();
    let seconds = started.elapsed().as_secs_f64();
    state
        .metrics()
        .record_request(&route, method, status, seconds);
    tracing::info!(route = %route, method = %method, status, ms = seconds * 1e3, "request");
    response
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::Method;

    #[test]
    fn method_labels_come_from_a_closed_set() {
        assert_eq!(method_label(&Method::POST), "POST");
        assert_eq!(method_label(&Method::PATCH), "PATCH");
        let invented = Method::from_bytes("X".repeat(60_000).as_bytes()).unwrap();
        assert_eq!(method_label(&invented), "other");
        assert_eq!(method_label(&Method::from_bytes(b"get").unwrap()), "other");
    }
}
