//! Shared helpers of the HTTP integration tests: a server on an ephemeral
//! loopback port (with or without the shipped model), a blocking client,
//! answers without their wall-clock fields, and checks of responses against
//! `api/openapi.yaml`.

use super::schema;
use dpmp::net::Model;
use dpmp::service::{AppState, RunningServer, ServiceConfig};
use serde_json::Value;
use std::time::Duration;

/// A config listening on an ephemeral loopback port, with a deadline long
/// enough for debug builds on a loaded 2-core machine.
pub fn test_config() -> ServiceConfig {
    ServiceConfig::default()
        .with_addr("127.0.0.1:0".parse().unwrap())
        .with_deadline(Duration::from_secs(60))
}

/// Start a server with `config` (and the shipped robot, no model).
pub fn start(config: ServiceConfig) -> RunningServer {
    let robot = dpmp::robot::Robot::panda().unwrap();
    RunningServer::start(AppState::new(config, robot, None).unwrap()).unwrap()
}

/// A server with the shipped robot and model (`models/default`).
pub fn start_with_default_model() -> RunningServer {
    let model = Model::load(&super::default_model_dir())
        .expect("models/default is committed with the repository");
    let state = AppState::new(
        test_config(),
        dpmp::robot::Robot::panda().unwrap(),
        Some(model),
    )
    .unwrap();
    RunningServer::start(state).unwrap()
}

/// The body with every `solve_ms` (the one timing field) removed.
pub fn without_timing(mut v: Value) -> Value {
    fn strip(v: &mut Value) {
        match v {
            Value::Object(map) => {
                map.remove("solve_ms");
                map.values_mut().for_each(strip);
            }
            Value::Array(items) => items.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut v);
    v
}

/// A blocking client with a generous timeout (tests must not hang).
pub fn client() -> reqwest::blocking::Client {
    reqwest::blocking::Client::builder()
        .timeout(Duration::from_secs(120))
        .build()
        .unwrap()
}

/// POST `body` as JSON text; returns (status, parsed JSON body).
pub fn post_json(
    client: &reqwest::blocking::Client,
    url: &str,
    body: impl Into<reqwest::blocking::Body>,
) -> (u16, Value) {
    let response = client
        .post(url)
        .header("content-type", "application/json")
        .body(body)
        .send()
        .unwrap();
    status_and_json(response)
}

/// Status and JSON body of a response (panics with the text when the body
/// is not JSON: every answer of the service must be JSON).
pub fn status_and_json(response: reqwest::blocking::Response) -> (u16, Value) {
    let status = response.status().as_u16();
    let text = response.text().unwrap();
    let value = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("status {status}: body is not JSON ({e}): {text:?}"));
    (status, value)
}

/// The error code of an error body.
pub fn code(body: &Value) -> &str {
    body["error"]["code"].as_str().unwrap_or("<no code>")
}

/// The error field of an error body.
pub fn field(body: &Value) -> Option<&str> {
    body["error"]["field"].as_str()
}

/// The OpenAPI document as JSON.
pub fn openapi() -> Value {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/api/openapi.yaml")).unwrap();
    let yaml: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
    serde_json::to_value(yaml).unwrap()
}

/// The schema of `status`'s JSON answer of `METHOD path` in the spec.
pub fn response_schema<'a>(spec: &'a Value, method: &str, path: &str, status: u16) -> &'a Value {
    let op = &spec["paths"][path][method];
    let mut response = &op["responses"][status.to_string()];
    if let Some(r) = response.get("$ref") {
        let pointer = r.as_str().unwrap().trim_start_matches('#');
        response = spec.pointer(pointer).unwrap();
    }
    &response["content"]["application/json"]["schema"]
}

/// Panic unless `body` validates against the spec's schema of that answer.
pub fn assert_valid(spec: &Value, method: &str, path: &str, status: u16, body: &Value) {
    let schema = response_schema(spec, method, path, status);
    assert!(
        !schema.is_null(),
        "{method} {path} {status} is not documented"
    );
    let errors = schema::validate(spec, schema, body);
    assert!(errors.is_empty(), "{method} {path} {status}: {errors:#?}");
}
