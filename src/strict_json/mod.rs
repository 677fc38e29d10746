//! Strict JSON input: what every JSON body the service reads and every
//! request file the CLI reads goes through besides its typed parse.
//!
//! - **Duplicate keys** ([`find_duplicate_key`]). RFC 8259 leaves duplicate
//!   names undefined, and serde_json's `Value` keeps the last one silently:
//!   `{"target_box": [..], "target_box": [..]}` would plan for whichever box
//!   came second. Duplicates are refused with the JSON path of the object
//!   that holds them, on every route alike. The scan ([`duplicates`]) is one
//!   pass linear in the bytes: a long key over many array elements costs its
//!   bytes, not their product; [`find_duplicate_key_until`] also stops when
//!   its caller says so (a request's deadline), asked every
//!   [`VALUES_PER_STOP_CHECK`] values.
//! - **Capped sequences** ([`AtMost`]): a typed parse that refuses the first
//!   item beyond a length, so a body's memory is bounded by its caps.
//! - **Messages in the reader's terms** ([`message_of`]): serde's Rust type
//!   names spelled as the JSON to send.

mod bounded;
mod duplicates;
mod messages;

pub use bounded::{option_vec_at_most, vec_at_most, AtMost};
pub use messages::{message_of, without_type_names};

use std::fmt;

/// The first duplicate key of a JSON document.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DuplicateKey {
    /// JSON path of the duplicated member (`obstacles[2].radius`).
    pub path: String,
    /// The key that appears twice.
    pub key: String,
}

impl fmt::Display for DuplicateKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the key {:?} appears more than once in the same object",
            self.key
        )
    }
}

/// Why [`find_duplicate_key_until`] gave up before the end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stopped;

/// How many values the walk reads between two calls of its stop test.
pub const VALUES_PER_STOP_CHECK: usize = 1 << 14;

/// The first duplicate object key in `bytes`, if any. Bytes that are not
/// JSON give `None` here: the typed parse that follows reports them.
pub fn find_duplicate_key(bytes: &[u8]) -> Option<DuplicateKey> {
    // Never stopped: the walk runs to the end.
    find_duplicate_key_until(bytes, &|| false).unwrap_or_default()
}

/// [`find_duplicate_key`], giving up with [`Stopped`] once `stop()` is true
/// (asked every [`VALUES_PER_STOP_CHECK`] values).
pub fn find_duplicate_key_until(
    bytes: &[u8],
    stop: &dyn Fn() -> bool,
) -> Result<Option<DuplicateKey>, Stopped> {
    duplicates::scan(bytes, stop)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_first_duplicate_with_its_path() {
        assert_eq!(
            find_duplicate_key(br#"{"a": 1, "b": {"c": [1, {"d": 2}]}}"#),
            None
        );
        let d =
            find_duplicate_key(br#"{"target_box": [1,2,3,4], "target_box": [5,6,7,8]}"#).unwrap();
        assert_eq!(
            (d.path.as_str(), d.key.as_str()),
            ("target_box", "target_box")
        );
        let d = find_duplicate_key(br#"{"obstacles": [{}, {"radius": 1, "radius": 2}]}"#).unwrap();
        assert_eq!(d.path, "obstacles[1].radius");
        // Same key in sibling objects is fine.
        assert_eq!(find_duplicate_key(br#"[{"a": 1}, {"a": 2}]"#), None);
        // Escaped spellings of one key are the same key.
        assert!(find_duplicate_key(br#"{"a": 1, "\u0061": 2}"#).is_some());
        // Not JSON: left to the typed parse.
        assert_eq!(find_duplicate_key(b"{"), None);
        // A duplicate deep inside arrays of a long key names its place.
        let d = find_duplicate_key(br#"{"k": [[0, 1], [{"x": 1, "x": 2}]]}"#).unwrap();
        assert_eq!(d.path, "k[1][0].x");
    }

    #[test]
    fn messages_name_json_not_rust_types() {
        assert_eq!(
            without_type_names("invalid type: sequence, expected struct WireRequest"),
            "invalid type: sequence, expected an object"
        );
        assert_eq!(
            without_type_names("invalid type: integer `5`, expected enum Boundary"),
            "invalid type: integer `5`, expected one of its allowed strings"
        );
        assert_eq!(
            without_type_names("expected tuple struct Numbers or struct Goal"),
            "expected an object or an object"
        );
        assert_eq!(
            without_type_names("invalid length 0, expected struct WireRequest with 17 elements"),
            "invalid length 0, expected an object"
        );
        // Lower-case words after "struct" are prose, left alone.
        assert_eq!(without_type_names("a struct of sorts"), "a struct of sorts");
        let e = serde_json::from_str::<Vec<u8>>("[1, 2").unwrap_err();
        assert_eq!(message_of(&e), "EOF while parsing a list");
    }

    #[test]
    fn the_walk_stops_when_its_caller_says_so() {
        let doc = format!("[{}0]", "0,".repeat(3 * VALUES_PER_STOP_CHECK));
        assert_eq!(
            find_duplicate_key_until(doc.as_bytes(), &|| true),
            Err(Stopped)
        );
        assert_eq!(
            find_duplicate_key_until(doc.as_bytes(), &|| false),
            Ok(None)
        );
        let calls = std::cell::Cell::new(0);
        let counted = || {
            calls.set(calls.get() + 1);
            false
        };
        find_duplicate_key_until(doc.as_bytes(), &counted).unwrap();
        // 3 x the interval of zeros plus the array itself: three checks.
        assert_eq!(calls.get(), 3);
    }
}
