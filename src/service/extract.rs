//! Request bodies read and parsed with the service's own error mapping
//! (axum's rejections are never answered as they are):
//!
//! - wrong or missing `Content-Type` → 415 `unsupported_media_type`;
//! - body over the limit → 413 `body_too_large`;
//! - bytes that are not JSON (syntax, truncation, trailing data, nesting
//!   deeper than 128, numbers out of range) → 400 `malformed_json`;
//! - JSON of the wrong shape (unknown field, wrong type, missing field, a
//!   key twice in one object) → 422 `invalid_input` with the JSON path of
//!   the field;
//! - a body that does not arrive in time → 408 `body_timeout`, or 503 at
//!   the deadline ([`within_body_time`]).
//!
//! Handlers read the bytes on the async runtime and parse them inside the
//! request's job on the blocking pool ([`super::limits`]).

use super::error::ApiError;
use axum::body::Bytes;
use axum::extract::{FromRequest, Request};
use axum::http::header::CONTENT_TYPE;
use axum::http::{HeaderMap, StatusCode};
use serde::de::DeserializeOwned;
use std::future::Future;
use std::time::{Duration, Instant};

/// The request media types the service reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MediaType {
    /// `application/json` (or any `application/*+json`).
    Json,
    /// `multipart/form-data`.
    Multipart,
}

/// The media type of a request, or `None` when absent or another type.
pub fn media_type(headers: &HeaderMap) -> Option<MediaType> {
    let value = headers.get(CONTENT_TYPE)?.to_str().ok()?;
    let essence = value.split(';').next()?.trim().to_ascii_lowercase();
    if essence == "application/json"
        || (essence.starts_with("application/") && essence.ends_with("+json"))
    {
        Some(MediaType::Json)
    } else if essence == "multipart/form-data" {
        Some(MediaType::Multipart)
    } else {
        None
    }
}

/// Buffer the whole body under the configured limit
/// ([`axum::extract::DefaultBodyLimit`]).
pub async fn read_body<S: Send + Sync>(request: Request, state: &S) -> Result<Bytes, ApiError> {
    Bytes::from_request(request, state)
        .await
        .map_err(|rejection| {
            if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::new(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    "body_too_large",
                    rejection.body_text(),
                )
            } else {
                ApiError::new(
                    StatusCode::BAD_REQUEST,
                    "malformed_body",
                    rejection.body_text(),
                )
            }
        })
}

/// `read` (a body being received) bounded in time: by the request's
/// `deadline` (then 503 `deadline_exceeded`) and by `timeout` from now
/// (then 408 `body_timeout`), whichever comes first.
pub async fn within_body_time<T>(
    deadline: Instant,
    timeout: Duration,
    read: impl Future<Output = Result<T, ApiError>>,
) -> Result<T, ApiError> {
    let slow = Instant::now() + timeout;
    match tokio::time::timeout_at(deadline.min(slow).into(), read).await {
        Ok(result) => result,
        Err(_) if deadline <= slow => Err(ApiError::deadline_exceeded(
            "the deadline passed while the request body was still arriving",
        )),
        Err(_) => Err(ApiError::body_timeout(timeout)),
    }
}

/// Parse JSON bytes into `T`: syntax errors → 400 `malformed_json`, shape
/// errors and duplicate keys → 422 `invalid_input` naming the JSON path.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    parse_json_until(bytes, &|| false)
}

/// [`parse_json`] inside a request's job: the duplicate-key walk gives up
/// with 503 `deadline_exceeded` once `stop()` says the job is over (the
/// typed parse that follows is linear in the body and has no such check).
pub fn parse_json_until<T: DeserializeOwned>(
    bytes: &[u8],
    stop: &dyn Fn() -> bool,
) -> Result<T, ApiError> {
    match crate::strict_json::find_duplicate_key_until(bytes, stop) {
        Ok(None) => {}
        Ok(Some(d)) => return Err(ApiError::invalid(d.path.clone(), d.to_string())),
        Err(crate::strict_json::Stopped) => {
            return Err(ApiError::deadline_exceeded(
                "the deadline passed while the request body was being read",
            ))
        }
    }
    parse_typed(bytes)
}

/// The typed half of [`parse_json`], for bytes already checked for
/// duplicate keys.
pub fn parse_typed<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value = serde_path_to_error::deserialize(&mut de).map_err(|e| path_error(e, bytes))?;
    de.end().map_err(|e| {
        ApiError::malformed_json(format!("trailing data after the JSON value: {e}"))
    })?;
    Ok(value)
}

/// One member of an already parsed body (`field`, its raw JSON text) as
/// `T`; errors name `field` and the path inside it (`camera.fx`).
pub fn parse_member<T: DeserializeOwned>(
    field: &str,
    raw: &serde_json::value::RawValue,
) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_str(raw.get());
    serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let inner = e.path().to_string();
        let message = crate::strict_json::message_of(e.inner());
        let path = match inner.as_str() {
            "" | "." => field.to_string(),
            p if p.starts_with('[') => format!("{field}{p}"),
            p => format!("{field}.{p}"),
        };
        ApiError::invalid(field_of(&path, &message), message)
    })
}

/// The field an error is about: serde's path, and for a missing field the
/// field itself (serde reports the object that lacks it: `.` at the top).
fn field_of(path: &str, message: &str) -> String {
    let missing = message
        .strip_prefix("missing field `")
        .and_then(|rest| rest.split('`').next());
    match missing {
        Some(name) if path.is_empty() || path == "." => name.to_string(),
        Some(name) => format!("{path}.{name}"),
        None => path.to_string(),
    }
}

/// The answer for a failed typed parse of `bytes`. serde_json classes a
/// few type errors as syntax (a number where an enum's name goes: "expected
/// value"); when the bytes are valid JSON it is the value that is wrong, so
/// the answer is 422 naming the field, not 400.
fn path_error(e: serde_path_to_error::Error<serde_json::Error>, bytes: &[u8]) -> ApiError {
    use serde_json::error::Category;
    let field = e.path().to_string();
    let inner = e.into_inner();
    match inner.classify() {
        Category::Data => {
            let message = crate::strict_json::message_of(&inner);
            ApiError::invalid(field_of(&field, &message), message)
        }
        Category::Syntax
            if inner.to_string().starts_with("expected value")
                && serde_json::from_slice::<serde::de::IgnoredAny>(bytes).is_ok() =>
        {
            ApiError::invalid(
                field,
                "not a value this field takes: see its type in api/openapi.yaml",
            )
        }
        Category::Syntax | Category::Eof | Category::Io => {
            ApiError::malformed_json(format!("the body is not valid JSON: {inner}"))
        }
    }
}

/// The members of a JSON object body, each kept as its raw JSON text and
/// parsed on its own into its type: no value tree is built, so a body's
/// memory is its size plus what its typed fields hold.
pub type Fields = std::collections::BTreeMap<String, Box<serde_json::value::RawValue>>;

/// The members as one JSON object's text (what remains once the route has
/// taken its own).
pub fn object_text(fields: &Fields) -> String {
    let mut text = String::from("{");
    for (i, (key, value)) in fields.iter().enumerate() {
        if i > 0 {
            text.push(',');
        }
        text.push_str(&serde_json::Value::from(key.as_str()).to_string());
        text.push(':');
        text.push_str(value.get());
    }
    text.push('}');
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;
    use serde::Deserialize;

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Thing {
        radius: f64,
        items: Vec<Inner>,
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Inner {
        id: String,
    }

    #[test]
    fn media_types_are_recognised() {
        let mut h = HeaderMap::new();
        assert_eq!(media_type(&h), None);
        for (v, want) in [
            ("application/json", Some(MediaType::Json)),
            ("Application/JSON; charset=utf-8", Some(MediaType::Json)),
            ("application/problem+json", Some(MediaType::Json)),
            (
                "multipart/form-data; boundary=x",
                Some(MediaType::Multipart),
            ),
            ("text/plain", None),
            ("application/jsonx", None),
        ] {
            h.insert(CONTENT_TYPE, HeaderValue::from_static(v));
            assert_eq!(media_type(&h), want, "{v}");
        }
    }

    #[test]
    fn syntax_errors_are_400_and_shape_errors_422_with_path() {
        for bad in [
            &b"{"[..],
            b"",
            b"{\"radius\": 1,}",
            b"{\"radius\": 1, \"items\": [",
            b"{\"radius\": 1, \"items\": []} x",
            b"\xff\xfe",
        ] {
            let e = parse_json::<Thing>(bad).unwrap_err();
            assert_eq!(
                (e.status.as_u16(), e.code),
                (400, "malformed_json"),
                "{bad:?}"
            );
        }
        let e = parse_json::<Thing>(br#"{"radius": "big", "items": []}"#).unwrap_err();
        assert_eq!(
            (e.status.as_u16(), e.field.as_deref()),
            (422, Some("radius"))
        );
        let e = parse_json::<Thing>(br#"{"radius": 1, "items": [{"id": "a"}, {"id": 3}]}"#)
            .unwrap_err();
        assert_eq!(e.field.as_deref(), Some("items[1].id"));
        let e = parse_json::<Thing>(br#"{"radius": 1, "items": [], "extra": 1}"#).unwrap_err();
        assert_eq!(e.status.as_u16(), 422);
        assert!(e.message.contains("extra"), "{}", e.message);
        let deep = "[".repeat(10_000);
        let e = parse_json::<serde_json::Value>(deep.as_bytes()).unwrap_err();
        assert_eq!(e.status.as_u16(), 400);
        let e = parse_json::<Thing>(br#"{"radius": 1e999, "items": []}"#).unwrap_err();
        assert_eq!(e.status.as_u16(), 400);
        // Valid JSON that serde_json's enum reading calls a syntax error.
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        enum Kind {
            Rest,
        }
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct WithKind {
            kind: Kind,
        }
        let e = parse_json::<WithKind>(br#"{"kind": 3}"#).unwrap_err();
        assert_eq!((e.status.as_u16(), e.field.as_deref()), (422, Some("kind")));
        let ok = parse_json::<Thing>(br#" {"radius": 2.5, "items": [{"id": "a"}]} "#).unwrap();
        assert_eq!(ok.radius, 2.5);
    }
}
