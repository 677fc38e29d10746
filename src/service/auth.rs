//! Optional bearer-token authentication: the middleware that checks a
//! request's `Authorization` header against the configured
//! [`Token`](super::token::Token).

use super::error::ApiError;
use super::state::AppState;
use axum::extract::{Request, State};
use axum::http::header::AUTHORIZATION;
use axum::middleware::Next;
use axum::response::Response;

/// Middleware: when a token is configured, require
/// `Authorization: Bearer <token>`; otherwise answer 401 `unauthorized`.
pub async fn require_token(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Result<Response, ApiError> {
    if let Some(token) = &state.config().token {
        let presented = request
            .headers()
            .get(AUTHORIZATION)
            .and_then(|v| bearer(v.as_bytes()));
        let ok = presented.is_some_and(|p| token.matches(p));
        if !ok {
            return Err(ApiError::unauthorized());
        }
    }
    Ok(next.run(request).await)
}

/// The credentials of a `Bearer` authorization header value.
fn bearer(value: &[u8]) -> Option<&[u8]> {
    let scheme = b"bearer ";
    if value.len() > scheme.len() && value[..scheme.len()].eq_ignore_ascii_case(scheme) {
        Some(value[scheme.len()..].trim_ascii())
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bearer_scheme_is_case_insensitive() {
        assert_eq!(bearer(b"Bearer abc"), Some(&b"abc"[..]));
        assert_eq!(bearer(b"bearer  abc "), Some(&b"abc"[..]));
        assert_eq!(bearer(b"Basic abc"), None);
        assert_eq!(bearer(b"Bearer "), None);
    }
}
