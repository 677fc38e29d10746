//! `dpmp plan` end to end with the shipped `models/default`: a one-plant
//! dataset is generated into a temp dir with `dpmp data generate`, and the
//! plan answer for one of its images (box and scene from the record) is
//! checked: a 150 x 7 prior with positive spread, a trajectory inside the
//! Panda's joint limits, a known status and a finite clearance report.

use dpmp::robot::Robot;
use serde_json::Value;
use std::path::{Path, PathBuf};
mod cli_support;

use cli_support::dpmp;

fn default_model() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default")
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Generate one plant, return (dataset dir, first record).
fn one_plant(dir: &Path) -> (PathBuf, Value) {
    let data = dir.join("data");
    let o = dpmp(&[
        "data",
        "generate",
        "--out",
        data.to_str().unwrap(),
        "--configs",
        "1",
        "--berries-per-config",
        "1",
        "--demos",
        "2",
        "--seed",
        "11",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest = read_json(&data.join("manifest.json"));
    let entries = manifest["targets"]
        .as_array()
        .or_else(|| manifest["entries"].as_array())
        .expect("manifest lists its targets");
    let record_path = data.join(entries[0]["record"].as_str().unwrap());
    (data, read_json(&record_path))
}

#[test]
fn plan_with_the_shipped_model_gives_a_valid_trajectory() {
    let model = default_model();
    assert!(
        model.join("model.safetensors").is_file(),
        "models/default is committed with the repository"
    );
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let image = data.join(record["image"].as_str().unwrap());
    let b: Vec<String> = record["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap().to_string())
        .collect();
    let scene = dir.path().join("scene.json");
    std::fs::write(&scene, record["scene"].to_string()).unwrap();
    let o = dpmp(&[
        "plan",
        "--image",
        image.to_str().unwrap(),
        "--box",
        &b.join(","),
        "--mask-applied",
        "--scene",
        scene.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();

    let status = answer["status"].as_str().unwrap();
    assert!(
        ["optimal", "infeasible", "max_iterations"].contains(&status),
        "{status}"
    );
    // Prior: T x 7 mean and (positive) standard deviation.
    let mean = answer["prior"]["mean"].as_array().unwrap();
    let std = answer["prior"]["std"].as_array().unwrap();
    assert_eq!(mean.len(), 150);
    assert_eq!(std.len(), 150);
    for (m, s) in mean.iter().zip(std) {
        assert_eq!(m.as_array().unwrap().len(), 7);
        for v in s.as_array().unwrap() {
            let v = v.as_f64().unwrap();
            assert!(v.is_finite() && v > 0.0, "std {v}");
        }
    }
    assert_eq!(answer["weights"].as_array().unwrap().len(), 56);
    // The trajectory stays inside the joint limits (when one is returned).
    let robot = Robot::panda().unwrap();
    let points = answer["trajectory"]["points"].as_array().unwrap();
    if status != "infeasible" {
        assert!(!points.is_empty());
    }
    for p in points {
        let q = p["positions"].as_array().unwrap();
        assert_eq!(q.len(), 7);
        for (v, l) in q.iter().zip(robot.limits()) {
            let v = v.as_f64().unwrap();
            assert!(
                v >= l.lower - 1e-6 && v <= l.upper + 1e-6,
                "{v} outside {l:?}"
            );
        }
    }
    if status == "optimal" {
        let clearance = answer["report"]["min_clearance_m"].as_f64().unwrap();
        assert!(clearance >= 0.02 - 1e-3, "clearance {clearance}");
        assert!(
            answer["report"]["max_joint_limit_violation_rad"]
                .as_f64()
                .unwrap()
                <= 1e-6
        );
    }
    assert_eq!(
        answer["model"].as_str().unwrap(),
        read_json(&model.join("config.json"))["name"]
            .as_str()
            .unwrap()
    );
}
