//! Duplicate object keys in JSON input.
//!
//! RFC 8259 leaves duplicate names undefined, and serde_json's `Value` keeps
//! the last one silently: `{"target_box": [..], "target_box": [..]}` would
//! plan for whichever box came second. Every JSON body the service reads
//! and every request file the CLI reads goes through [`find_duplicate_key`]
//! first, so duplicates are refused with the JSON path of the object that
//! holds them, on every route alike.
//!
//! The walk is one streaming pass of serde's deserializer over the bytes
//! (no `Value` is built), linear in the size of the document: each object
//! keeps only its own key set (keys borrowed from the input where they have
//! no escapes), and a value's place is a link to its parent's ([`Place`]),
//! so the JSON path is spelled out only for the duplicate that is reported.
//! A long key over many array elements therefore costs what its bytes cost,
//! not their product. [`find_duplicate_key_until`] also stops when its
//! caller says so (a request's deadline), checked every
//! [`VALUES_PER_STOP_CHECK`] values.

mod bounded;

pub use bounded::{option_vec_at_most, vec_at_most, AtMost};

use serde::de::{DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use std::borrow::Cow;
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
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let mut walk = WalkState {
        found: None,
        stopped: false,
        values: 0,
        stop,
    };
    let _ = Walk {
        place: Place::Root,
        state: &mut walk,
    }
    .deserialize(&mut de);
    if walk.stopped {
        return Err(Stopped);
    }
    Ok(walk.found)
}

/// A serde_json error's message in the reader's terms: without its " at
/// line L column C" (for errors in a part of a document re-read on its own,
/// where that position means nothing) and without the Rust type names serde
/// puts in its "expected ..." (`struct WireRequest` is "an object").
pub fn message_of(e: &serde_json::Error) -> String {
    let text = e.to_string();
    let text = match text.rfind(" at line ") {
        Some(i) => &text[..i],
        None => &text,
    };
    without_type_names(text)
}

/// `text` with serde's `struct Name` / `enum Name` spelled as the JSON the
/// reader must send.
pub fn without_type_names(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    loop {
        let found = [
            ("struct ", "an object"),
            ("enum ", "one of its allowed strings"),
        ]
        .iter()
        .filter_map(|(word, words)| rest.find(word).map(|i| (i, *word, *words)))
        .min_by_key(|(i, ..)| *i);
        let Some((i, word, words)) = found else {
            out.push_str(rest);
            return out;
        };
        let after = &rest[i + word.len()..];
        let name_len = after
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(after.len());
        let starts_a_type_name = after.starts_with(|c: char| c.is_ascii_uppercase());
        let word_starts = i == 0 || rest[..i].ends_with(' ');
        if starts_a_type_name && word_starts {
            let before = rest[..i]
                .trim_end_matches("untagged ")
                .trim_end_matches("tuple ");
            out.push_str(before);
            out.push_str(words);
            rest = without_arity(&after[name_len..]);
        } else {
            out.push_str(&rest[..i + word.len()]);
            rest = after;
        }
    }
}

/// `text` without a leading " with N element(s)" (serde's arity of a
/// struct read from an array, meaningless for an object).
fn without_arity(text: &str) -> &str {
    let Some(rest) = text.strip_prefix(" with ") else {
        return text;
    };
    let digits = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    if digits == 0 {
        return text;
    }
    let after = &rest[digits..];
    after
        .strip_prefix(" elements")
        .or_else(|| after.strip_prefix(" element"))
        .unwrap_or(text)
}

/// Where a value sits: the document itself, a member of an object or an
/// element of an array, each linked to its parent's place.
#[derive(Clone, Copy)]
enum Place<'p> {
    Root,
    Member(&'p Place<'p>, &'p str),
    Element(&'p Place<'p>, usize),
}

impl Place<'_> {
    /// The JSON path of this place (`obstacles[1].radius`; empty at the
    /// root).
    fn path(&self) -> String {
        match self {
            Place::Root => String::new(),
            Place::Member(parent, key) => match parent.path() {
                p if p.is_empty() => (*key).to_string(),
                p => format!("{p}.{key}"),
            },
            Place::Element(parent, index) => format!("{}[{index}]", parent.path()),
        }
    }
}

/// What the whole walk shares: the first duplicate, the stop test and its
/// counter.
struct WalkState<'s> {
    found: Option<DuplicateKey>,
    stopped: bool,
    values: usize,
    stop: &'s dyn Fn() -> bool,
}

impl WalkState<'_> {
    /// Count one value; false once the caller wants the walk stopped.
    fn go_on(&mut self) -> bool {
        self.values += 1;
        if self.values.is_multiple_of(VALUES_PER_STOP_CHECK) && (self.stop)() {
            self.stopped = true;
        }
        !self.stopped
    }
}

/// One value being walked, at `place`.
struct Walk<'p, 's, 'w> {
    place: Place<'p>,
    state: &'w mut WalkState<'s>,
}

/// Aborts the walk (a duplicate found, or the caller's stop).
#[derive(Debug)]
struct Stop;

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("walk stopped")
    }
}

fn stop<E: serde::de::Error>() -> E {
    E::custom(Stop)
}

impl<'de> DeserializeSeed<'de> for Walk<'_, '_, '_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        if !self.state.go_on() {
            return Err(stop());
        }
        deserializer.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_, '_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut index = 0usize;
        loop {
            let item = Walk {
                place: Place::Element(&self.place, index),
                state: &mut *self.state,
            };
            if seq.next_element_seed(item)?.is_none() {
                return Ok(());
            }
            index += 1;
        }
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut keys = KeySet::default();
        while let Some(key) = map.next_key_seed(KeySeed)? {
            if keys.contains(&key) {
                let path = Place::Member(&self.place, &key).path();
                self.state.found = Some(DuplicateKey {
                    path,
                    key: key.into_owned(),
                });
                return Err(stop());
            }
            map.next_value_seed(Walk {
                place: Place::Member(&self.place, &key),
                state: &mut *self.state,
            })?;
            keys.insert(key);
        }
        Ok(())
    }
}

/// The keys of one object: a list while short (most objects have a handful
/// of keys), a hash set beyond [`KeySet::LIST_MAX`].
#[derive(Default)]
struct KeySet<'de> {
    list: Vec<Cow<'de, str>>,
    set: std::collections::HashSet<Cow<'de, str>>,
}

impl<'de> KeySet<'de> {
    const LIST_MAX: usize = 16;

    fn contains(&self, key: &str) -> bool {
        if self.list.len() < Self::LIST_MAX {
            self.list.iter().any(|k| k == key)
        } else {
            self.set.contains(key)
        }
    }

    fn insert(&mut self, key: Cow<'de, str>) {
        if self.list.len() < Self::LIST_MAX {
            self.list.push(key);
            if self.list.len() == Self::LIST_MAX {
                self.set.extend(self.list.iter().cloned());
            }
        } else {
            self.set.insert(key);
        }
    }
}

/// An object key, borrowed from the input where it has no escapes.
struct KeySeed;

impl<'de> DeserializeSeed<'de> for KeySeed {
    type Value = Cow<'de, str>;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for KeySeed {
    type Value = Cow<'de, str>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an object key")
    }

    fn visit_borrowed_str<E>(self, v: &'de str) -> Result<Self::Value, E> {
        Ok(Cow::Borrowed(v))
    }

    fn visit_str<E>(self, v: &str) -> Result<Self::Value, E> {
        Ok(Cow::Owned(v.to_string()))
    }
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
