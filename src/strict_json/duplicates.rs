//! The duplicate-key scan: one pass over the bytes, linear in them.
//!
//! A hand-written scanner, not serde's deserializer: it never parses a
//! number (it skips to the next delimiter), compares keys as borrowed slices
//! of the input (unescaping only keys that hold a backslash), keeps each open
//! object's keys in place while they are few ([`KeySet`]), and keeps the
//! open containers on an explicit stack, so the JSON path is spelled out
//! only for the duplicate it reports. Input that is not JSON gives `None`:
//! the typed parse that follows reports it in its own words.

use super::{DuplicateKey, Stopped, VALUES_PER_STOP_CHECK};
use std::borrow::Cow;

/// Deepest nesting scanned (serde_json's own recursion limit); deeper input
/// is left to the typed parse, which refuses it.
const MAX_DEPTH: usize = 128;

/// See [`super::find_duplicate_key_until`].
pub(super) fn scan(bytes: &[u8], stop: &dyn Fn() -> bool) -> Result<Option<DuplicateKey>, Stopped> {
    let mut scanner = Scanner {
        bytes,
        at: 0,
        values: 0,
        stop,
        open: Vec::new(),
        keys: Vec::new(),
    };
    match scanner.document() {
        Ok(()) => Ok(None),
        Err(End::Duplicate(d)) => Ok(Some(d)),
        Err(End::Stopped) => Err(Stopped),
        Err(End::NotJson) => Ok(None),
    }
}

/// Why a scan ended early.
enum End {
    Duplicate(DuplicateKey),
    Stopped,
    NotJson,
}

/// An open container: an object (its keys so far are `keys[first..]` of
/// the scanner's key stack, the last being the member's being read), or an
/// array with the index being read.
enum Open {
    Object {
        first: usize,
        /// The same keys hashed, once the object has more than
        /// [`LINEAR_KEYS`].
        hashed: Option<std::collections::HashSet<String>>,
    },
    Array {
        index: usize,
    },
}

/// Keys an object is searched through one by one before they are hashed.
const LINEAR_KEYS: usize = 16;

struct Scanner<'a, 's> {
    bytes: &'a [u8],
    at: usize,
    values: usize,
    stop: &'s dyn Fn() -> bool,
    open: Vec<Open>,
    /// The keys of every open object, outermost first.
    keys: Vec<Cow<'a, str>>,
}

impl<'a> Scanner<'a, '_> {
    /// One value and nothing but whitespace after it.
    fn document(&mut self) -> Result<(), End> {
        self.value()?;
        self.skip_whitespace();
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(End::NotJson)
        }
    }

    /// Scan one value, iteratively through nested containers.
    fn value(&mut self) -> Result<(), End> {
        loop {
            self.count_value()?;
            self.skip_whitespace();
            match self.peek()? {
                b'{' => {
                    self.at += 1;
                    if self.open.len() == MAX_DEPTH {
                        return Err(End::NotJson);
                    }
                    self.skip_whitespace();
                    if self.peek()? == b'}' {
                        self.at += 1;
                    } else {
                        let key = self.key()?;
                        self.open.push(Open::Object {
                            first: self.keys.len(),
                            hashed: None,
                        });
                        self.keys.push(key);
                        continue;
                    }
                }
                b'[' => {
                    self.at += 1;
                    if self.open.len() == MAX_DEPTH {
                        return Err(End::NotJson);
                    }
                    self.skip_whitespace();
                    if self.peek()? == b']' {
                        self.at += 1;
                    } else {
                        self.open.push(Open::Array { index: 0 });
                        continue;
                    }
                }
                b'"' => {
                    self.skip_string()?;
                }
                _ => self.scalar()?,
            }
            // A value is complete: close the containers it completes, and
            // go on with the next member or element of the innermost open one.
            if self.after_value()? {
                return Ok(());
            }
        }
    }

    /// After a value: `,` opens the next member or element (false: scan
    /// it), `}` / `]` closes a container; true once nothing is open.
    fn after_value(&mut self) -> Result<bool, End> {
        loop {
            self.skip_whitespace();
            if self.open.is_empty() {
                return Ok(true);
            }
            let next = self.peek()?;
            self.at += 1;
            let Some(open) = self.open.last_mut() else {
                return Ok(true);
            };
            match (open, next) {
                (Open::Array { index }, b',') => {
                    *index += 1;
                    return Ok(false);
                }
                (Open::Object { .. }, b',') => {
                    self.skip_whitespace();
                    let key = self.key()?;
                    if self.seen(&key) {
                        self.keys.push(key.clone());
                        return Err(End::Duplicate(self.duplicate(key)));
                    }
                    self.keys.push(key);
                    return Ok(false);
                }
                (Open::Array { .. }, b']') => {
                    self.open.pop();
                }
                (Open::Object { first, .. }, b'}') => {
                    let first = *first;
                    self.keys.truncate(first);
                    self.open.pop();
                }
                _ => return Err(End::NotJson),
            }
        }
    }

    /// A member's key and its `:`.
    fn key(&mut self) -> Result<Cow<'a, str>, End> {
        if self.peek()? != b'"' {
            return Err(End::NotJson);
        }
        let key = self.string()?;
        self.skip_whitespace();
        if self.peek()? != b':' {
            return Err(End::NotJson);
        }
        self.at += 1;
        Ok(key)
    }

    /// Past a string (at its opening quote); whether it holds an escape.
    fn skip_string(&mut self) -> Result<bool, End> {
        self.at += 1;
        let mut escaped = false;
        loop {
            match self.bytes.get(self.at) {
                None => return Err(End::NotJson),
                Some(b'"') => break,
                Some(b'\\') => {
                    escaped = true;
                    self.at += 2;
                }
                Some(_) => self.at += 1,
            }
        }
        self.at += 1;
        Ok(escaped)
    }

    /// A key's string (at its opening quote): borrowed when it has no
    /// escape, else unescaped by serde_json.
    fn string(&mut self) -> Result<Cow<'a, str>, End> {
        let start = self.at;
        let escaped = self.skip_string()?;
        let raw = &self.bytes[start..self.at];
        if escaped {
            serde_json::from_slice::<String>(raw)
                .map(Cow::Owned)
                .map_err(|_| End::NotJson)
        } else {
            std::str::from_utf8(&raw[1..raw.len() - 1])
                .map(Cow::Borrowed)
                .map_err(|_| End::NotJson)
        }
    }

    /// A number or literal: its bytes up to the next delimiter (their
    /// grammar is the typed parse's to check).
    fn scalar(&mut self) -> Result<(), End> {
        let start = self.at;
        while let Some(&b) = self.bytes.get(self.at) {
            if matches!(b, b',' | b']' | b'}' | b' ' | b'\n' | b'\r' | b'\t') {
                break;
            }
            if !matches!(b, b'0'..=b'9' | b'-' | b'+' | b'.' | b'e' | b'E' | b'a'..=b'z') {
                return Err(End::NotJson);
            }
            self.at += 1;
        }
        if self.at == start {
            return Err(End::NotJson);
        }
        Ok(())
    }

    fn skip_whitespace(&mut self) {
        while matches!(self.bytes.get(self.at), Some(b' ' | b'\n' | b'\r' | b'\t')) {
            self.at += 1;
        }
    }

    fn peek(&self) -> Result<u8, End> {
        self.bytes.get(self.at).copied().ok_or(End::NotJson)
    }

    /// Count a value; ask the caller whether to go on every
    /// [`VALUES_PER_STOP_CHECK`] values.
    fn count_value(&mut self) -> Result<(), End> {
        self.values += 1;
        if self.values.is_multiple_of(VALUES_PER_STOP_CHECK) && (self.stop)() {
            return Err(End::Stopped);
        }
        Ok(())
    }

    /// Whether the innermost open object already has `key` (linear while
    /// it has few keys, then through a hash set built once).
    fn seen(&mut self, key: &str) -> bool {
        let Some(Open::Object { first, hashed }) = self.open.last_mut() else {
            return false;
        };
        let keys = &self.keys[*first..];
        if keys.len() <= LINEAR_KEYS {
            return keys.iter().any(|k| k == key);
        }
        let set = hashed.get_or_insert_with(|| keys.iter().map(|k| k.to_string()).collect());
        // The last key (the member just read) joins the set here.
        if let Some(last) = keys.last() {
            set.insert(last.to_string());
        }
        set.contains(key)
    }

    /// The report of `key` found twice in the innermost open object (it is
    /// the last on the key stack).
    fn duplicate(&self, key: Cow<'a, str>) -> DuplicateKey {
        let mut path = String::new();
        // Each open object's current member is its last key on the stack:
        // the one before the next object's first, or the stack's last.
        let firsts: Vec<usize> = self
            .open
            .iter()
            .filter_map(|o| match o {
                Open::Object { first, .. } => Some(*first),
                Open::Array { .. } => None,
            })
            .collect();
        let mut object = 0;
        for open in &self.open {
            match open {
                Open::Object { .. } => {
                    let end = firsts.get(object + 1).copied().unwrap_or(self.keys.len());
                    object += 1;
                    if !path.is_empty() {
                        path.push('.');
                    }
                    path.push_str(&self.keys[end - 1]);
                }
                Open::Array { index } => path.push_str(&format!("[{index}]")),
            }
        }
        DuplicateKey {
            path,
            key: key.into_owned(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A JSON tree whose objects keep their members in order, duplicates
    /// included (what serde_json's `Value` cannot hold).
    enum Tree {
        Number(String),
        Text(String),
        Array(Vec<Tree>),
        Object(Vec<(String, Tree)>),
    }

    fn random_tree(rng: &mut rand::rngs::StdRng, depth: usize) -> Tree {
        let keys = ["a", "b", "c", "\\u0061", "k\\\"q", "é"];
        match rng.gen_range(0..if depth > 3 { 2 } else { 4 }) {
            0 => Tree::Number(["0", "-1.5e3", "true", "null", "12"][rng.gen_range(0..5)].into()),
            1 => Tree::Text(["x", "", "a\\\"b", "{[,]}"][rng.gen_range(0..4)].into()),
            2 => Tree::Array(
                (0..rng.gen_range(0..4))
                    .map(|_| random_tree(rng, depth + 1))
                    .collect(),
            ),
            _ => Tree::Object(
                (0..rng.gen_range(0..4))
                    .map(|_| {
                        (
                            keys[rng.gen_range(0..keys.len())].to_string(),
                            random_tree(rng, depth + 1),
                        )
                    })
                    .collect(),
            ),
        }
    }

    fn text(tree: &Tree, out: &mut String, rng: &mut rand::rngs::StdRng) {
        let space = |out: &mut String, rng: &mut rand::rngs::StdRng| {
            if rng.gen_bool(0.3) {
                out.push_str(" \n");
            }
        };
        match tree {
            Tree::Number(n) => out.push_str(n),
            Tree::Text(t) => out.push_str(&format!("\"{t}\"")),
            Tree::Array(items) => {
                out.push('[');
                for (i, item) in items.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    space(out, rng);
                    text(item, out, rng);
                }
                out.push(']');
            }
            Tree::Object(members) => {
                out.push('{');
                for (i, (k, v)) in members.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    space(out, rng);
                    out.push_str(&format!("\"{k}\""));
                    space(out, rng);
                    out.push(':');
                    text(v, out, rng);
                }
                out.push('}');
            }
        }
    }

    /// The reference: the first duplicate in document order, by walking
    /// the tree (keys compared unescaped).
    fn first_duplicate(tree: &Tree, path: &str) -> Option<String> {
        let unescaped = |k: &str| serde_json::from_str::<String>(&format!("\"{k}\"")).unwrap();
        let join = |k: &str| {
            if path.is_empty() {
                k.to_string()
            } else {
                format!("{path}.{k}")
            }
        };
        match tree {
            Tree::Number(_) | Tree::Text(_) => None,
            Tree::Array(items) => items
                .iter()
                .enumerate()
                .find_map(|(i, item)| first_duplicate(item, &format!("{path}[{i}]"))),
            Tree::Object(members) => {
                let mut seen = Vec::new();
                for (k, v) in members {
                    let k = unescaped(k);
                    if seen.contains(&k) {
                        return Some(join(&k));
                    }
                    if let Some(d) = first_duplicate(v, &join(&k)) {
                        return Some(d);
                    }
                    seen.push(k);
                }
                None
            }
        }
    }

    #[test]
    fn the_scan_agrees_with_a_walk_of_the_tree_on_random_documents() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut found = 0;
        for _ in 0..3000 {
            let tree = random_tree(&mut rng, 0);
            let mut doc = String::new();
            text(&tree, &mut doc, &mut rng);
            assert!(
                serde_json::from_str::<serde::de::IgnoredAny>(&doc).is_ok(),
                "{doc}"
            );
            let got = scan(doc.as_bytes(), &|| false).unwrap().map(|d| d.path);
            let want = first_duplicate(&tree, "");
            assert_eq!(got, want, "{doc}");
            found += usize::from(want.is_some());
        }
        assert!(found > 300, "{found} documents with a duplicate");
    }

    #[test]
    fn objects_of_many_keys_are_searched_through_their_hash_set() {
        let members: Vec<String> = (0..40)
            .map(|i| format!("\"k{i}\": {{\"x\": [{i}]}}"))
            .collect();
        let distinct = format!("{{\"outer\": [{{{}}}]}}", members.join(", "));
        assert!(matches!(scan(distinct.as_bytes(), &|| false), Ok(None)));
        for repeated in [3, 17, 39] {
            let doc = format!(
                "{{\"outer\": [{{{}, \"k{repeated}\": 0}}]}}",
                members.join(", ")
            );
            let d = scan(doc.as_bytes(), &|| false).unwrap().unwrap();
            assert_eq!(d.path, format!("outer[0].k{repeated}"));
        }
    }

    #[test]
    fn what_is_not_json_is_left_to_the_typed_parse() {
        for bad in [
            "",
            "{",
            "[1,",
            "{\"a\" 1}",
            "{\"a\":1,}",
            "[1 2]",
            "\"abc",
            "{1: 2}",
            "[1]]",
            "@",
        ] {
            assert!(
                matches!(scan(bad.as_bytes(), &|| false), Ok(None)),
                "{bad:?}"
            );
        }
        let deep = format!("{}{}", "[".repeat(MAX_DEPTH + 1), "]".repeat(MAX_DEPTH + 1));
        assert!(matches!(scan(deep.as_bytes(), &|| false), Ok(None)));
    }
}
