//! Support shared by the integration tests: running the `dpmp` binary
//! (`cli`), a server on an ephemeral port and its client (`http`), a JSON
//! Schema validator for `api/openapi.yaml` (`schema`), tiny datasets and
//! settings for the network tests (`net`), the Panda and configurations in
//! its limits (`robot`), obstacle builders (`scene`), reading JSON files
//! and arrays (`json`), generated typical requests (`requests`), and the
//! shipped model's folder ([`default_model_dir`]).

#![allow(dead_code)] // every test module uses a subset

pub mod cli;
pub mod http;
pub mod json;
pub mod net;
pub mod process;
pub mod requests;
pub mod robot;
pub mod scene;
pub mod schema;

use std::path::{Path, PathBuf};

/// The shipped model, `models/default`.
pub fn default_model_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default")
}
