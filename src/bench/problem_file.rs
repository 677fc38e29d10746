//! The benchmark problem file: an optimise request (DESIGN.md's request
//! schema, the same JSON `dpmp optimize` reads) plus an `expect` block
//! (what a correct planner must conclude) and a `meta` block (how the file
//! was made: generator, seed, category).
//!
//! The request keys sit at the top level of the file, next to `expect` and
//! `meta`, so `dpmp optimize --request` accepts a problem file once those
//! two keys are removed. The request part is kept as JSON here and parsed
//! into [`crate::optim::OptimizeRequest`] by the runner, which reports a
//! malformed request as a failed problem instead of aborting.

use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// What a correct planner must conclude on a problem.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Expect {
    /// Whether a trajectory satisfying every constraint exists; `null`:
    /// unknown (no search found one and nothing proves there is none).
    pub feasible: Option<bool>,
    /// Optional lower bound a feasible answer's minimum clearance must meet (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_clearance_m: Option<f64>,
    /// Joint-major weights that satisfy every constraint (the proof of a
    /// `feasible: true` label found by a search).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub witness: Option<Vec<f64>>,
}

/// How a problem file was made.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    /// Generator name and version (e.g. `dpmp bench make-problems v1`).
    pub generator: String,
    /// Seed of this problem.
    pub seed: u64,
    /// One of [`CATEGORIES`].
    pub category: String,
    /// Free-text description of the construction.
    #[serde(default)]
    pub description: String,
    /// Reference final TCP position (m), e.g. the demonstrations' mean:
    /// the runner reports each method's final-point TCP error against it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_final_tcp: Option<[f64; 3]>,
}

/// The problem categories, in report order.
pub const CATEGORIES: [&str; 7] = [
    "easy",
    "on-path",
    "dense",
    "velocity",
    "joint-limit",
    "degenerate-prior",
    "infeasible",
];

/// Category of every problem of the hard set (`dpmp bench make-problems
/// --set hard`, [`super::hard_set`]).
pub const HARD_CATEGORY: &str = "hard";

/// One benchmark problem.
#[derive(Clone, Debug, PartialEq)]
pub struct ProblemFile {
    /// File stem (the problem's name in reports).
    pub name: String,
    /// The optimise request as JSON (every key except `expect` and `meta`).
    pub request: Value,
    /// Expected outcome.
    pub expect: Expect,
    /// Provenance.
    pub meta: Meta,
}

impl ProblemFile {
    /// Parse a problem from JSON text; errors name `field` prefixes such as
    /// `expect.feasible` or `meta.category`.
    pub fn from_json(name: &str, text: &str) -> Result<ProblemFile> {
        let value: Value = serde_json::from_str(text)
            .map_err(|e| Error::invalid("problem", format!("malformed JSON: {e}")))?;
        let Value::Object(mut map) = value else {
            return Err(Error::invalid("problem", "must be a JSON object"));
        };
        let expect = take_block::<Expect>(&mut map, "expect")?;
        let meta = take_block::<Meta>(&mut map, "meta")?;
        if !CATEGORIES.contains(&meta.category.as_str()) && meta.category != HARD_CATEGORY {
            return Err(Error::invalid(
                "meta.category",
                format!(
                    "must be one of {CATEGORIES:?} or {HARD_CATEGORY:?}, got {:?}",
                    meta.category
                ),
            ));
        }
        if let Some(w) = &expect.witness {
            if expect.feasible != Some(true) {
                return Err(Error::invalid(
                    "expect.witness",
                    "only a problem labelled feasible has a witness",
                ));
            }
            crate::error::ensure_finite("expect.witness", w)?;
        }
        if let Some(c) = expect.min_clearance_m {
            if !c.is_finite() {
                return Err(Error::invalid("expect.min_clearance_m", "must be finite"));
            }
        }
        Ok(ProblemFile {
            name: name.to_string(),
            request: Value::Object(map),
            expect,
            meta,
        })
    }

    /// Read one problem file; errors name the file.
    pub fn load(path: &Path) -> Result<ProblemFile> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .ok_or_else(|| Error::file(path, "file name is not valid UTF-8"))?;
        ProblemFile::from_json(name, &text).map_err(|e| Error::file(path, e.to_string()))
    }

    /// The file's compact JSON (one line): request keys, then `expect` and `meta`.
    pub fn to_json(&self) -> Result<String> {
        let mut map = match &self.request {
            Value::Object(m) => m.clone(),
            _ => return Err(Error::invalid("request", "must be a JSON object")),
        };
        map.insert("expect".into(), to_value(&self.expect)?);
        map.insert("meta".into(), to_value(&self.meta)?);
        serde_json::to_string(&Value::Object(map))
            .map_err(|e| Error::Numerical(format!("cannot serialise problem: {e}")))
    }

    /// Write `DIR/<name>.json` atomically (temporary file, then rename).
    pub fn save(&self, dir: &Path) -> Result<PathBuf> {
        let path = dir.join(format!("{}.json", self.name));
        write_atomic(&path, self.to_json()?.as_bytes())?;
        Ok(path)
    }
}

/// Every `*.json` in `dir`, sorted by file name, parsed. A file that does
/// not parse is returned as an error in its slot (the runner counts it as
/// failed) rather than aborting the whole load.
pub fn load_dir(dir: &Path) -> Result<Vec<(String, Result<ProblemFile>)>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(Error::file(dir, "contains no *.json problem files"));
    }
    Ok(paths
        .into_iter()
        .map(|p| {
            let name = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            (name, ProblemFile::load(&p))
        })
        .collect())
}

pub use crate::fsio::write_atomic;

fn take_block<T: serde::de::DeserializeOwned>(
    map: &mut Map<String, Value>,
    key: &str,
) -> Result<T> {
    let value = map
        .remove(key)
        .ok_or_else(|| Error::invalid(key, "missing block"))?;
    serde_json::from_value(value).map_err(|e| Error::invalid(key, e.to_string()))
}

fn to_value<T: Serialize>(value: &T) -> Result<Value> {
    serde_json::to_value(value).map_err(|e| Error::Numerical(format!("cannot serialise: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"{"prior": {"mean": [1.0], "cov": [[1.0]]}, "duration_s": 2.0,
        "expect": {"feasible": false},
        "meta": {"generator": "test", "seed": 7, "category": "infeasible"}}"#;

    #[test]
    fn round_trips_request_expect_and_meta() {
        let p = ProblemFile::from_json("p", TEXT).unwrap();
        assert_eq!(p.expect.feasible, Some(false));
        assert_eq!(p.meta.seed, 7);
        assert_eq!(p.request["duration_s"], 2.0);
        assert!(p.request.get("expect").is_none());
        let again = ProblemFile::from_json("p", &p.to_json().unwrap()).unwrap();
        assert_eq!(again, p);
    }

    #[test]
    fn bad_blocks_name_their_field() {
        let no_expect = r#"{"meta": {"generator": "g", "seed": 1, "category": "easy"}}"#;
        let e = ProblemFile::from_json("p", no_expect).unwrap_err();
        assert_eq!(e.field(), Some("expect"));
        let bad_cat = TEXT.replace("\"infeasible\"", "\"extreme\"");
        let e = ProblemFile::from_json("p", &bad_cat).unwrap_err();
        assert_eq!(e.field(), Some("meta.category"));
        let orphan = TEXT.replace(
            "\"feasible\": false",
            "\"feasible\": null, \"witness\": [1.0]",
        );
        let e = ProblemFile::from_json("p", &orphan).unwrap_err();
        assert_eq!(e.field(), Some("expect.witness"));
        let extra = TEXT.replace("\"feasible\": false", "\"feasible\": false, \"x\": 1");
        assert_eq!(
            ProblemFile::from_json("p", &extra).unwrap_err().field(),
            Some("expect")
        );
    }
}
