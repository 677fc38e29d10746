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
//! (no `Value` is built); each object keeps only its own key set.

use serde::de::{DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use std::collections::HashSet;
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

/// The first duplicate object key in `bytes`, if any. Bytes that are not
/// JSON give `None` here: the typed parse that follows reports them.
pub fn find_duplicate_key(bytes: &[u8]) -> Option<DuplicateKey> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let mut found = None;
    let walk = Walk {
        path: String::new(),
        found: &mut found,
    };
    let _ = walk.deserialize(&mut de);
    found
}

/// One value being walked, at `path`; the first duplicate goes to `found`.
struct Walk<'a> {
    path: String,
    found: &'a mut Option<DuplicateKey>,
}

/// Aborts the walk once a duplicate is found.
#[derive(Debug)]
struct Stop;

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("duplicate key")
    }
}

fn stop<E: serde::de::Error>() -> E {
    E::custom(Stop)
}

impl<'de> DeserializeSeed<'de> for Walk<'_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        deserializer.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_> {
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
                path: format!("{}[{index}]", self.path),
                found: &mut *self.found,
            };
            if seq.next_element_seed(item)?.is_none() {
                return Ok(());
            }
            index += 1;
        }
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut keys = HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            let path = if self.path.is_empty() {
                key.clone()
            } else {
                format!("{}.{key}", self.path)
            };
            if !keys.insert(key.clone()) {
                *self.found = Some(DuplicateKey { path, key });
                return Err(stop());
            }
            map.next_value_seed(Walk {
                path,
                found: &mut *self.found,
            })?;
        }
        Ok(())
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
    }
}
