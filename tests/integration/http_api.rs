//! Endpoints over a real socket: happy paths with numeric checks and every
//! error class (400, 401, 404, 405, 413, 415, 422, 503).

use crate::common::http::*;
use crate::common::json::numbers;
use crate::common::requests::typical_json;
use dpmp::service::token::Token;
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

    let text = metrics_text(&c, &server);
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

/// The typical request (real-like prior, 10 obstacles, 150 samples, 2 cm).
fn typical_request(seed: u64) -> Value {
    typical_json(seed, &Default::default())
}

#[test]
fn optimize_answers_a_verified_trajectory() {
    let server = start(test_config());
    let c = client();
    let request = typical_request(1);
    let (s, body) = post_json(&c, &server.url("/v1/optimize"), request.to_string());
    assert_eq!(s, 200, "{body}");
    let robot = dpmp::robot::Robot::panda().unwrap();
    let trajectory = &body["trajectory"];
    assert_eq!(
        trajectory["joint_names"],
        serde_json::to_value(robot.joint_names()).unwrap()
    );
    let points = trajectory["points"].as_array().unwrap();
    assert_eq!(points.len(), 150);
    assert_eq!(points[0]["positions"].as_array().unwrap().len(), 7);
    let t_end = points.last().unwrap()["time_from_start"].as_f64().unwrap();
    assert!((t_end - 4.0).abs() < 1e-9, "{t_end}");
    assert_eq!(body["weights"].as_array().unwrap().len(), 56);
    let report = &body["report"];
    if body["status"] == "optimal" {
        let clearance = report["min_clearance_m"].as_f64().unwrap();
        assert!(clearance >= 0.02 - 1e-6, "clearance {clearance}");
        assert!(report["max_joint_limit_violation_rad"].as_f64().unwrap() <= 1e-6);
        assert!(report["max_velocity_ratio"].as_f64().unwrap() <= 1.0 + 1e-6);
    } else {
        assert!(body["reason"].is_string(), "{body}");
    }
    assert!(body["mahalanobis"].as_f64().unwrap() >= 0.0);
    // The solve was counted in the metrics.
    let text = metrics_text(&c, &server);
    assert!(text.contains("dpmp_solver_iterations_count 1"), "{text}");
    assert!(
        text.contains("dpmp_solver_duration_seconds_count 1"),
        "{text}"
    );
    if std::path::Path::new("/proc/self/stat").exists() {
        assert!(
            text.contains("# TYPE process_resident_memory_bytes gauge"),
            "{text}"
        );
    }
}

#[test]
fn the_ros2_format_is_the_message_with_accelerations_and_the_same_motion() {
    let server = start(test_config());
    let c = client();
    let url = server.url("/v1/optimize");
    let request = typical_request(1);
    let (_, dpmp) = post_json(&c, &url, request.to_string());
    let mut ros = request.clone();
    ros["trajectory_format"] = json!("ros2");
    let (s, body) = post_json(&c, &url, ros.to_string());
    assert_eq!(s, 200, "{body}");
    // The schema of the message (additional properties refused), via the
    // response's oneOf: exactly the ROS 2 shape matches.
    let spec = openapi();
    assert_valid(&spec, "post", "/v1/optimize", s, &body);
    let trajectory = &body["trajectory"];
    assert_eq!(
        trajectory["header"]["stamp"],
        json!({"sec": 0, "nanosec": 0})
    );
    assert_eq!(trajectory["header"]["frame_id"], "");
    assert_eq!(trajectory["joint_names"], dpmp["trajectory"]["joint_names"]);
    assert_eq!(body["weights"], dpmp["weights"]);
    let points = trajectory["points"].as_array().unwrap();
    let plain = dpmp["trajectory"]["points"].as_array().unwrap();
    assert_eq!(points.len(), plain.len());
    let seconds = |p: &Value| {
        p["time_from_start"]["sec"].as_f64().unwrap()
            + p["time_from_start"]["nanosec"].as_f64().unwrap() * 1e-9
    };
    for (p, q) in points.iter().zip(plain) {
        assert!((seconds(p) - q["time_from_start"].as_f64().unwrap()).abs() <= 5e-10);
        assert_eq!(p["positions"], q["positions"]);
        assert_eq!(p["velocities"], q["velocities"]);
        assert_eq!(p["effort"], json!([]));
        assert!(q.get("accelerations").is_none());
    }
    // Accelerations: central differences of the velocities (dt = 4/149 s).
    for k in 1..points.len() - 1 {
        let dt = seconds(&points[k + 1]) - seconds(&points[k - 1]);
        let (before, after) = (
            numbers(&points[k - 1]["velocities"]),
            numbers(&points[k + 1]["velocities"]),
        );
        let acc = numbers(&points[k]["accelerations"]);
        for j in 0..7 {
            let fd = (after[j] - before[j]) / dt;
            assert!(
                (fd - acc[j]).abs() < 2e-3 * (1.0 + acc[j].abs()),
                "point {k} joint {j}: {fd} vs {}",
                acc[j]
            );
        }
    }
    // Rest-to-rest (the default boundary): the first and last points stand
    // still, as a Franka needs.
    for end in [&points[0], &points[points.len() - 1]] {
        let still = numbers(&end["velocities"])
            .into_iter()
            .chain(numbers(&end["accelerations"]))
            .all(|v| v.abs() < 1e-9);
        assert!(still, "{end}");
    }
    // The message round-trips through typed ROS 2 structures (every field
    // required, no other field accepted) without losing a bit.
    let typed: ros2::JointTrajectory = serde_json::from_value(trajectory.clone()).unwrap();
    assert_eq!(&serde_json::to_value(&typed).unwrap(), trajectory);
    // An unknown format is refused, naming the field.
    ros["trajectory_format"] = json!("ros1");
    let (s, body) = post_json(&c, &url, ros.to_string());
    assert_eq!(s, 422, "{body}");
    assert!(
        body["error"]["field"]
            .as_str()
            .unwrap_or("")
            .contains("trajectory_format"),
        "{body}"
    );
}

#[test]
fn robot_and_models_describe_what_is_loaded() {
    let server = start(test_config());
    let c = client();
    let (s, body) = status_and_json(c.get(server.url("/v1/robot")).send().unwrap());
    assert_eq!(s, 200);
    assert_eq!(body["dof"], json!(7));
    let names = body["joint_names"].as_array().unwrap();
    assert_eq!(names.len(), 7);
    assert_eq!(names[0], json!("panda_joint1"));
    let joints = body["joints"].as_array().unwrap();
    // Panda joint 4 limits from the datasheet: [-3.0718, -0.0698].
    assert!((joints[3]["lower"].as_f64().unwrap() + 3.0718).abs() < 1e-3);
    assert!((joints[3]["upper"].as_f64().unwrap() + 0.0698).abs() < 1e-3);
    let home = body["home"].as_array().unwrap();
    assert!((home[3].as_f64().unwrap() + 2.5334).abs() < 1e-9);
    assert!(!body["collision_shapes"].as_array().unwrap().is_empty());
    let (s, body) = status_and_json(c.get(server.url("/v1/models")).send().unwrap());
    assert_eq!((s, body), (200, json!({"models": []})));
    let (_, ready) = status_and_json(c.get(server.url("/readyz")).send().unwrap());
    assert_eq!(ready["robot"]["dof"], json!(7));
    assert_eq!(ready["model"]["loaded"], json!(false));
}

#[test]
fn bad_requests_get_the_documented_4xx() {
    let config = test_config().with_body_limit(64 * 1024);
    let server = start(config);
    let c = client();
    let url = server.url("/v1/optimize");
    // 415: wrong or missing content type.
    let r = c.post(&url).body("{}").send().unwrap();
    let (s, body) = status_and_json(r);
    assert_eq!((s, code(&body)), (415, "unsupported_media_type"));
    let r = c
        .post(&url)
        .header("content-type", "text/plain")
        .body("{}")
        .send()
        .unwrap();
    assert_eq!(r.status().as_u16(), 415);
    // 400: malformed JSON.
    let (s, body) = post_json(&c, &url, "{\"prior\": ");
    assert_eq!((s, code(&body)), (400, "malformed_json"));
    // 413: body over the limit.
    let big = format!("{{\"pad\": \"{}\"}}", "x".repeat(100 * 1024));
    let (s, body) = post_json(&c, &url, big);
    assert_eq!((s, code(&body)), (413, "body_too_large"));
    // 422: wrong shapes and broken rules, naming the field.
    let mut request = typical_request(2);
    request["obstacles"][1]["radius"] = json!(-0.01);
    let (s, body) = post_json(&c, &url, request.to_string());
    assert_eq!((s, code(&body)), (422, "invalid_input"), "{body}");
    assert!(field(&body).unwrap().starts_with("obstacles[1]"), "{body}");
    let mut request = typical_request(2);
    request["start"] = json!([0.0, 1.0]);
    let (s, body) = post_json(&c, &url, request.to_string());
    assert_eq!((s, field(&body)), (422, Some("start")), "{body}");
    let mut request = typical_request(2);
    request["clearance_m"] = json!("NaN");
    let (s, body) = post_json(&c, &url, request.to_string());
    assert_eq!((s, field(&body)), (422, Some("clearance_m")), "{body}");
    let mut request = typical_request(2);
    request["samples"] = json!(1000);
    let (s, body) = post_json(&c, &url, request.to_string());
    assert_eq!((s, field(&body)), (422, Some("samples")), "{body}");
    let (s, body) = post_json(
        &c,
        &url,
        json!({"prior": {"mean": [1.0], "cov": [[1.0]]}, "bogus": 1}).to_string(),
    );
    assert_eq!(s, 422, "{body}");
    // Point clouds: NaN, empty, wrong shape, a broken compact form, too many.
    let cloud = |shape: Value| {
        let mut request = typical_request(2);
        let mut o = json!({"id": "cloud", "type": "points", "radius": 0.005});
        for (k, v) in shape.as_object().unwrap() {
            o[k] = v.clone();
        }
        request["obstacles"] = json!([o]);
        let (s, body) = post_json(&c, &url, request.to_string());
        (s, field(&body).map(str::to_string), body)
    };
    for (shape, expected) in [
        (json!({"points": [[0.5, 0.0, "NaN"]]}), "obstacles[0]"),
        (json!({"points": []}), "obstacles[0].points"),
        (json!({"points": [[0.5, 0.0]]}), "obstacles[0]"),
        (
            json!({"points": [[0.5, 0.0, 0.5]], "radius": -1.0}),
            "obstacles[0].radius",
        ),
        (json!({"points_base64": "AAAA"}), "obstacles[0]"),
    ] {
        let (s, f, body) = cloud(shape.clone());
        assert_eq!(s, 422, "{shape}: {body}");
        assert!(
            f.as_deref().is_some_and(|f| f.starts_with(expected)),
            "{shape}: {body}"
        );
    }
    // Beyond the per-obstacle cap (the body limit is raised for it).
    let big_server = start(test_config().with_body_limit(8 << 20));
    let many = vec![[0.5, 0.0, 0.5]; dpmp::scene::obstacle::MAX_CLOUD_POINTS + 1];
    let mut request = typical_request(2);
    request["obstacles"] =
        json!([{"id": "cloud", "type": "points", "points": many, "radius": 0.005}]);
    let (s, body) = post_json(&c, &big_server.url("/v1/optimize"), request.to_string());
    assert_eq!(s, 422, "{body}");
    assert!(
        field(&body).is_some_and(|f| f.starts_with("obstacles")),
        "{body}"
    );
}

#[test]
fn plan_validates_and_answers_503_without_a_model() {
    use base64::Engine as _;
    let server = start(test_config().with_body_limit(4 << 20));
    let c = client();
    let url = server.url("/v1/plan");
    let mut png = Vec::new();
    image::DynamicImage::new_rgb8(64, 48)
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let b64 = base64::engine::general_purpose::STANDARD.encode(&png);
    let valid = json!({"image_base64": b64, "target_box": [10, 10, 20, 20], "clearance_m": 0.02});
    let (s, body) = post_json(&c, &url, valid.to_string());
    assert_eq!((s, code(&body)), (503, "model_unavailable"), "{body}");
    // Multipart with the same content reaches the same point.
    let form = reqwest::blocking::multipart::Form::new()
        .part(
            "image",
            reqwest::blocking::multipart::Part::bytes(png.clone()).file_name("x.png"),
        )
        .text(
            "request",
            json!({"target_box": [10, 10, 20, 20]}).to_string(),
        );
    let (s, body) = status_and_json(c.post(&url).multipart(form).send().unwrap());
    assert_eq!((s, code(&body)), (503, "model_unavailable"), "{body}");
    for (patch, status, fld) in [
        (json!({"image_base64": "@@@"}), 400, Some("image_base64")),
        (
            json!({"target_box": [10, 10, 5, 20]}),
            422,
            Some("target_box"),
        ),
        (
            json!({"target_box": [10, 10, 65, 20]}),
            422,
            Some("target_box"),
        ),
        (json!({"mask_applied": "yes"}), 422, Some("mask_applied")),
        (
            json!({"prior": {"mean": [], "cov": []}}),
            422,
            Some("prior"),
        ),
        (
            json!({"obstacles": [{"id": "a", "type": "sphere", "center": [0, 0], "radius": 0.1}]}),
            422,
            None,
        ),
        (
            json!({"image_base64": base64::engine::general_purpose::STANDARD.encode(b"GIF89a.....")}),
            415,
            Some("image_base64"),
        ),
    ] {
        let mut request = valid.clone();
        for (k, v) in patch.as_object().unwrap() {
            request[k] = v.clone();
        }
        let (s, body) = post_json(&c, &url, request.to_string());
        assert_eq!(s, status, "{patch} -> {body}");
        if fld.is_some() {
            assert_eq!(field(&body), fld, "{patch} -> {body}");
        }
    }
    let form = reqwest::blocking::multipart::Form::new().text("request", "{}");
    let (s, body) = status_and_json(c.post(&url).multipart(form).send().unwrap());
    assert_eq!((s, code(&body)), (400, "malformed_multipart"));
}

/// `trajectory_msgs/msg/JointTrajectory` and the messages it holds, field
/// for field as ROS 2 defines them (rosidl), for the round trip above.
mod ros2 {
    use serde::{Deserialize, Serialize};

    /// `builtin_interfaces/msg/Time` and `Duration`.
    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Time {
        pub sec: i32,
        pub nanosec: u32,
    }

    /// `std_msgs/msg/Header`.
    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Header {
        pub stamp: Time,
        pub frame_id: String,
    }

    /// `trajectory_msgs/msg/JointTrajectoryPoint`.
    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct JointTrajectoryPoint {
        pub positions: Vec<f64>,
        pub velocities: Vec<f64>,
        pub accelerations: Vec<f64>,
        pub effort: Vec<f64>,
        pub time_from_start: Time,
    }

    /// `trajectory_msgs/msg/JointTrajectory`.
    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct JointTrajectory {
        pub header: Header,
        pub joint_names: Vec<String>,
        pub points: Vec<JointTrajectoryPoint>,
    }
}

/// The `/metrics` exposition text.
fn metrics_text(c: &reqwest::blocking::Client, server: &dpmp::service::RunningServer) -> String {
    c.get(server.url("/metrics"))
        .send()
        .unwrap()
        .text()
        .unwrap()
}

/// What an outside probe found, each answered in the client's own terms:
/// the prior in one form only, no Rust type or decoder internals in a
/// message, a goal out of reach named as such, no path on the open
/// `/readyz`.
#[test]
fn answers_speak_the_clients_terms() {
    let server = start_with_default_model();
    let c = client();
    let url = server.url("/v1/optimize");
    let request = typical_request(2);
    let prior = request["prior"].clone();
    // Both forms at once, an unknown key, an empty annotation.
    let mut both = prior.clone();
    both["annotation"] = json!([]);
    let mut unknown = prior.clone();
    unknown["weights"] = json!([1.0]);
    for (bad, words) in [
        (both, "not both"),
        (unknown, "unknown field `weights`"),
        (json!({"annotation": []}), "7"),
    ] {
        let mut r = request.clone();
        r["prior"] = bad;
        let (s, body) = post_json(&c, &url, r.to_string());
        assert_eq!(
            (s, field(&body).map(|f| f.starts_with("prior"))),
            (422, Some(true)),
            "{body}"
        );
        let message = body["error"]["message"].as_str().unwrap();
        assert!(message.contains(words), "{message}");
    }
    // Wrong top-level shapes name no Rust type.
    for bad in ["[]", "7", "{\"goal\": 3}", "{\"boundary\": 3}"] {
        let (s, body) = post_json(&c, &url, bad);
        assert_eq!(s, 422, "{bad}: {body}");
        let message = body["error"]["message"].as_str().unwrap();
        for internal in ["struct", "enum", "Wire", "Spec"] {
            assert!(!message.contains(internal), "{bad}: {message}");
        }
    }
    // An approach tolerance out of range is refused with or without an axis.
    let mut wide = request.clone();
    wide["goal"]["approach_tolerance_rad"] = json!(4.0);
    let (s, body) = post_json(&c, &url, wide.to_string());
    assert_eq!(
        (s, field(&body)),
        (422, Some("goal.approach_tolerance_rad")),
        "{body}"
    );
    // A goal the arm cannot reach: proven infeasible with the reason, not
    // a numerical failure.
    let mut far = request.clone();
    far["goal"] = json!({"position": [4.0, 0.0, 0.5]});
    let (s, body) = post_json(&c, &url, far.to_string());
    assert_eq!(
        (s, body["status"].as_str()),
        (200, Some("infeasible")),
        "{body}"
    );
    assert!(body["reason"].as_str().unwrap().contains("reach"), "{body}");
    // A corrupt PNG: what is wrong, not the decoder's debug text.
    let png = {
        let mut out = std::io::Cursor::new(Vec::new());
        image::DynamicImage::ImageRgb8(image::RgbImage::new(640, 480))
            .write_to(&mut out, image::ImageFormat::Png)
            .unwrap();
        let mut bytes = out.into_inner();
        let n = bytes.len();
        for b in &mut bytes[60..n - 20] {
            *b ^= 0x5a;
        }
        bytes
    };
    use base64::Engine as _;
    let plan = json!({
        "image_base64": base64::engine::general_purpose::STANDARD.encode(&png),
        "target_box": [300, 200, 340, 250],
        "target_position": [0.6, 0.05, 0.55],
    });
    let (s, body) = post_json(&c, &server.url("/v1/plan"), plan.to_string());
    assert_eq!((s, code(&body)), (400, "malformed_image"), "{body}");
    let message = body["error"]["message"].as_str().unwrap();
    assert!(
        !message.contains('{') && !message.contains("Chunk"),
        "{message}"
    );
    // The open readiness probe names the model's folder, not its path.
    let (_, ready) = status_and_json(c.get(server.url("/readyz")).send().unwrap());
    assert_eq!(ready["model"]["source"], json!("default"), "{ready}");
}
