//! Robustness over a real socket: concurrent answers equal sequential ones
//! byte for byte (except `solve_ms`), graceful shutdown finishes a request
//! in flight, the deadline answers without hanging, and a bounded fuzz run
//! of mutated bodies never gets a 5xx or a non-JSON answer.

use crate::common::http::*;
use crate::common::requests::typical_json;
use rand::{Rng, SeedableRng};
use serde_json::{json, Value};
use std::time::{Duration, Instant};

/// A smaller version of the typical request (50 samples, 3 obstacles) so
/// that the many solves of this file stay fast in debug builds.
fn typical_request(seed: u64) -> Value {
    let settings = dpmp::fixtures::ExampleSettings {
        n_obstacles: 3,
        ..Default::default()
    };
    let mut v = typical_json(seed, &settings);
    v["promp"]["n_samples"] = json!(50);
    v
}

#[test]
fn concurrent_answers_equal_sequential_ones() {
    let server = start(test_config());
    let url = server.url("/v1/optimize");
    let bodies: Vec<String> = (0..3)
        .map(|s| typical_request(10 + s).to_string())
        .collect();
    let c = client();
    let sequential: Vec<Value> = bodies
        .iter()
        .map(|b| without_timing(post_json(&c, &url, b.clone()).1))
        .collect();
    let concurrent: Vec<Value> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..6)
            .map(|k| {
                let body = bodies[k % 3].clone();
                let url = url.clone();
                scope.spawn(move || without_timing(post_json(&client(), &url, body).1))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (k, answer) in concurrent.iter().enumerate() {
        assert!(answer.get("status").is_some(), "{answer}");
        assert_eq!(
            answer.to_string(),
            sequential[k % 3].to_string(),
            "request {k} differs"
        );
    }
}

#[test]
fn graceful_shutdown_finishes_the_request_in_flight() {
    let server = start(test_config());
    let url = server.url("/v1/optimize");
    let body = typical_request(5).to_string();
    let in_flight = std::thread::spawn(move || post_json(&client(), &url, body));
    // Give the request time to reach the solver, then shut down.
    std::thread::sleep(Duration::from_millis(30));
    let t0 = Instant::now();
    server.shutdown().unwrap();
    let (status, answer) = in_flight.join().unwrap();
    assert_eq!(status, 200, "{answer}");
    assert_eq!(answer["trajectory"]["points"].as_array().unwrap().len(), 50);
    assert!(t0.elapsed() < Duration::from_secs(30));
}

#[test]
fn a_tiny_deadline_answers_quickly_without_hanging() {
    let config = test_config().with_deadline(Duration::from_millis(1));
    let server = start(config);
    let c = client();
    let t0 = Instant::now();
    let (status, body) = post_json(
        &c,
        &server.url("/v1/optimize"),
        typical_request(6).to_string(),
    );
    // Either the solver stopped at the deadline (max_iterations, or a fast
    // path that finished anyway) or the request got 503.
    match status {
        200 => assert!(body["status"].is_string(), "{body}"),
        503 => assert_eq!(code(&body), "deadline_exceeded"),
        other => panic!("unexpected {other}: {body}"),
    }
    assert!(t0.elapsed() < Duration::from_secs(5));
}

/// One mutated body: random bytes, truncations, wrong types, huge numbers,
/// NaN strings, deep nesting, or a field-level mutation of a valid request.
fn mutate(rng: &mut impl Rng, base: &Value, base_text: &str) -> Vec<u8> {
    match rng.gen_range(0..8) {
        0 => (0..rng.gen_range(0..64)).map(|_| rng.gen()).collect(),
        1 => base_text.as_bytes()[..rng.gen_range(0..base_text.len())].to_vec(),
        2 => {
            let depth = rng.gen_range(1..5000);
            format!("{}{}", "[".repeat(depth), "]".repeat(depth / 2)).into_bytes()
        }
        3 => {
            let mut bytes = base_text.as_bytes().to_vec();
            for _ in 0..rng.gen_range(1..4) {
                let i = rng.gen_range(0..bytes.len());
                bytes[i] = rng.gen();
            }
            bytes
        }
        _ => {
            let mut v = base.clone();
            let replacement = match rng.gen_range(0..9) {
                0 => json!("NaN"),
                1 => json!(1e308),
                2 => json!(-1),
                3 => json!(null),
                4 => json!([]),
                5 => json!({"x": 1}),
                6 => json!(u64::MAX),
                7 => json!("Infinity"),
                _ => json!(true),
            };
            let fields = [
                "prior",
                "promp",
                "duration_s",
                "start",
                "obstacles",
                "clearance_m",
                "joint_limit_margin_rad",
                "samples",
                "options",
                "goal",
            ];
            let key = fields[rng.gen_range(0..fields.len())];
            if rng.gen_bool(0.5) {
                if let Some(items) = v[key].as_array_mut() {
                    if !items.is_empty() {
                        let i = rng.gen_range(0..items.len());
                        items[i] = replacement;
                        return v.to_string().into_bytes();
                    }
                }
            }
            v[key] = replacement;
            v.to_string().into_bytes()
        }
    }
}

#[test]
fn fuzzed_bodies_never_get_5xx_or_non_json() {
    let config = test_config().with_deadline(Duration::from_millis(300));
    let server = start(config);
    let c = client();
    // A small valid request keeps the solves that do happen cheap.
    let mut base = typical_request(7);
    base["promp"]["n_samples"] = json!(30);
    base["obstacles"] = json!([base["obstacles"][0]]);
    let base_text = base.to_string();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let mut statuses = std::collections::BTreeMap::new();
    for i in 0..1000 {
        let body = mutate(&mut rng, &base, &base_text);
        let path = if i % 4 == 3 {
            "/v1/plan"
        } else {
            "/v1/optimize"
        };
        let response = c
            .post(server.url(path))
            .header("content-type", "application/json")
            .body(body.clone())
            .send()
            .unwrap();
        let (status, json) = status_and_json(response);
        assert!(
            (200..500).contains(&status) || (status == 503 && json["error"].is_object()),
            "status {status} for {:?}: {json}",
            String::from_utf8_lossy(&body[..body.len().min(200)])
        );
        if status >= 400 {
            assert!(json["error"]["code"].is_string(), "{json}");
        }
        *statuses.entry(status).or_insert(0) += 1;
    }
    eprintln!("fuzz statuses: {statuses:?}");
    assert!(statuses.keys().any(|s| *s == 400) && statuses.keys().any(|s| *s == 422));
}
