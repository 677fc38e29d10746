//! `POST /v1/plan` over a real socket with the shipped `models/default`: a
//! freshly generated plant image (640x480 JPEG) and its scene go in, the
//! network's prior and the optimised trajectory come out. Checked: the
//! answer validates against `api/openapi.yaml`, the prior has the grid's
//! shape with a positive spread, the trajectory keeps the joint limits and
//! (when `optimal`) the requested clearance, JSON and multipart give the
//! same plan, and the same request gives the same bytes (bar `solve_ms`).

mod http_support;

use base64::Engine as _;
use dpmp::net::Model;
use dpmp::robot::Robot;
use dpmp::service::{AppState, RunningServer};
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use http_support::*;
use serde_json::{json, Value};
use std::path::Path;

const CLEARANCE_M: f64 = 0.02;

/// A server with the shipped robot and model.
fn start_with_default_model() -> RunningServer {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
    let model = Model::load(&dir).expect("models/default is committed with the repository");
    let state = AppState::new(test_config(), Robot::panda().unwrap(), Some(model)).unwrap();
    RunningServer::start(state).unwrap()
}

/// One generated target: JPEG bytes, its box and its scene's obstacles.
fn generated_target() -> (Vec<u8>, [f64; 4], Value) {
    let generator = Generator::new(SynthSettings::new(1, 1), Robot::panda().unwrap()).unwrap();
    let out = generator.config(21, 0).unwrap();
    let mut jpeg = Vec::new();
    image::DynamicImage::ImageRgb8(out.images[0].clone())
        .write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
    let record = &out.records[0];
    let obstacles = serde_json::to_value(&record.scene.obstacles).unwrap();
    (jpeg, record.bbox, obstacles)
}

/// The answer without its wall-clock fields.
fn without_times(mut v: Value) -> Value {
    for key in ["report", "prior_mean_report"] {
        if let Some(r) = v.get_mut(key).and_then(Value::as_object_mut) {
            r.remove("solve_ms");
        }
    }
    v
}

#[test]
fn plan_with_the_shipped_model_over_http() {
    let server = start_with_default_model();
    let c = client();
    let url = server.url("/v1/plan");
    let (jpeg, bbox, obstacles) = generated_target();
    let b64 = base64::engine::general_purpose::STANDARD.encode(&jpeg);
    let fields = json!({
        "target_box": bbox,
        "mask_applied": true,
        "obstacles": obstacles,
        "clearance_m": CLEARANCE_M,
    });
    let mut body = fields.clone();
    body["image_base64"] = json!(b64);
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{answer}");
    assert_valid(&openapi(), "post", "/v1/plan", s, &answer);

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

    // Multipart (image part + JSON part) plans the same trajectory, and
    // the same JSON request gives the same answer.
    let form = reqwest::blocking::multipart::Form::new()
        .part(
            "image",
            reqwest::blocking::multipart::Part::bytes(jpeg).file_name("plant.jpg"),
        )
        .text("request", fields.to_string());
    let (s, multipart) = status_and_json(c.post(&url).multipart(form).send().unwrap());
    assert_eq!(s, 200, "{multipart}");
    assert_eq!(multipart["trajectory"], answer["trajectory"]);
    let (_, again) = post_json(&c, &url, body.to_string());
    assert_eq!(without_times(again), without_times(answer));
}
