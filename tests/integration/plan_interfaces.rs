//! `dpmp plan` and `/v1/plan` build one `PlanRequest`: the same inputs
//! through the flags (and `--task FILE`) and through the HTTP body give the
//! same answer, every optimiser field of the body has a place on the
//! command line, and the checks that involve several inputs refuse the same
//! mistakes in both (exit 2 / 422, naming the field).

use crate::common::cli::dpmp;
use crate::common::http::{client, field, post_json, start_with_default_model, without_timing};
use base64::Engine as _;
use dpmp::robot::Robot;
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use serde_json::{json, Value};

#[test]
fn the_cli_with_a_task_file_answers_as_the_http_route_does() {
    let generator = Generator::new(SynthSettings::new(1, 1), Robot::panda().unwrap()).unwrap();
    let out = generator.config(21, 0).unwrap();
    let record = out.records[0].clone();
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("image.png");
    out.images[0].save(&image).unwrap();
    let depth_png = out.depths[0].as_ref().unwrap().encode_png().unwrap();
    let depth = dir.path().join("depth.png");
    std::fs::write(&depth, &depth_png).unwrap();
    // Optimiser fields the CLI had no flag for: the start, the trajectory
    // format, the restarts, the joint-limit margin.
    let task = json!({
        "obstacles": record.scene.obstacles(),
        "clearance_m": 0.02,
        "duration_s": record.duration_s,
        "joint_limit_margin_rad": 0.01,
        "options": {"restarts": 2},
    });
    let task_file = dir.path().join("task.json");
    std::fs::write(&task_file, task.to_string()).unwrap();
    let plot = dir.path().join("plan.png");
    let b: Vec<String> = record.bbox.iter().map(|v| v.to_string()).collect();
    let start: Vec<String> = record.start.iter().map(|v| v.to_string()).collect();
    let o = dpmp(&[
        "plan",
        "--image",
        image.to_str().unwrap(),
        "--box",
        &b.join(","),
        "--mask-applied",
        "--depth",
        depth.to_str().unwrap(),
        "--task",
        task_file.to_str().unwrap(),
        "--start",
        &start.join(","),
        "--trajectory-format",
        "ros2",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cli: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(std::fs::metadata(&plot).unwrap().len() > 10_000, "a plot");

    let png = |p: &std::path::Path| {
        base64::engine::general_purpose::STANDARD.encode(std::fs::read(p).unwrap())
    };
    let mut body = task.clone();
    body["image_base64"] = json!(png(&image));
    body["depth_base64"] = json!(base64::engine::general_purpose::STANDARD.encode(&depth_png));
    body["target_box"] = json!(record.bbox);
    body["mask_applied"] = json!(true);
    body["start"] = json!(record.start);
    body["trajectory_format"] = json!("ros2");
    let server = start_with_default_model();
    let (status, http) = post_json(&client(), &server.url("/v1/plan"), body.to_string());
    assert_eq!(status, 200, "{http}");
    assert_eq!(without_timing(cli.clone()), without_timing(http));
    // The flags took effect: the ROS 2 layout, the record's start.
    let points = cli["trajectory"]["points"].as_array().unwrap();
    let first: Vec<f64> = points[0]["positions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for (a, b) in first.iter().zip(&record.start) {
        assert!((a - b).abs() < 1e-6, "{first:?} vs {:?}", record.start);
    }
    assert!(cli["trajectory"]["joint_names"].is_array(), "ros2 layout");

    // The same mistakes are refused by both, naming the field.
    let refused = |extra: &[&str]| {
        let mut args = vec![
            "plan",
            "--image",
            image.to_str().unwrap(),
            "--box",
            "1,1,30,30",
        ];
        args.extend_from_slice(extra);
        let o = dpmp(&args);
        assert_eq!(o.status.code(), Some(2), "{extra:?}");
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    assert!(refused(&["--depth-scale", "0.001"]).contains("--depth-scale"));
    assert!(refused(&["--goal-tolerance", "0.02"]).contains("--goal-tolerance"));
    assert!(refused(&["--trajectory-format", "yaml"]).contains("--trajectory-format"));
    assert!(refused(&["--approach-axis", "0,0,1"]).contains("--approach-axis"));
    let mut only_scale = body.clone();
    only_scale.as_object_mut().unwrap().remove("depth_base64");
    only_scale["depth_scale_m"] = json!(0.001);
    let (status, answer) = post_json(&client(), &server.url("/v1/plan"), only_scale.to_string());
    assert_eq!(status, 422, "{answer}");
    assert_eq!(field(&answer), Some("depth_scale_m"), "{answer}");
}

/// The camera's pose (what the ROS 2 node takes from a `TransformStamped`)
/// is where the depth is back-projected from: the hand camera's own pose
/// at home plans exactly as no pose does, and the same pose moved 5 cm
/// along the base's y axis moves the located berry by those 5 cm.
#[test]
fn a_camera_pose_is_where_the_depth_is_seen_from() {
    use dpmp::net::Model;
    use dpmp::optim::{SolveControl, Task};
    use dpmp::perception::Camera;
    use dpmp::plan::{predict_and_optimize, PlanFields, PlanParts, PlanRequest};
    use nalgebra::{Isometry3, Translation3};
    use std::sync::Arc;

    let robot = Arc::new(Robot::panda().unwrap());
    let model = Arc::new(Model::shipped().unwrap());
    let generator = Generator::new(SynthSettings::new(1, 1), (*robot).clone()).unwrap();
    let out = generator.config(21, 0).unwrap();
    let record = &out.records[0];
    let home = Camera::at_home(&model.config().camera_model(), &robot)
        .unwrap()
        .pose;
    let plan = |pose: Option<Isometry3<f64>>| {
        let parts = PlanParts {
            mask_applied: true,
            depth: out.depths[0].clone(),
            camera_pose: pose,
            ..PlanParts::new(
                image::DynamicImage::ImageRgb8(out.images[0].clone()),
                record.bbox,
                Task::default(),
            )
        };
        let request = PlanRequest::new(parts, &PlanFields::json()).unwrap();
        predict_and_optimize(&model, &robot, request, &SolveControl::default()).unwrap()
    };
    let (none, at_home) = (plan(None), plan(Some(home)));
    let (a, b) = (none.target.unwrap(), at_home.target.unwrap());
    assert_eq!(a.position, b.position);
    assert_eq!(none.result.weights, at_home.result.weights);
    let moved = plan(Some(Translation3::new(0.0, 0.05, 0.0) * home))
        .target
        .unwrap();
    for (axis, shift) in [0.0, 0.05, 0.0].iter().enumerate() {
        let d = moved.position[axis] - a.position[axis];
        assert!((d - shift).abs() < 1e-9, "axis {axis}: moved {d}");
    }
}
