//! `world: "depth"`: the plan's world sensed from the depth image, on
//! generated targets with an intruder across their path (`--intruders`).
//! Checked against what the generator knows: every sensed point lies on a
//! true surface, the target is kept out of the cloud, the plan keeps clear
//! of the intruder the prior runs into (exact distances to the true scene,
//! dense in time), and the HTTP interface carries the field, its report
//! and its refusals.

use crate::common::http::*;
use base64::Engine as _;
use dpmp::net::Model;
use dpmp::optim::{Status, Task};
use dpmp::plan::world::{point_radius_m, SENSED_OBSTACLE_ID, UNSEEN_NOTE};
use dpmp::plan::{predict_and_optimize, PlanFields, PlanParts, PlanRequest, WorldSource};
use dpmp::robot::Robot;
use dpmp::scene::{Obstacle, Scene};
use dpmp::synth::generate::{ConfigOutput, Generator};
use dpmp::synth::settings::SynthSettings;
use serde_json::{json, Value};
use std::sync::Arc;

const CLEARANCE_M: f64 = 0.015;

/// One configuration of 2 berries, each with an intruder.
fn with_intruders(config: usize) -> ConfigOutput {
    let settings = SynthSettings {
        intruders: 1,
        ..SynthSettings::new(1, 2)
    };
    let generator = Generator::new(settings, Robot::panda().unwrap()).unwrap();
    generator.config(31337, config).unwrap()
}

fn parts(out: &ConfigOutput, i: usize, world: WorldSource, obstacles: Vec<Obstacle>) -> PlanParts {
    let record = &out.records[i];
    let task = Task {
        start: Some(record.start.clone()),
        obstacles,
        clearance_m: CLEARANCE_M,
        ..Task::default()
    };
    let image = image::DynamicImage::ImageRgb8(out.images[i].clone());
    PlanParts {
        mask_applied: true,
        depth: out.depths[i].clone(),
        world,
        ..PlanParts::new(image, record.bbox, task)
    }
}

/// The least distance of the answer's trajectory to `truth` (exact hull
/// distances at 1,000 phases).
fn true_clearance(robot: &Robot, truth: &Scene, weights: &[f64]) -> f64 {
    let basis = dpmp::promp::Basis::new(&Default::default())
        .unwrap()
        .resampled(1000)
        .unwrap();
    let nb = basis.n_basis();
    let w = nalgebra::DMatrix::from_fn(nb, robot.dof(), |i, j| weights[j * nb + i]);
    let q = basis.matrix() * w;
    (0..q.nrows())
        .filter_map(|t| {
            let row: Vec<f64> = q.row(t).iter().copied().collect();
            truth.min_clearance(robot, &robot.fk(&row))
        })
        .map(|c| c.distance)
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn the_sensed_world_keeps_the_plan_clear_of_what_the_prior_runs_into() {
    let model = Arc::new(Model::load_or_shipped(None).unwrap());
    let robot = Arc::new(Robot::panda().unwrap());
    let (mut blocked, mut cleared) = (0, 0);
    for config in 0..2 {
        let out = with_intruders(config);
        for (i, record) in out.records.iter().enumerate() {
            let truth = Scene::new(record.scene.obstacles()).unwrap();
            let intruders = record.scene.intruders();
            assert!(!intruders.is_empty(), "{}: no intruder", record.id);
            let plan = |world| {
                let request =
                    PlanRequest::new(parts(&out, i, world, Vec::new()), &PlanFields::json())
                        .unwrap();
                predict_and_optimize(&model, &robot, request, &Default::default()).unwrap()
            };
            let blind = plan(WorldSource::None);
            if true_clearance(&robot, &truth, &blind.result.weights) < 0.010 {
                blocked += 1;
            }
            assert!(blind.world.is_none());
            let sensed = plan(WorldSource::Depth);
            let report = sensed.world.as_ref().expect("a world report");
            assert!(report.points > 200, "{} points", report.points);
            assert!(report.removed_as_target > 0);
            assert_eq!(report.note, UNSEEN_NOTE);
            assert!(report.radius_m >= point_radius_m(&Default::default(), 0.0));
            if sensed.result.status == Status::Optimal {
                let d = true_clearance(&robot, &truth, &sensed.result.weights);
                assert!(
                    d >= 0.010,
                    "{}: the depth world's optimal plan is {d} m from the true scene",
                    record.id
                );
                cleared += 1;
            }
        }
    }
    // The prior alone runs into most intruders; the sensed world clears them.
    assert!(blocked >= 2, "only {blocked} of 4 blind plans collide");
    assert!(cleared >= 3, "only {cleared} of 4 depth plans are optimal");
}

/// The cloud the plan is given, rebuilt through the library as the plan
/// builds it.
fn sensed_cloud(out: &ConfigOutput, i: usize) -> (Vec<[f64; 3]>, f64) {
    let model = Model::load_or_shipped(None).unwrap();
    let robot = Robot::panda().unwrap();
    let camera = dpmp::perception::Camera::at_home(&model.config().camera_model(), &robot).unwrap();
    let depth = out.depths[i].as_ref().unwrap();
    let cloud = dpmp::perception::cloud::depth_cloud(depth, &camera, &Default::default(), None);
    let radius = point_radius_m(&Default::default(), cloud.max_depth_m);
    (cloud.points, radius)
}

#[test]
fn every_sensed_point_lies_on_a_true_surface() {
    let out = with_intruders(0);
    let record = &out.records[0];
    let truth = Scene::new(record.scene.obstacles()).unwrap();
    let (points, _) = sensed_cloud(&out, 0);
    assert!(points.len() > 500, "{} points", points.len());
    // Projection and back-projection agree with the renderer: each point
    // (a voxel's mean of returns) is within a voxel diagonal and the depth
    // noise of some true obstacle (parry's point distance to its parts).
    let far = points
        .iter()
        .filter(|p| {
            truth
                .obstacle_containing(&nalgebra::Point3::from(**p), 0.0087 + 0.005)
                .is_none()
        })
        .count();
    assert!(
        far * 100 <= points.len(),
        "{far} of {} points lie off every true surface",
        points.len()
    );
}

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

#[test]
fn http_plans_with_the_depth_world_and_refuses_it_without_depth() {
    let out = with_intruders(0);
    let record = &out.records[0];
    let mut png = Vec::new();
    image::DynamicImage::ImageRgb8(out.images[0].clone())
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let depth = out.depths[0].as_ref().unwrap().encode_png().unwrap();
    let server = start_with_default_model();
    let c = client();
    let url = server.url("/v1/plan");
    let body = json!({
        "image_base64": b64(&png),
        "depth_base64": b64(&depth),
        "target_box": record.bbox,
        "mask_applied": true,
        "start": record.start,
        "clearance_m": CLEARANCE_M,
        "world": "depth",
    });
    let (s, answer) = post_json(&c, &url, body.to_string());
    assert_eq!(s, 200, "{answer}");
    assert_valid(&openapi(), "post", "/v1/plan", s, &answer);
    let world = &answer["world"];
    assert_eq!(world["source"], "depth");
    assert!(world["points"].as_u64().unwrap() > 200, "{world}");
    assert!(world["removed_as_target"].as_u64().unwrap() > 0);
    assert_eq!(world["note"], UNSEEN_NOTE);
    // Mistakes name the field.
    let refused = |mut b: Value, edit: &dyn Fn(&mut Value)| {
        edit(&mut b);
        let (s, e) = post_json(&c, &url, b.to_string());
        assert_eq!(s, 422, "{e}");
        e["error"]["field"].as_str().unwrap().to_string()
    };
    let no_depth = |b: &mut Value| {
        b.as_object_mut().unwrap().remove("depth_base64");
    };
    assert_eq!(refused(body.clone(), &no_depth), "world");
    assert_eq!(
        refused(body.clone(), &|b| b["world"] = json!("lidar")),
        "world"
    );
    assert_eq!(refused(body.clone(), &|b| b["world"] = json!(3)), "world");
    let clash = |b: &mut Value| {
        b["obstacles"] = json!([{"id": SENSED_OBSTACLE_ID, "type": "sphere",
            "center": [2.0, 0.0, 0.0], "radius": 0.1}]);
    };
    assert_eq!(refused(body, &clash), "world");
}

/// A record's scene, intruder labels and all, is posted as it is: the
/// labels are set aside, every obstacle is planned around, and reading the
/// record back keeps them.
#[test]
fn a_records_scene_posts_as_it_is_and_keeps_its_intruder_labels() {
    let out = with_intruders(0);
    let record = &out.records[0];
    let text = serde_json::to_value(&record.scene).unwrap();
    assert!(
        text["obstacles"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["intruder"] == json!(true)),
        "{text}"
    );
    let back: dpmp::synth::dataset::RecordScene = serde_json::from_value(text.clone()).unwrap();
    assert_eq!(&back, &record.scene);
    assert!(!back.intruders().is_empty());
    // Into an optimise request as written.
    let mut request = crate::common::requests::typical_json(1, &Default::default());
    request["obstacles"] = text["obstacles"].clone();
    request["start"] = json!(record.start);
    request.as_object_mut().unwrap().remove("goal");
    let parsed: dpmp::optim::OptimizeRequest = serde_json::from_value(request.clone()).unwrap();
    assert_eq!(parsed.task.obstacles, record.scene.obstacles());
    let server = start(test_config());
    let (s, body) = post_json(&client(), &server.url("/v1/optimize"), request.to_string());
    assert_eq!(s, 200, "{body}");
}
