//! Reading the JSON files and arrays the CLI and HTTP tests check.

use serde_json::Value;
use std::path::Path;

/// The JSON file at `path` (panics when it is missing or not JSON).
pub fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A JSON array of numbers as `f64`s (panics on anything else).
pub fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}
