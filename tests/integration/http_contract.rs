//! The contract: the router's routes and `api/openapi.yaml`'s paths are the
//! same set, every documented error code is one the service can answer, and
//! real responses validate against the spec's schemas.

use crate::common::http::*;
use crate::common::requests::typical_json;
use crate::common::schema::{unknown_keywords, validate};
use dpmp::service::routes;
use serde_json::Value;
use std::collections::BTreeSet;

fn spec_operations(spec: &Value) -> BTreeSet<(String, String)> {
    let mut out = BTreeSet::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for method in item.as_object().unwrap().keys() {
            out.insert((method.to_uppercase(), path.clone()));
        }
    }
    out
}

#[test]
fn router_routes_equal_spec_paths() {
    let spec = openapi();
    let router: BTreeSet<(String, String)> = routes::specs()
        .into_iter()
        .map(|r| (r.method.to_string(), r.path.to_string()))
        .collect();
    assert_eq!(router, spec_operations(&spec));
    // Every route the table lists is really served (not 404/405).
    let server = start(test_config());
    let c = client();
    for (method, path) in &router {
        let request = match method.as_str() {
            "GET" => c.get(server.url(path)),
            _ => c
                .post(server.url(path))
                .header("content-type", "application/json")
                .body("{}"),
        };
        let status = request.send().unwrap().status().as_u16();
        assert!(status != 404 && status != 405, "{method} {path}: {status}");
    }
}

#[test]
fn real_responses_validate_against_the_spec() {
    let spec = openapi();
    let server = start(test_config());
    let c = client();
    for path in ["/healthz", "/readyz", "/v1/robot", "/v1/models"] {
        let (s, body) = status_and_json(c.get(server.url(path)).send().unwrap());
        assert_valid(&spec, "get", path, s, &body);
    }
    let request = typical_json(1, &Default::default());
    let url = server.url("/v1/optimize");
    let (s, body) = post_json(&c, &url, request.to_string());
    assert_eq!(s, 200, "{body}");
    assert_valid(&spec, "post", "/v1/optimize", s, &body);
    // The request itself validates against the request schema.
    let request_schema = &spec["paths"]["/v1/optimize"]["post"]["requestBody"]["content"]
        ["application/json"]["schema"];
    assert_eq!(
        validate(&spec, request_schema, &request),
        Vec::<String>::new()
    );
    // Error answers of every class validate too.
    for (body, status) in [
        ("{", 400),
        (
            "{\"prior\": {\"mean\": [1], \"cov\": [[1]]}, \"clearance_m\": \"x\"}",
            422,
        ),
    ] {
        let (s, answer) = post_json(&c, &url, body);
        assert_eq!(s, status);
        assert_valid(&spec, "post", "/v1/optimize", s, &answer);
    }
    let (s, answer) = status_and_json(c.post(&url).body("{}").send().unwrap());
    assert_valid(&spec, "post", "/v1/optimize", s, &answer);
    let (s, answer) = post_json(
        &c,
        &server.url("/v1/plan"),
        "{\"target_box\": [1, 2, 3, 4]}",
    );
    assert_valid(&spec, "post", "/v1/plan", s, &answer);
}

#[test]
fn documented_examples_validate() {
    let spec = openapi();
    for (path, media) in [
        ("/v1/optimize", "application/json"),
        ("/v1/plan", "application/json"),
    ] {
        let content = &spec["paths"][path]["post"]["requestBody"]["content"][media];
        for (name, example) in content["examples"].as_object().unwrap() {
            let errors = validate(&spec, &content["schema"], &example["value"]);
            assert!(errors.is_empty(), "{path} example {name}: {errors:#?}");
        }
    }
    // The optimize example is accepted by the real request type.
    let example = &spec["paths"]["/v1/optimize"]["post"]["requestBody"]["content"]
        ["application/json"]["examples"]["annotation_prior"]["value"];
    let _: dpmp::optim::OptimizeRequest = serde_json::from_value(example.clone()).unwrap();
}

/// Every schema in the spec: the components and each operation's request
/// and response bodies, with a JSON-pointer-like path.
fn spec_schemas(spec: &Value) -> Vec<(String, &Value)> {
    let mut out: Vec<(String, &Value)> = spec["components"]["schemas"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(name, s)| (format!("#/components/schemas/{name}"), s))
        .collect();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let bodies = std::iter::once(&op["requestBody"]).chain(
                op["responses"]
                    .as_object()
                    .into_iter()
                    .flatten()
                    .map(|(_, r)| r),
            );
            for body in bodies {
                for (media, content) in body["content"].as_object().into_iter().flatten() {
                    out.push((format!("{method} {path} {media}"), &content["schema"]));
                }
            }
        }
    }
    out
}

#[test]
fn spec_schemas_use_only_known_keywords() {
    let spec = openapi();
    let schemas = spec_schemas(&spec);
    assert!(schemas.len() > 30, "only {} schemas found", schemas.len());
    let unknown: Vec<String> = schemas
        .iter()
        .flat_map(|(path, schema)| unknown_keywords(schema, path))
        .collect();
    assert!(unknown.is_empty(), "unknown schema keywords: {unknown:#?}");
}

/// Every request example in the contract is answered 200 by the service as
/// shipped (the Panda and the shipped model), and the answer validates.
#[test]
fn every_documented_example_is_answered_by_the_shipped_service() {
    let spec = openapi();
    let server = start_with_default_model();
    let c = client();
    let mut tried = 0;
    for (path, item) in spec["paths"].as_object().unwrap() {
        for (method, operation) in item.as_object().unwrap() {
            let content = &operation["requestBody"]["content"]["application/json"];
            let Some(examples) = content["examples"].as_object() else {
                continue;
            };
            for (name, example) in examples {
                let (s, body) = post_json(&c, &server.url(path), example["value"].to_string());
                assert_eq!(s, 200, "{method} {path} example {name}: {body}");
                assert_valid(&spec, method, path, s, &body);
                tried += 1;
            }
        }
    }
    assert!(tried >= 2, "{tried} examples");
}
