//! `POST /v1/plan` over a real socket with the shipped `models/default`: a
//! freshly generated plant image (640x480 JPEG) and its scene go in, the
//! network's prior and the optimised trajectory come out. Checked: the
//! answer validates against `api/openapi.yaml`, the prior has the grid's
//! shape with a positive spread, the trajectory keeps the joint limits and
//! (when `optimal`) the requested clearance, JSON and multipart give the
//! same plan, and the same request gives the same bytes (bar `solve_ms`).

use crate::common::http::*;
use crate::common::json::numbers;
use crate::common::robot::final_tcp_pose;
use base64::Engine as _;
use dpmp::net::Model;
use dpmp::robot::Robot;
use dpmp::service::{AppState, RunningServer};
use dpmp::synth::dataset::TargetRecord;
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use serde_json::{json, Value};
use std::path::Path;

const CLEARANCE_M: f64 = 0.02;

/// One generated target: JPEG bytes, its box and its scene's obstacles.
fn generated_target() -> (Vec<u8>, [f64; 4], Value) {
    let (jpeg, _, record) = generated_target_with_depth();
    let obstacles = serde_json::to_value(record.scene.obstacles()).unwrap();
    (jpeg, record.bbox, obstacles)
}

/// One generated target: JPEG bytes, its aligned depth PNG, its record.
fn generated_target_with_depth() -> (Vec<u8>, Vec<u8>, TargetRecord) {
    let generator = Generator::new(SynthSettings::new(1, 1), Robot::panda().unwrap()).unwrap();
    let out = generator.config(21, 0).unwrap();
    let mut jpeg = Vec::new();
    image::DynamicImage::ImageRgb8(out.images[0].clone())
        .write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
    let depth = out.depths[0].as_ref().unwrap().encode_png().unwrap();
    (jpeg, depth, out.records[0].clone())
}

/// A server with the shipped model and its answer (200, contract-checked)
/// to the generated target with depth, with everything that made it.
struct DepthPlan {
    _server: RunningServer,
    c: reqwest::blocking::Client,
    url: String,
    jpeg: Vec<u8>,
    depth: Vec<u8>,
    record: TargetRecord,
    fields: Value,
    body: Value,
    answer: Value,
}

fn plan_generated_target_with_depth() -> DepthPlan {
    let server = start_with_default_model();
    let c = client();
    let url = server.url("/v1/plan");
    let (jpeg, depth, record) = generated_target_with_depth();
    let (fields, body) = depth_request(&jpeg, &depth, &record);
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{answer}");
    assert_valid(&openapi(), "post", "/v1/plan", s, &answer);
    DepthPlan {
        _server: server,
        c,
        url,
        jpeg,
        depth,
        record,
        fields,
        body,
        answer,
    }
}

#[test]
fn plan_with_the_shipped_model_over_http() {
    let DepthPlan {
        _server,
        c,
        url,
        jpeg,
        depth,
        fields,
        body,
        answer,
        ..
    } = plan_generated_target_with_depth();

    // The prior: 150 samples x 7 joints, positive spread.
    let mean = answer["prior"]["mean"].as_array().unwrap();
    let std = answer["prior"]["std"].as_array().unwrap();
    assert_eq!((mean.len(), std.len()), (150, 150));
    for row in std {
        let row = row.as_array().unwrap();
        assert_eq!(row.len(), 7);
        assert!(row.iter().all(|v| v.as_f64().unwrap() > 0.0));
    }
    assert!(!answer["model"].as_str().unwrap().is_empty());

    // The trajectory keeps the joint limits; an optimal one the clearance.
    let robot = Robot::panda().unwrap();
    let points = answer["trajectory"]["points"].as_array().unwrap();
    assert_eq!(points.len(), 150);
    for p in points {
        for (v, lim) in p["positions"]
            .as_array()
            .unwrap()
            .iter()
            .zip(robot.limits())
        {
            let v = v.as_f64().unwrap();
            assert!(
                v >= lim.lower - 1e-6 && v <= lim.upper + 1e-6,
                "{v} outside {lim:?}"
            );
        }
    }
    let status = answer["status"].as_str().unwrap();
    assert!(["optimal", "infeasible", "max_iterations"].contains(&status));
    if status == "optimal" {
        let clearance = answer["report"]["min_clearance_m"].as_f64().unwrap();
        assert!(clearance >= CLEARANCE_M - 1e-6, "clearance {clearance}");
    }

    // Multipart (image and depth parts + JSON part) plans the same
    // trajectory, and the same JSON request gives the same answer.
    let form = reqwest::blocking::multipart::Form::new()
        .part(
            "image",
            reqwest::blocking::multipart::Part::bytes(jpeg).file_name("plant.jpg"),
        )
        .part("depth", reqwest::blocking::multipart::Part::bytes(depth))
        .text("request", fields.to_string());
    let (s, multipart) = status_and_json(c.post(&url).multipart(form).send().unwrap());
    assert_eq!(s, 200, "{multipart}");
    assert_eq!(multipart["trajectory"], answer["trajectory"]);
    let (_, again) = post_json(&c, &url, body.to_string());
    assert_eq!(without_timing(again), without_timing(answer));
}

#[test]
fn without_depth_or_target_no_goal_is_derived() {
    // A box-only model (freshly initialised: the path, not the accuracy).
    let config = dpmp::net::ModelConfig::new("box-only", dpmp::net::Arch::Cvae);
    let network = dpmp::net::Network::new(config, 5, &candle_core::Device::Cpu).unwrap();
    let model = Model::from_network(network);
    let state = AppState::new(test_config(), Robot::panda().unwrap(), Some(model)).unwrap();
    let server = RunningServer::start(state).unwrap();
    let c = client();
    let url = server.url("/v1/plan");
    let (jpeg, bbox, obstacles) = generated_target();
    let body = json!({
        "image_base64": base64::engine::general_purpose::STANDARD.encode(&jpeg),
        "target_box": bbox,
        "mask_applied": true,
        "obstacles": obstacles,
        "clearance_m": CLEARANCE_M,
    });
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{answer}");
    assert_valid(&openapi(), "post", "/v1/plan", s, &answer);
    assert!(answer.get("target").is_none());
    let (_, again) = post_json(&c, &url, body.to_string());
    assert_eq!(without_timing(again), without_timing(answer));
}

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// The plan fields of a generated target (box, scene, clearance), and the
/// whole JSON body with its image and depth as base64.
fn depth_request(jpeg: &[u8], depth: &[u8], record: &TargetRecord) -> (Value, Value) {
    let fields = json!({
        "target_box": record.bbox,
        "mask_applied": true,
        "obstacles": record.scene.obstacles(),
        "clearance_m": CLEARANCE_M,
    });
    let mut body = fields.clone();
    body["image_base64"] = json!(b64(jpeg));
    body["depth_base64"] = json!(b64(depth));
    (fields, body)
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn plan_with_depth_goes_to_the_berry_it_measured() {
    let DepthPlan {
        _server,
        c,
        url,
        jpeg,
        depth,
        record,
        fields,
        answer,
        ..
    } = plan_generated_target_with_depth();

    // The measured berry, and the goal 10 cm short of it towards home.
    let target = &answer["target"];
    assert_eq!(target["source"], "depth");
    let position = numbers(&target["position"]);
    assert!(
        distance(&position, &record.target_position.unwrap()) < 0.008,
        "{target}"
    );
    let robot = Robot::panda().unwrap();
    let home = robot.tcp_pose(&robot.home()).translation.vector;
    let goal = numbers(&target["goal"]);
    assert!((distance(&goal, &position) - 0.10).abs() < 1e-9);
    let towards_home =
        distance(&goal, home.as_slice()) + 0.10 - distance(&position, home.as_slice());
    assert!(towards_home.abs() < 1e-9, "goal not on the line to home");

    // An optimal plan ends within the goal's tolerance, near the demos.
    assert_eq!(answer["status"], "optimal", "{}", answer["reason"]);
    let tcp = final_tcp_pose(&robot, &answer).translation.vector;
    let tolerance = target["goal_tolerance_m"].as_f64().unwrap();
    assert!(distance(tcp.as_slice(), &goal) <= tolerance + 1e-6);
    assert!(distance(tcp.as_slice(), &record.final_tcp.position) < 0.015);

    // Multipart with a depth part plans the same; a client position too.
    let form = reqwest::blocking::multipart::Form::new()
        .part(
            "image",
            reqwest::blocking::multipart::Part::bytes(jpeg.clone()),
        )
        .part(
            "depth",
            reqwest::blocking::multipart::Part::bytes(depth.clone()),
        )
        .text("request", fields.to_string());
    let (s, multipart) = status_and_json(c.post(&url).multipart(form).send().unwrap());
    assert_eq!(s, 200, "{multipart}");
    assert_eq!(multipart["trajectory"], answer["trajectory"]);
    let mut client_target = fields.clone();
    client_target["image_base64"] = json!(b64(&jpeg));
    client_target["target_position"] = json!(position);
    let (s, own) = post_json(&c, &url, client_target.to_string());
    assert_eq!(s, 200, "{own}");
    assert_eq!(own["target"]["source"], "client");
    assert_eq!(own["target"]["goal"], answer["target"]["goal"]);
}

#[test]
fn bad_depth_inputs_are_422_naming_the_field() {
    let server = start_with_default_model();
    let c = client();
    let url = server.url("/v1/plan");
    let (jpeg, depth, record) = generated_target_with_depth();
    let png16 = |w: u32, h: u32, value: u16| {
        let d = dpmp::perception::DepthImage::new(w, h, 0.001, vec![value; (w * h) as usize], "d");
        d.unwrap().encode_png().unwrap()
    };
    let base = json!({
        "target_box": record.bbox,
        "mask_applied": true,
        "image_base64": b64(&jpeg),
    });
    // A colour image (and its depth) not of the camera's size: the colour
    // image is named, not the depth.
    let small = {
        let mut out = std::io::Cursor::new(Vec::new());
        image::DynamicImage::ImageRgb8(image::RgbImage::new(320, 240))
            .write_to(&mut out, image::ImageFormat::Png)
            .unwrap();
        out.into_inner()
    };
    let cases = [
        (
            "image_base64",
            json!({"image_base64": b64(&small), "target_box": [10, 10, 40, 40],
                   "depth_base64": b64(&png16(320, 240, 500))}),
        ),
        (
            "depth_base64",
            json!({"depth_base64": b64(&png16(320, 240, 500))}),
        ),
        (
            "depth_base64",
            json!({"depth_base64": b64(&png16(640, 480, 0))}),
        ),
        ("depth_base64", json!({"depth_base64": b64(&jpeg)})),
        ("depth_base64", json!({"depth_base64": 7})),
        (
            "target_position",
            json!({"depth_base64": b64(&depth), "target_position": [0.7, 0.0, 0.7]}),
        ),
        ("target_position", json!({"target_position": [0.7, 0.0]})),
        (
            "target_position",
            json!({"target_position": [0.7, 0.0, 1e9]}),
        ),
        ("depth_scale_m", json!({"depth_scale_m": 0.001})),
        (
            "depth_scale_m",
            json!({"depth_base64": b64(&depth), "depth_scale_m": -1.0}),
        ),
        ("goal_standoff_m", json!({"goal_standoff_m": 0.1})),
        (
            "goal_standoff_m",
            json!({"depth_base64": b64(&depth), "goal_standoff_m": 2.0}),
        ),
        (
            "goal",
            json!({"depth_base64": b64(&depth), "goal": {"position": [0.6, 0.0, 0.7]}}),
        ),
    ];
    for (expected, extra) in cases {
        let mut body = base.clone();
        for (k, v) in extra.as_object().unwrap() {
            body[k] = v.clone();
        }
        let (s, answer) = post_json(&c, &url, body.to_string());
        assert_eq!(
            (s, field(&answer)),
            (422, Some(expected)),
            "{extra}: {answer}"
        );
    }
    // A berry out of the arm's reach is named by the field it came from,
    // before any numerics: depth of 30 m everywhere, a scale 1000x too
    // large, a client position 4 m away.
    let far_cases = [
        (
            "depth_base64",
            json!({"depth_base64": b64(&png16(640, 480, 30_000))}),
        ),
        (
            "depth_scale_m",
            json!({"depth_base64": b64(&depth), "depth_scale_m": 1.0}),
        ),
        (
            "target_position",
            json!({"target_position": [4.0, 0.0, 0.5]}),
        ),
    ];
    for (expected, extra) in far_cases {
        let mut body = base.clone();
        for (k, v) in extra.as_object().unwrap() {
            body[k] = v.clone();
        }
        let (s, answer) = post_json(&c, &url, body.to_string());
        assert_eq!((s, field(&answer)), (422, Some(expected)), "{answer}");
        let message = answer["error"]["message"].as_str().unwrap();
        assert!(message.contains("beyond its reach (1.09 m)"), "{message}");
        assert_eq!(code(&answer), "invalid_input", "{answer}");
    }
}

#[test]
fn a_depth_conditioned_model_needs_depth() {
    let mut config = dpmp::net::ModelConfig::new("depth-cvae", dpmp::net::Arch::Cvae);
    config.depth_condition = true;
    let network = dpmp::net::Network::new(config, 3, &candle_core::Device::Cpu).unwrap();
    let model = Model::from_network(network);
    let state = AppState::new(test_config(), Robot::panda().unwrap(), Some(model)).unwrap();
    let server = RunningServer::start(state).unwrap();
    let c = client();
    let url = server.url("/v1/plan");
    let (jpeg, depth, record) = generated_target_with_depth();
    let mut body = json!({
        "target_box": record.bbox,
        "mask_applied": true,
        "image_base64": b64(&jpeg),
        "obstacles": record.scene.obstacles(),
    });
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!((s, field(&answer)), (422, Some("depth_base64")), "{answer}");
    // With depth (or a 3-D target) it plans.
    body["depth_base64"] = json!(b64(&depth));
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{answer}");
    body.as_object_mut().unwrap().remove("depth_base64");
    body["target_position"] = json!(record.target_position);
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{answer}");
}

#[test]
fn the_service_refuses_a_model_trained_for_another_robot() {
    let mut config = dpmp::net::ModelConfig::new("hand-model", dpmp::net::Arch::Cvae);
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/panda/panda.urdf");
    let hand = Robot::from_urdf_file(&urdf, "panda_link0", "panda_hand").unwrap();
    config.robot = Some(hand.identity());
    let network = dpmp::net::Network::new(config, 1, &candle_core::Device::Cpu).unwrap();
    let model = Model::from_network(network);
    let e = AppState::new(test_config(), Robot::panda().unwrap(), Some(model)).unwrap_err();
    assert_eq!(e.field(), Some("robot"));
    assert!(e.to_string().contains("hand-model"), "{e}");
    // The model's own robot is accepted.
    let mut config = dpmp::net::ModelConfig::new("hand-model", dpmp::net::Arch::Cvae);
    config.robot = Some(hand.identity());
    let network = dpmp::net::Network::new(config, 1, &candle_core::Device::Cpu).unwrap();
    assert!(AppState::new(test_config(), hand, Some(Model::from_network(network))).is_ok());
}

/// The server, client, URL, body and answer of the plan with depth and
/// no other constraint.
fn free_depth_plan() -> (
    RunningServer,
    reqwest::blocking::Client,
    String,
    Value,
    Value,
) {
    let p = plan_generated_target_with_depth();
    (p._server, p.c, p.url, p.body, p.answer)
}

#[test]
fn a_derived_goal_takes_the_request_s_approach_direction() {
    let (_server, c, url, body, free) = free_depth_plan();
    let robot = Robot::panda().unwrap();
    let final_axis =
        |answer: &Value| final_tcp_pose(&robot, answer).rotation * nalgebra::Vector3::z();
    // Ask for an axis 0.15 rad off the one the plan ends with, within 0.05.
    let a0 = final_axis(&free);
    let side = nalgebra::Unit::new_normalize(a0.cross(&nalgebra::Vector3::x()));
    let axis = nalgebra::UnitQuaternion::from_axis_angle(&side, 0.15) * a0;
    let mut asked = body.clone();
    asked["goal"] =
        json!({"approach_axis": [axis.x, axis.y, axis.z], "approach_tolerance_rad": 0.05});
    let (s, answer) = post_json(&c, &url, asked.to_string());
    assert_eq!(s, 200, "{answer}");
    assert_valid(&openapi(), "post", "/v1/plan", s, &answer);
    assert_eq!(answer["target"]["goal"], free["target"]["goal"]);
    assert_eq!(answer["status"], "optimal", "{}", answer["reason"]);
    let angle = final_axis(&answer).dot(&axis).clamp(-1.0, 1.0).acos();
    assert!(angle <= 0.05 + 1e-6, "{angle} rad");
    let reported = answer["report"]["goal_angle_error_rad"].as_f64().unwrap();
    assert!((reported - angle).abs() < 1e-6);
    // A zero axis, or an unknown key, is refused naming the field.
    for (goal, field) in [
        (
            json!({"approach_axis": [0.0, 0.0, 0.0]}),
            "goal.approach_axis",
        ),
        (json!({"approach_axis": [0.0, 0.0, 1.0], "tilt": 1}), "goal"),
    ] {
        let mut bad = body.clone();
        bad["goal"] = goal;
        let (s, err) = post_json(&c, &url, bad.to_string());
        assert_eq!(s, 422, "{err}");
        assert!(
            super::common::http::field(&err)
                .unwrap_or("")
                .starts_with(field),
            "{err}"
        );
    }
}

#[test]
fn via_points_shape_a_plan_too() {
    // The free plan's TCP halfway through, moved 3 cm up: a plan through
    // it passes within the waypoint's tolerance at that time.
    let (_server, c, url, body, free) = free_depth_plan();
    let robot = Robot::panda().unwrap();
    let points = free["trajectory"]["points"].as_array().unwrap();
    let middle = &points[points.len() / 2];
    let time_s = middle["time_from_start"].as_f64().unwrap();
    let tcp_at = |p: &Value| robot.tcp_pose(&numbers(&p["positions"])).translation.vector;
    let via = tcp_at(middle) + nalgebra::Vector3::new(0.0, 0.0, 0.03);
    let mut asked = body.clone();
    asked["via_points"] =
        json!([{"time_s": time_s, "position": [via.x, via.y, via.z], "tolerance_m": 0.005}]);
    let (s, answer) = post_json(&c, &url, asked.to_string());
    assert_eq!(s, 200, "{answer}");
    assert_valid(&openapi(), "post", "/v1/plan", s, &answer);
    assert_eq!(answer["status"], "optimal", "{}", answer["reason"]);
    let points = answer["trajectory"]["points"].as_array().unwrap();
    let at = points
        .iter()
        .find(|p| (p["time_from_start"].as_f64().unwrap() - time_s).abs() < 1e-9)
        .expect("a sample at the waypoint's time");
    let miss = (tcp_at(at) - via).norm();
    assert!(
        miss <= 0.005 + 1e-6,
        "the TCP passes {miss} m from the waypoint"
    );
    assert!(answer["report"]["via_position_excess_m"].as_f64().unwrap() <= 1e-6);
}

/// A copy of the shipped model whose head weights are scaled by 1e30 (its
/// checksum updated, so it loads): its predictions overflow.
fn broken_model_copy() -> tempfile::TempDir {
    use dpmp::net::checkpoint;
    let dir = tempfile::tempdir().unwrap();
    let from = crate::common::default_model_dir();
    let mut tensors = checkpoint::read_tensors(&from.join(checkpoint::WEIGHTS_FILE)).unwrap();
    for (name, (_, values)) in tensors.iter_mut() {
        if name.starts_with("heads.") {
            values.iter_mut().for_each(|v| *v *= 1e30);
        }
    }
    let named: Vec<(String, candle_core::Tensor)> = tensors
        .iter()
        .map(|(k, (s, v))| {
            let t = candle_core::Tensor::from_slice(v, s.as_slice(), &candle_core::Device::Cpu);
            (k.clone(), t.unwrap())
        })
        .collect();
    let weights = dir.path().join(checkpoint::WEIGHTS_FILE);
    checkpoint::write_tensors(&weights, &named).unwrap();
    let mut config = crate::common::json::read_json(&from.join(checkpoint::CONFIG_FILE));
    config["weights_sha256"] = json!(checkpoint::sha256_hex(&std::fs::read(&weights).unwrap()));
    std::fs::write(dir.path().join(checkpoint::CONFIG_FILE), config.to_string()).unwrap();
    dir
}

#[test]
fn a_model_predicting_an_invalid_prior_is_a_server_error_not_the_clients() {
    let dir = broken_model_copy();
    let model = Model::load(dir.path()).unwrap();
    let state = AppState::new(test_config(), Robot::panda().unwrap(), Some(model)).unwrap();
    let server = RunningServer::start(state).unwrap();
    let (jpeg, depth, record) = generated_target_with_depth();
    let (_, body) = depth_request(&jpeg, &depth, &record);
    let (status, answer) = post_json(&client(), &server.url("/v1/plan"), body.to_string());
    assert_eq!((status, code(&answer)), (500, "model_error"), "{answer}");
    assert_eq!(field(&answer), None, "{answer}");
}

/// Images from another camera plan with that camera's intrinsics: the
/// generated target at half resolution (every second pixel of colour and
/// depth) with the intrinsics halved back-projects to the same berry the
/// full-size images locate.
#[test]
fn a_given_camera_back_projects_its_own_images() {
    let DepthPlan {
        _server,
        c,
        url,
        jpeg,
        depth,
        record,
        fields,
        answer,
        ..
    } = plan_generated_target_with_depth();
    let full = image::load_from_memory(&jpeg).unwrap().to_rgb8();
    let half = image::RgbImage::from_fn(full.width() / 2, full.height() / 2, |x, y| {
        *full.get_pixel(2 * x, 2 * y)
    });
    let mut half_png = Vec::new();
    image::DynamicImage::ImageRgb8(half)
        .write_to(
            &mut std::io::Cursor::new(&mut half_png),
            image::ImageFormat::Png,
        )
        .unwrap();
    let d = dpmp::perception::DepthImage::decode_png(&depth, 0.001, "depth").unwrap();
    let (w, h) = (d.width() / 2, d.height() / 2);
    let units: Vec<u16> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| d.units()[(2 * y * d.width() + 2 * x) as usize])
        .collect();
    let half_depth = dpmp::perception::DepthImage::new(w, h, 0.001, units, "d")
        .unwrap()
        .encode_png()
        .unwrap();
    let model = dpmp::net::Model::shipped().unwrap();
    let mut camera = serde_json::to_value(model.config().camera_model()).unwrap();
    for k in ["fx", "fy", "cx", "cy"] {
        let v = camera["intrinsics"][k].as_f64().unwrap();
        camera["intrinsics"][k] = json!(v / 2.0);
    }
    camera["intrinsics"]["width"] = json!(w);
    camera["intrinsics"]["height"] = json!(h);
    let mut body = fields.clone();
    body["target_box"] = json!(record.bbox.map(|v| v / 2.0));
    body["image_base64"] = json!(b64(&half_png));
    body["depth_base64"] = json!(b64(&half_depth));
    let (s, without) = post_json(&c, &url, body.to_string());
    assert_eq!(
        (s, field(&without)),
        (422, Some("image_base64")),
        "{without}"
    );
    body["camera"] = camera.clone();
    let (s, with) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{with}");
    let here = numbers(&with["target"]["position"]);
    let there = numbers(&answer["target"]["position"]);
    assert!(distance(&here, &there) < 0.005, "{here:?} vs {there:?}");
    // A bad camera is named down to its field.
    camera["intrinsics"]["fx"] = json!(-1.0);
    body["camera"] = camera;
    let (s, bad) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 422, "{bad}");
    assert_eq!(field(&bad), Some("camera.intrinsics.fx"), "{bad}");
}
