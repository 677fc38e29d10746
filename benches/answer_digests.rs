//! SHA-256 of every answer on a fixed set of requests, apart from timing
//! (every `solve_ms` set to 0): the before/after check of a refactor that
//! must not change behaviour. `cargo bench --bench answer_digests >
//! before.txt`, change the code, run it again and `diff` the two files.
//!
//! The set: the typical 100 (`fixtures::typical_request`), the first 40
//! problems of `problems/hard/`, and the plan pipeline on 10 generated
//! plants (the box-only model without depth, the default model with depth).

use dpmp::optim::{optimize_with, OptimizeRequest, SolveControl};
use dpmp::robot::Robot;
use sha2::{Digest, Sha256};
use std::path::Path;
use std::sync::Arc;

/// `value` with every `solve_ms` member set to 0, hashed.
fn digest(mut value: serde_json::Value) -> String {
    zero_timing(&mut value);
    let bytes = serde_json::to_vec(&value).expect("json");
    Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn zero_timing(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Object(map) => {
            for (key, v) in map.iter_mut() {
                if key == "solve_ms" {
                    *v = serde_json::json!(0.0);
                } else {
                    zero_timing(v);
                }
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(zero_timing),
        _ => {}
    }
}

fn optimize_digest(request: &OptimizeRequest, robot: &Robot) -> String {
    match optimize_with(request, robot, &SolveControl::default()) {
        Ok(response) => digest(serde_json::to_value(&response).expect("response json")),
        Err(e) => digest(serde_json::json!({ "error": e.to_string() })),
    }
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let robot = Robot::panda().expect("panda");
    let settings = dpmp::fixtures::ExampleSettings::default();
    for seed in 0..100 {
        let request = dpmp::fixtures::typical_request(&robot, seed, &settings).expect("typical");
        println!("typical-{seed:03} {}", optimize_digest(&request, &robot));
    }
    let hard = dpmp::bench::load_dir(&root.join("problems/hard")).expect("problems/hard");
    for (name, file) in hard.into_iter().take(40) {
        let file: dpmp::bench::ProblemFile = file.expect("hard problem");
        let request: OptimizeRequest = serde_json::from_value(file.request).expect("request");
        println!("{name} {}", optimize_digest(&request, &robot));
    }
    plan_digests(root, Arc::new(robot));
}

/// The plan pipeline on generated plants, each answer hashed.
fn plan_digests(root: &Path, robot: Arc<Robot>) {
    use dpmp::net::Model;
    use dpmp::plan::{predict_and_optimize, PlanFields, PlanParts, PlanRequest};
    use dpmp::synth::generate::Generator;
    use dpmp::synth::settings::SynthSettings;
    let models = ["models/rgb-only", "models/default"];
    let generator = Generator::new(SynthSettings::new(10, 1), (*robot).clone()).expect("generator");
    for dir in models {
        let Ok(model) = Model::load(&root.join(dir)) else {
            println!("{dir} absent");
            continue;
        };
        let model = Arc::new(model);
        let depth_model = model.config().depth_condition;
        for k in 0..10 {
            let out = generator.config(21, k).expect("plant");
            let record = out.records[0].clone();
            let depth = match (&out.depths[0], depth_model || k % 2 == 0) {
                (Some(depth), true) => Some(depth.clone()),
                _ => None,
            };
            let task = dpmp::optim::Task {
                obstacles: record.scene.obstacles(),
                clearance_m: 0.02,
                ..Default::default()
            };
            let image = image::DynamicImage::ImageRgb8(out.images[0].clone());
            let parts = PlanParts {
                mask_applied: true,
                depth,
                ..PlanParts::new(image, record.bbox, task)
            };
            let input = PlanRequest::new(parts, &PlanFields::json()).expect("plan request");
            let answer = match predict_and_optimize(&model, &robot, input, &Default::default()) {
                Ok(r) => digest(serde_json::to_value(&r).expect("plan json")),
                Err(e) => digest(serde_json::json!({ "error": e.to_string() })),
            };
            println!("{dir}-plant-{k} {answer}");
        }
    }
}
