//! The service under abuse, on loopback, bounded in count and time: the
//! deadline stops all of a request's work, a cheap proof answers a too
//! short duration at once, slow and idle clients are cut off, a flood of
//! idle connections cannot lock `/healthz` out, busy connections at the cap
//! are refused in JSON, hyper's own parse errors are JSON, and a shutdown
//! drains within its limit while answering late requests 503.

use crate::common::http::*;
use crate::common::process::{exit_within, serve_process, signal};
use crate::common::requests::typical_json;
use dpmp::service::{AppState, RunningServer, ServiceConfig};
use serde_json::{json, Value};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

/// A server with `config` whose state the test keeps (limiter load).
fn start_keeping_state(config: ServiceConfig) -> (RunningServer, AppState) {
    let robot = dpmp::robot::Robot::panda().unwrap();
    let state = AppState::new(config, robot, None).unwrap();
    (RunningServer::start(state.clone()).unwrap(), state)
}

/// A raw connection with read and write timeouts (tests never hang).
fn connect(addr: SocketAddr) -> TcpStream {
    let s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.set_write_timeout(Some(Duration::from_secs(10))).unwrap();
    s
}

/// Everything the server sends until it closes (or the read times out).
fn read_all(mut s: TcpStream) -> String {
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

/// Status code and JSON body of a raw HTTP/1.1 answer.
fn parse_answer(raw: &str) -> (u16, Value) {
    let status = raw
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no status line in {raw:?}"));
    let body = raw.split("\r\n\r\n").nth(1).unwrap_or("");
    let value = serde_json::from_str(body)
        .unwrap_or_else(|e| panic!("status {status}: body is not JSON ({e}): {raw:?}"));
    (status, value)
}

/// The heaviest request the service accepts: 256 obstacles (246 far from
/// the robot), 2000 samples x 5 dense, 32 restarts, 1000 iterations, 32
/// extra samples.
fn maximal_request() -> Value {
    let mut v = typical_json(1, &Default::default());
    let obstacles = v["obstacles"].as_array_mut().unwrap();
    for k in obstacles.len()..256 {
        let f = k as f64 / 256.0;
        obstacles.push(json!({"id": format!("far-{k}"), "type": "sphere",
            "center": [-0.6 + 0.2 * f, -0.5 + f, 0.3 + 0.5 * f], "radius": 0.02}));
    }
    v["promp"]["n_samples"] = json!(2000);
    v["options"]["verify_factor"] = json!(5);
    v["options"]["restarts"] = json!(32);
    v["options"]["max_iterations"] = json!(1000);
    v["samples"] = json!(32);
    v
}

#[test]
fn the_deadline_stops_every_thread_of_the_request() {
    let deadline = Duration::from_millis(400);
    let config = test_config().with_deadline(deadline).with_concurrency(2, 8);
    let (server, state) = start_keeping_state(config);
    let url = server.url("/v1/optimize");
    let body = maximal_request().to_string();
    let answers: Vec<(u16, Value, Duration, Duration)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..3)
            .map(|_| {
                let (url, body, state) = (url.clone(), body.clone(), &state);
                scope.spawn(move || {
                    let t0 = Instant::now();
                    let (status, answer) = post_json(&client(), &url, body);
                    let answered = t0.elapsed();
                    // The job is over when the answer is: poll the limiter.
                    while state.limiter().load().running > 0 && t0.elapsed() < answered * 4 {
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    (status, answer, answered, t0.elapsed())
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let mut last_answer = Duration::ZERO;
    for (status, answer, answered, _) in &answers {
        match status {
            200 => {
                assert_eq!(answer["status"], "max_iterations", "{answer}");
                let warnings = answer["report"]["warnings"].to_string();
                assert!(warnings.contains("deadline"), "{warnings}");
            }
            503 => assert_eq!(code(answer), "deadline_exceeded"),
            other => panic!("{other}: {answer}"),
        }
        // Parsing 80 kB, the solve and the answer all end at the deadline
        // (plus the grace period at the very most).
        assert!(
            *answered < deadline + dpmp::service::limits::GRACE + Duration::from_millis(1000),
            "answered after {answered:?}"
        );
        last_answer = last_answer.max(*answered);
    }
    let t0 = Instant::now();
    while state.limiter().load().running > 0 {
        assert!(
            t0.elapsed() < Duration::from_millis(100),
            "a job still runs after its answer"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    // The next ordinary request is served, not refused for want of a slot.
    let mut small = typical_json(2, &Default::default());
    small["promp"]["n_samples"] = json!(50);
    let (status, answer) = post_json(&client(), &url, small.to_string());
    assert_eq!(status, 200, "{answer}");
}

#[test]
fn a_request_whose_qps_hold_thousands_of_rows_stops_by_its_deadline() {
    // A free start, a goal 0.3 m from the prior's and a duration of 1 ms:
    // no proof of infeasibility applies, every sample breaks its jerk
    // limits (a 4 s motion squeezed into 1 ms), and each QP holds
    // thousands of rows, so one QP can outlast the time left. The solver
    // stops inside a QP, so the answer is the solve's own (200, the
    // deadline's warning), not the grace period's 503, and it comes well
    // within the grace period.
    let deadline = Duration::from_millis(400);
    let server = start(test_config().with_deadline(deadline));
    let settings = dpmp::fixtures::ExampleSettings {
        with_start: false,
        ..Default::default()
    };
    let mut v = typical_json(3, &settings);
    v["duration_s"] = json!(0.001);
    v["obstacles"] = json!([]);
    v["goal"] = json!({"position": [0.3, 0.3, 0.4], "tolerance_m": 0.005});
    let t0 = Instant::now();
    let (status, answer) = post_json(&client(), &server.url("/v1/optimize"), v.to_string());
    let answered = t0.elapsed();
    assert_eq!(status, 200, "{answer}");
    assert_eq!(answer["stop_reason"], "deadline", "{answer}");
    assert!(
        answered < deadline + dpmp::service::limits::GRACE / 2,
        "answered after {answered:?}"
    );
}

#[test]
fn a_too_short_duration_is_proven_infeasible_at_once() {
    let server = start(test_config());
    let mut v = typical_json(1, &Default::default());
    v["duration_s"] = json!(0.05);
    v["promp"]["n_samples"] = json!(50);
    let t0 = Instant::now();
    let (status, answer) = post_json(&client(), &server.url("/v1/optimize"), v.to_string());
    assert_eq!(status, 200, "{answer}");
    assert_eq!(answer["status"], "infeasible", "{answer}");
    let bound = answer["duration_lower_bound_s"].as_f64().unwrap();
    assert!(bound > 0.05 && bound < 4.0, "{bound}");
    assert!(answer["reason"]
        .as_str()
        .unwrap()
        .starts_with("duration_s:"));
    // The proof is closed-form; the bounded search for a verified duration
    // is what takes time.
    assert!(
        t0.elapsed()
            < dpmp::optim::infeasible::duration::DURATION_SEARCH_BUDGET + Duration::from_secs(3)
    );
    if let Some(d) = answer["min_duration_s"].as_f64() {
        assert!(d >= bound);
        v["duration_s"] = json!(d);
        let (_, again) = post_json(&client(), &server.url("/v1/optimize"), v.to_string());
        assert_eq!(again["status"], "optimal", "{again}");
    }
}

#[test]
fn idle_connections_are_cut_and_cannot_lock_out_healthz() {
    let mut config = test_config();
    config.header_read_timeout = Duration::from_millis(300);
    config.max_connections = 16;
    config.max_connections_per_ip = 16;
    let server = start(config);
    // Four times the cap of connections that never send a byte.
    let idle: Vec<TcpStream> = (0..64).map(|_| connect(server.addr())).collect();
    let t0 = Instant::now();
    let (status, body) = status_and_json(client().get(server.url("/healthz")).send().unwrap());
    assert_eq!((status, body["status"].as_str()), (200, Some("ok")));
    assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
    // The survivors are closed once the header timeout passes.
    let t0 = Instant::now();
    let last = idle.into_iter().last().unwrap();
    let rest = read_all(last);
    assert!(
        rest.is_empty() || rest.starts_with("HTTP/1.1 408"),
        "{rest:?}"
    );
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
}

/// A request whose headers promise a body that never comes (busy).
fn half_sent(addr: SocketAddr) -> TcpStream {
    let mut s = connect(addr);
    write!(
        s,
        "POST /v1/optimize HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\ncontent-length: 1000\r\n\r\n{{\"pri"
    )
    .unwrap();
    s
}

#[test]
fn busy_connections_at_the_cap_refuse_new_ones_in_json() {
    let mut config = test_config();
    config.max_connections = 2;
    config.max_connections_per_ip = 2;
    let server = start(config);
    let _busy: Vec<TcpStream> = (0..2).map(|_| half_sent(server.addr())).collect();
    std::thread::sleep(Duration::from_millis(100));
    let mut s = connect(server.addr());
    let _ = s.write_all(b"GET /healthz HTTP/1.1\r\nhost: x\r\n\r\n");
    let (status, body) = parse_answer(&read_all(s));
    assert_eq!(
        (status, code(&body)),
        (503, "too_many_connections"),
        "{body}"
    );
}

#[test]
fn a_slow_body_gets_408_in_json() {
    let mut config = test_config();
    config.body_read_timeout = Duration::from_millis(300);
    let server = start(config);
    let t0 = Instant::now();
    let (status, body) = parse_answer(&read_all(half_sent(server.addr())));
    assert_eq!((status, code(&body)), (408, "body_timeout"), "{body}");
    assert!(t0.elapsed() < Duration::from_secs(3));
}

#[test]
fn requests_hyper_cannot_parse_get_json_errors() {
    let server = start(test_config());
    let cases: [(Vec<u8>, u16, &str); 3] = [
        (b"GARBAGE\r\n\r\n".to_vec(), 400, "malformed_request"),
        (
            b"GET /healthz HTTP/1.1\r\nhost: x\r\nbad header\r\n\r\n".to_vec(),
            400,
            "malformed_request",
        ),
        (
            format!(
                "GET /healthz HTTP/1.1\r\nhost: x\r\nx-big: {}\r\n\r\n",
                "a".repeat(dpmp::service::server::MAX_HEADER_BYTES + 4096)
            )
            .into_bytes(),
            431,
            "headers_too_large",
        ),
    ];
    for (request, want_status, want_code) in cases {
        let mut s = connect(server.addr());
        let _ = s.write_all(&request);
        let raw = read_all(s);
        let (status, body) = parse_answer(&raw);
        assert_eq!((status, code(&body)), (want_status, want_code), "{raw:?}");
    }
}

#[test]
fn shutdown_drains_within_its_limit_and_answers_late_requests_503() {
    let mut config = test_config();
    config.drain_timeout = Duration::from_millis(600);
    let server = start(config);
    let addr = server.addr();
    // A request whose body never arrives holds the drain until its limit.
    let stuck = half_sent(addr);
    std::thread::sleep(Duration::from_millis(100));
    let t0 = Instant::now();
    let stopping = std::thread::spawn(move || server.shutdown());
    std::thread::sleep(Duration::from_millis(100));
    // During the drain: new requests are answered, not reset.
    let c = client();
    let (status, body) = status_and_json(c.get(format!("http://{addr}/readyz")).send().unwrap());
    assert_eq!(status, 503);
    assert_eq!(body["shutting_down"], true, "{body}");
    let (status, body) = post_json(&c, &format!("http://{addr}/v1/optimize"), "{}");
    assert_eq!((status, code(&body)), (503, "shutting_down"), "{body}");
    stopping.join().unwrap().unwrap();
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(500) && took < Duration::from_secs(3),
        "{took:?}"
    );
    drop(stuck);
}

#[test]
fn duplicate_keys_are_refused_on_every_route() {
    let server = start_with_default_model();
    let c = client();
    let body = r#"{"target_box": [1, 2, 3, 4], "target_box": [5, 6, 7, 8], "image_base64": ""}"#;
    for route in ["/v1/optimize", "/v1/plan"] {
        let (status, answer) = post_json(&c, &server.url(route), body);
        assert_eq!(
            (status, field(&answer)),
            (422, Some("target_box")),
            "{route}: {answer}"
        );
    }
    let mut v = typical_json(0, &Default::default()).to_string();
    v = v.replacen("\"radius\":", "\"radius\":0.01,\"radius\":", 1);
    let (status, answer) = post_json(&c, &server.url("/v1/optimize"), v);
    assert_eq!(status, 422, "{answer}");
    assert!(field(&answer).unwrap().ends_with(".radius"), "{answer}");
}

#[test]
fn oversized_geometry_is_refused_naming_the_field() {
    let server = start(test_config());
    let c = client();
    let cases = [
        (
            json!({"id": "huge", "type": "box", "center": [0.5, 0.0, 0.5],
                   "half_extents": [1e20, 0.1, 0.1]}),
            "obstacles[0].half_extents[0]",
        ),
        (
            json!({"id": "far", "type": "capsule", "a": [0.5, -1e5, 0.5],
                   "b": [0.5, 1e5, 0.5], "radius": 0.02}),
            "obstacles[0].a[1]",
        ),
        (
            json!({"id": "dust", "type": "sphere", "center": [0.5, 0.0, 0.5], "radius": 1e-12}),
            "obstacles[0].radius",
        ),
    ];
    for (obstacle, want) in cases {
        let mut v = typical_json(0, &Default::default());
        v["obstacles"] = json!([obstacle]);
        let (status, answer) = post_json(&c, &server.url("/v1/optimize"), v.to_string());
        assert_eq!((status, field(&answer)), (422, Some(want)), "{answer}");
    }
}

#[cfg(unix)]
#[test]
fn sigterm_drains_within_its_limit_and_a_second_signal_exits_at_once() {
    // A half-sent request holds the drain until its limit, then exit 0.
    let (mut child, addr) = serve_process(&["--drain-timeout-ms", "800"]);
    let stuck = half_sent(addr);
    std::thread::sleep(Duration::from_millis(100));
    let t0 = Instant::now();
    signal(&child, "TERM");
    assert_eq!(exit_within(&mut child, Duration::from_secs(10)), Some(0));
    let took = t0.elapsed();
    assert!(took >= Duration::from_millis(700), "{took:?}");
    drop(stuck);
    // A second signal during a long drain ends the process at once.
    let (mut child, addr) = serve_process(&["--drain-timeout-ms", "60000"]);
    let stuck = half_sent(addr);
    std::thread::sleep(Duration::from_millis(100));
    signal(&child, "TERM");
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    signal(&child, "INT");
    assert_eq!(exit_within(&mut child, Duration::from_secs(5)), Some(130));
    assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
    drop(stuck);
}

#[test]
fn the_dense_sample_limit_names_both_fields_it_multiplies() {
    let server = start(test_config());
    let mut v = typical_json(0, &Default::default());
    v["promp"]["n_samples"] = json!(2000);
    v["options"]["verify_factor"] = json!(6);
    let (status, answer) = post_json(&client(), &server.url("/v1/optimize"), v.to_string());
    assert_eq!(
        (status, field(&answer)),
        (422, Some("options.verify_factor")),
        "{answer}"
    );
    let message = answer["error"]["message"].as_str().unwrap();
    assert!(message.contains("promp.n_samples"), "{message}");
}

#[test]
fn a_truncated_jpeg_is_refused_over_http() {
    let server = start_with_default_model();
    let img = image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([x as u8, y as u8, 9]));
    let mut jpeg = Vec::new();
    image::DynamicImage::ImageRgb8(img)
        .write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
    jpeg.truncate(jpeg.len() / 3);
    use base64::Engine as _;
    let body = json!({"image_base64": base64::engine::general_purpose::STANDARD.encode(&jpeg),
        "target_box": [1, 1, 20, 20], "target_position": [0.66, 0.0, 0.7]});
    let (status, answer) = post_json(&client(), &server.url("/v1/plan"), body.to_string());
    assert_eq!(
        (status, code(&answer)),
        (400, "malformed_image"),
        "{answer}"
    );
    assert_eq!(field(&answer), Some("image_base64"));
}

/// Invented methods (any token is a valid HTTP method) count as `other`:
/// the metrics' label set stays closed, whatever clients send.
#[test]
fn invented_methods_do_not_grow_the_metrics() {
    let server = start(test_config());
    for k in 0..20 {
        let method = format!("X{}{k}", "M".repeat(2000));
        let mut s = connect(server.addr());
        let _ = write!(
            s,
            "{method} /healthz HTTP/1.1\r\nhost: x\r\nconnection: close\r\n\r\n"
        );
        let (status, _) = parse_answer(&read_all(s));
        assert_eq!(status, 405);
    }
    let text = client()
        .get(server.url("/metrics"))
        .send()
        .unwrap()
        .text()
        .unwrap();
    assert!(!text.contains("MMMM"), "an invented method became a label");
    assert!(
        text.contains(
            r#"dpmp_http_requests_total{route="/healthz",method="other",status="405"} 20"#
        ),
        "{text}"
    );
}

/// A declared body over the limit is refused from the head, at once.
#[test]
fn a_declared_body_over_the_limit_is_413_without_waiting_for_it() {
    let server = start(test_config().with_body_limit(1 << 20));
    let mut s = connect(server.addr());
    let t0 = Instant::now();
    let _ = write!(
        s,
        "POST /v1/optimize HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\ncontent-length: {}\r\n\r\n{{",
        2 << 20
    );
    let raw = read_all(s);
    let (status, body) = parse_answer(&raw);
    assert_eq!((status, code(&body)), (413, "body_too_large"), "{raw}");
    // Not after the body timeout (30 s) or the deadline (60 s).
    assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
}

/// The ends hyper answers with silence get an answer: HTTP/2 with prior
/// knowledge a GOAWAY(HTTP_1_1_REQUIRED), a head cut by the header timeout
/// a JSON 408; a connection that never sent a byte is closed quietly.
#[test]
fn http2_prefaces_and_cut_heads_get_an_answer() {
    let mut config = test_config();
    config.header_read_timeout = Duration::from_millis(300);
    let server = start(config);
    let mut s = connect(server.addr());
    s.write_all(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n\x00\x00\x00\x04\x00\x00\x00\x00\x00")
        .unwrap();
    let mut frames = Vec::new();
    let _ = s.read_to_end(&mut frames);
    assert!(frames.len() > 18, "{frames:?}");
    assert_eq!(frames[3], 4, "a SETTINGS frame first");
    assert_eq!(
        (frames[12], &frames[22..26]),
        (7, &[0u8, 0, 0, 0xd][..]),
        "then GOAWAY(HTTP_1_1_REQUIRED)"
    );
    let debug: Value = serde_json::from_slice(&frames[26..]).unwrap();
    assert_eq!(debug["error"]["code"], "http2_not_supported");

    let mut s = connect(server.addr());
    s.write_all(b"GET /healthz HTTP/1.1\r\nhost: x\r\n")
        .unwrap();
    let (status, body) = parse_answer(&read_all(s));
    assert_eq!((status, code(&body)), (408, "header_timeout"), "{body}");

    let idle = connect(server.addr());
    assert_eq!(read_all(idle), "");
}

/// `DPMP_API_TOKEN=""` does not serve without auth: `dpmp serve` refuses
/// it with exit code 2, naming the variable.
#[test]
fn an_empty_token_variable_stops_the_service_from_starting() {
    for blank in ["", "   "] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_dpmp"))
            .args(["serve", "--addr", "127.0.0.1:0", "--no-model"])
            .env("DPMP_API_TOKEN", blank)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let code = exit_within(&mut child, Duration::from_secs(60));
        let mut stderr = String::new();
        let _ = child.stderr.take().unwrap().read_to_string(&mut stderr);
        assert_eq!(code, Some(2), "{blank:?}: {stderr}");
        assert!(stderr.contains("DPMP_API_TOKEN"), "{stderr}");
    }
}
