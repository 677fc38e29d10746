//! The one error type of the HTTP layer, [`ApiError`], answered as
//! `{"error": {"code", "message", "field"}}` with a 4xx (or 503) status.
//!
//! | status | codes |
//! |---|---|
//! | 400 | `malformed_json`, `malformed_multipart`, `malformed_image`, `malformed_base64`, `malformed_body`, `malformed_request` (not HTTP/1.1) |
//! | 401 | `unauthorized` |
//! | 404 | `not_found` |
//! | 405 | `method_not_allowed` |
//! | 408 | `body_timeout`, `header_timeout` (written by the accept loop, [`super::server::json_errors`]) |
//! | 413 | `body_too_large`, `image_too_large` |
//! | 414 | `uri_too_long` |
//! | 415 | `unsupported_media_type`, `unsupported_image_format` |
//! | 422 | `invalid_input`, `infeasible`, `numerical` |
//! | 429 | `overloaded` |
//! | 431 | `headers_too_large` |
//! | 500 | `internal` (a bug, logged; the answer never carries its text), `model_error` (the loaded model produced an invalid prior) |
//! | 503 | `deadline_exceeded`, `model_unavailable`, `shutting_down`, `too_many_connections` |
//!
//! The 400/414/431 answers for requests hyper cannot parse and the 503
//! `too_many_connections` are written by the accept loop
//! ([`super::server`]) in the same shape.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Serialize;

/// An error answered to an HTTP client.
#[derive(Clone, Debug, PartialEq)]
pub struct ApiError {
    /// HTTP status.
    pub status: StatusCode,
    /// Machine-readable code (see the module table).
    pub code: &'static str,
    /// Human-readable explanation.
    pub message: String,
    /// The offending field as a JSON path (`obstacles[2].radius`), if any.
    pub field: Option<String>,
}

/// The JSON body `{"error": {...}}`.
#[derive(Serialize)]
struct Body<'a> {
    error: Detail<'a>,
}

#[derive(Serialize)]
struct Detail<'a> {
    code: &'a str,
    message: &'a str,
    field: Option<&'a str>,
}

impl ApiError {
    /// A new error without a field.
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        ApiError {
            status,
            code,
            message: message.into(),
            field: None,
        }
    }

    /// Attach the offending field (empty paths are dropped).
    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        let field = field.into();
        self.field = (!field.is_empty() && field != ".").then_some(field);
        self
    }

    /// 422 `invalid_input` naming `field`.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_input", message).with_field(field)
    }

    /// 400 for a body that is not valid JSON.
    pub fn malformed_json(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "malformed_json", message)
    }

    /// 413 for a body over the limit.
    pub fn body_too_large(limit: usize) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "body_too_large",
            format!("the request body exceeds the limit of {limit} bytes"),
        )
    }

    /// 415 for a content type the endpoint does not take.
    pub fn unsupported_media_type(expected: &str) -> Self {
        Self::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            format!("expected Content-Type {expected}"),
        )
    }

    /// 401 for a missing or wrong bearer token (never echoes the token).
    pub fn unauthorized() -> Self {
        Self::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "a valid `Authorization: Bearer <token>` header is required",
        )
    }

    /// 404 for an unknown route.
    pub fn not_found() -> Self {
        Self::new(StatusCode::NOT_FOUND, "not_found", "no such route")
    }

    /// 405 for a known route with another method.
    pub fn method_not_allowed() -> Self {
        Self::new(
            StatusCode::METHOD_NOT_ALLOWED,
            "method_not_allowed",
            "this route does not accept that method",
        )
    }

    /// 429 when the queue of waiting requests is full.
    pub fn overloaded() -> Self {
        Self::new(
            StatusCode::TOO_MANY_REQUESTS,
            "overloaded",
            "too many requests are waiting for a solver; retry later",
        )
    }

    /// 503 when the deadline passed before an answer was ready.
    pub fn deadline_exceeded(message: impl Into<String>) -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "deadline_exceeded",
            message,
        )
    }

    /// 503 when no network model is loaded.
    pub fn model_unavailable() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "model_unavailable",
            "no network model is loaded: start `dpmp serve --model DIR` with a trained model \
             (see the README's training section); /v1/optimize works without one",
        )
    }

    /// 500 for a bug (a solver task that panicked). The message is the
    /// server's own words, never a panic's text.
    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", message)
    }

    /// 500 when the loaded model's output is not a valid prior (a model
    /// fault, not the client's).
    pub fn model_error(message: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, "model_error", message)
    }

    /// 503 once a graceful shutdown has begun.
    pub fn shutting_down() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "shutting_down",
            "the service is shutting down; retry on another instance or after the restart",
        )
    }

    /// 408 when the body did not arrive within `body_read_timeout`.
    pub fn body_timeout(timeout: std::time::Duration) -> Self {
        Self::new(
            StatusCode::REQUEST_TIMEOUT,
            "body_timeout",
            format!(
                "the request body did not arrive within {} ms",
                timeout.as_millis()
            ),
        )
    }
}

impl From<crate::Error> for ApiError {
    fn from(e: crate::Error) -> Self {
        use crate::Error;
        let status = match &e {
            Error::Invalid { .. }
            | Error::Infeasible(_)
            | Error::Numerical(_)
            | Error::Unsolved(_) => StatusCode::UNPROCESSABLE_ENTITY,
            Error::Cancelled(_) => StatusCode::SERVICE_UNAVAILABLE,
            Error::File { .. } | Error::Write { .. } | Error::Model(_) => {
                StatusCode::INTERNAL_SERVER_ERROR
            }
        };
        let code = match &e {
            Error::Cancelled(_) => "deadline_exceeded",
            Error::File { .. } | Error::Write { .. } => "internal",
            other => other.code(),
        };
        let message = match &e {
            Error::Invalid { message, .. } => message.clone(),
            other => other.to_string(),
        };
        let field = e.field().map(str::to_string).unwrap_or_default();
        ApiError::new(status, code, message).with_field(field)
    }
}

/// Longest message (bytes) an answer carries; a message that quotes a
/// client's over-long key or id is cut there.
pub const MAX_MESSAGE_BYTES: usize = 1024;

/// Longest `field` (bytes) an answer carries.
pub const MAX_FIELD_BYTES: usize = 256;

/// `text` cut to at most `max` bytes (on a character boundary), saying how
/// long it was.
fn shortened(text: &str, max: usize) -> std::borrow::Cow<'_, str> {
    if text.len() <= max {
        return text.into();
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}… ({} bytes in all)", &text[..end], text.len()).into()
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let message = shortened(&self.message, MAX_MESSAGE_BYTES);
        let field = self.field.as_deref().map(|f| shortened(f, MAX_FIELD_BYTES));
        let body = Body {
            error: Detail {
                code: self.code,
                message: &message,
                field: field.as_deref(),
            },
        };
        let mut response = (self.status, Json(body)).into_response();
        if self.status == StatusCode::UNAUTHORIZED {
            response.headers_mut().insert(
                axum::http::header::WWW_AUTHENTICATE,
                axum::http::HeaderValue::from_static("Bearer"),
            );
        }
        response
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}: {}",
            self.status.as_u16(),
            self.code,
            self.message
        )?;
        if let Some(field) = &self.field {
            write!(f, " (field {field})")?;
        }
        Ok(())
    }
}

impl std::error::Error for ApiError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crate_errors_map_to_4xx_with_field() {
        let e: ApiError = crate::Error::invalid("obstacles[1].radius", "must be positive").into();
        assert_eq!(e.status, StatusCode::UNPROCESSABLE_ENTITY);
        assert_eq!(e.code, "invalid_input");
        assert_eq!(e.field.as_deref(), Some("obstacles[1].radius"));
        assert_eq!(e.message, "must be positive");
        let e: ApiError = crate::Error::Infeasible("start in collision".into()).into();
        assert_eq!((e.status.as_u16(), e.code), (422, "infeasible"));
        let e: ApiError = crate::Error::Cancelled("deadline".into()).into();
        assert_eq!((e.status.as_u16(), e.code), (503, "deadline_exceeded"));
    }

    #[tokio::test]
    async fn quoted_client_text_is_cut_to_a_bounded_answer() {
        let key = "é".repeat(1 << 20);
        let e = ApiError::invalid(key.clone(), format!("unknown field `{key}`"));
        let bytes = axum::body::to_bytes(e.into_response().into_body(), 1 << 16)
            .await
            .unwrap();
        assert!(
            bytes.len() < 2 * (MAX_MESSAGE_BYTES + MAX_FIELD_BYTES),
            "{}",
            bytes.len()
        );
        let v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        let message = v["error"]["message"].as_str().unwrap();
        assert!(
            message.ends_with(&format!("… ({} bytes in all)", key.len() + 16)),
            "{message}"
        );
    }

    #[tokio::test]
    async fn body_is_the_documented_json_shape() {
        let response = ApiError::invalid("start[2]", "must be finite").into_response();
        assert_eq!(response.status(), StatusCode::UNPROCESSABLE_ENTITY);
        let bytes = axum::body::to_bytes(response.into_body(), 1 << 16)
            .await
            .unwrap();
        let v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"error": {"code": "invalid_input", "message": "must be finite", "field": "start[2]"}})
        );
    }
}
