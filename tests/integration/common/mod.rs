//! Support shared by the integration tests: running the `dpmp` binary
//! (`cli`), a server on an ephemeral port and its client (`http`), a JSON
//! Schema validator for `api/openapi.yaml` (`schema`), and tiny datasets and
//! settings for the network tests (`net`).

#![allow(dead_code)] // every test module uses a subset

pub mod cli;
pub mod http;
pub mod net;
pub mod schema;
