//! `dpmp plan` end to end with the shipped `models/default`: a one-plant
//! dataset is generated into a temp dir with `dpmp data generate`, and the
//! plan answer for one of its images (box, depth and scene from the record)
//! is checked: a 150 x 7 prior with positive spread, a trajectory inside the
//! Panda's joint limits, a known status and a finite clearance report.

use dpmp::robot::Robot;
use serde_json::Value;
use std::path::{Path, PathBuf};

use crate::common::cli::dpmp;
use crate::common::default_model_dir;
use crate::common::json::{numbers, read_json};
use crate::common::robot::final_tcp_pose;

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
    let model = default_model_dir();
    assert!(
        model.join("model.safetensors").is_file(),
        "models/default is committed with the repository"
    );
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let mut args = plan_args(dir.path(), &data, &record);
    args.extend(["--model".into(), model.display().to_string()]);
    let o = dpmp(&args.iter().map(String::as_str).collect::<Vec<_>>());
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

/// The plan's final TCP lies within 1.5 cm of the record's demonstrations'
/// mean final TCP.
fn assert_ends_near_the_demonstrations(answer: &Value, record: &Value) {
    let robot = Robot::panda().unwrap();
    let tcp = final_tcp_pose(&robot, answer).translation.vector;
    let demos = numbers(&record["final_tcp"]["position"]);
    let error = (tcp - nalgebra::Vector3::from_row_slice(&demos)).norm();
    assert!(
        error < 0.015,
        "final TCP {error} m from the demonstrations' mean"
    );
}

/// `dpmp plan --image … --box … --scene …` arguments for a generated record.
fn plan_args(dir: &Path, data: &Path, record: &Value) -> Vec<String> {
    let b: Vec<String> = record["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap().to_string())
        .collect();
    let scene = dir.join("scene.json");
    std::fs::write(&scene, record["scene"].to_string()).unwrap();
    let path = |key: &str| {
        data.join(record[key].as_str().unwrap())
            .display()
            .to_string()
    };
    vec![
        "plan".into(),
        "--image".into(),
        path("image"),
        "--box".into(),
        b.join(","),
        "--mask-applied".into(),
        "--scene".into(),
        scene.display().to_string(),
        "--depth".into(),
        path("depth"),
    ]
}

#[test]
fn plan_a_dataset_record_directly() {
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let record_file = data
        .join("targets")
        .join(format!("{}.json", record["id"].as_str().unwrap()));
    assert!(record_file.is_file(), "{}", record_file.display());
    let o = dpmp(&["plan", "--record", record_file.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(answer["status"], "optimal", "{}", answer["reason"]);
    // The record's depth, start, duration and scene were used.
    assert_eq!(answer["target"]["source"], "depth");
    let points = answer["trajectory"]["points"].as_array().unwrap();
    let first = numbers(&points[0]["positions"]);
    let start = numbers(&record["start"]);
    for (a, b) in first.iter().zip(&start) {
        assert!(
            (a - b).abs() < 1e-6,
            "start {first:?} vs the record's {start:?}"
        );
    }
    let end = points.last().unwrap()["time_from_start"].as_f64().unwrap();
    let duration = record["duration_s"].as_f64().unwrap();
    assert!((end - duration).abs() < 1e-9, "{end} vs {duration}");
    assert_ends_near_the_demonstrations(&answer, &record);

    // The same target through the flags gives the same goal.
    let args = plan_args(dir.path(), &data, &record);
    let o = dpmp(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let flags: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(flags["target"], answer["target"]);

    // A standoff without depth or a target position is refused, not ignored.
    let mut no_depth = args[..args.len() - 2].to_vec();
    no_depth.extend(["--goal-standoff".into(), "0.2".into()]);
    let o = dpmp(&no_depth.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--goal-standoff"), "{err}");

    // A record outside a dataset, and --record with --image, exit 2.
    let stray = dir.path().join("stray.json");
    std::fs::write(&stray, record.to_string()).unwrap();
    let o = dpmp(&["plan", "--record", stray.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("stray.json") && err.contains("manifest.json"),
        "{err}"
    );
    let o = dpmp(&[
        "plan",
        "--record",
        record_file.to_str().unwrap(),
        "--image",
        "x.png",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--image"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn plan_with_depth_ends_near_the_demonstrations() {
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let args = plan_args(dir.path(), &data, &record);
    let o = dpmp(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(answer["status"], "optimal", "{}", answer["reason"]);
    assert_eq!(answer["target"]["source"], "depth");
    assert_ends_near_the_demonstrations(&answer, &record);

    // A depth image of another size is refused, naming the file.
    let small = dir.path().join("small.png");
    let d = dpmp::perception::DepthImage::new(8, 8, 0.001, vec![400; 64], "d").unwrap();
    std::fs::write(&small, d.encode_png().unwrap()).unwrap();
    let mut bad = args.clone();
    *bad.last_mut().unwrap() = small.display().to_string();
    let o = dpmp(&bad.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("small.png") && err.contains("8x8"), "{err}");
}

#[test]
fn eval_reports_depth_aware_planning_on_a_dataset_with_depth() {
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let out = dir.path().join("eval");
    let report = eval_json(&data, &out, &["--split", "all"]);
    assert_eq!(report["plan_targets"], 1);
    let figure = |k: &str| report[k].as_f64().unwrap_or_else(|| panic!("{k} missing"));
    assert!(figure("target_position_error_m") < 0.008);
    assert!(figure("plan_mean_final_position_error_m") < 0.015);
    assert!(
        figure("plan_p95_final_position_error_m")
            >= figure("plan_mean_final_position_error_m") - 1e-12
    );
    assert_eq!(figure("plan_optimal_fraction"), 1.0);
    assert!(figure("mean_final_position_error_m") > 0.0);
    assert!(record["target_depth_m"].as_f64().unwrap() > 0.2);
}

#[test]
fn eval_on_a_test_split_reports_the_condition_only_baseline() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let o = dpmp(&[
        "data",
        "generate",
        "--out",
        data.to_str().unwrap(),
        "--configs",
        "10",
        "--berries-per-config",
        "1",
        "--demos",
        "2",
        "--seed",
        "5",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = dir.path().join("eval");
    let report = eval_json(&data, &out, &[]);
    assert_eq!(report["split"], "test");
    assert_eq!(report["baseline_inputs"], "box centre + depth");
    let error = report["baseline_mean_final_position_error_m"]
        .as_f64()
        .unwrap();
    assert!(error.is_finite() && error > 0.0, "{error}");
}

#[test]
fn plan_refuses_a_model_for_another_robot_and_finds_the_model_through_the_environment() {
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let args = plan_args(dir.path(), &data, &record);

    // The shipped model was trained for the Panda to panda_tcp.
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/panda/panda.urdf");
    let mut other = args.clone();
    other.extend([
        "--robot".into(),
        urdf.display().to_string(),
        "--tip".into(),
        "panda_hand".into(),
    ]);
    let o = dpmp(&other.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("is for another robot") && err.contains("panda_hand"),
        "{err}"
    );

    // Without --model, DPMP_MODEL_DIR names the model folder.
    let missing = dir.path().join("no-model-here");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dpmp"))
        .args(&args)
        .env("DPMP_MODEL_DIR", &missing)
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no-model-here"), "{err}");
}

#[test]
fn without_depth_the_box_only_model_plans_and_the_default_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let (data, record) = one_plant(dir.path());
    let mut args = plan_args(dir.path(), &data, &record);
    args.truncate(args.len() - 2); // no --depth
    let rgb_only = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/rgb-only");
    let mut box_only = args.clone();
    box_only.extend(["--model".into(), rgb_only.display().to_string()]);
    let o = dpmp(&box_only.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(answer.get("target").is_none());
    assert_eq!(answer["prior"]["mean"].as_array().unwrap().len(), 150);

    let mut default = args.clone();
    default.extend(["--model".into(), default_model_dir().display().to_string()]);
    let o = dpmp(&default.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--depth")
            && err.contains("--target-position")
            && err.contains("models/rgb-only"),
        "{err}"
    );
    // The CLI's own words, not the HTTP field names.
    assert!(!err.contains("depth_base64"), "{err}");
}

/// `dpmp eval` of the shipped model on `data` (plus `extra` flags), its
/// JSON report; plots and CSVs go to `out`.
fn eval_json(data: &Path, out: &Path, extra: &[&str]) -> Value {
    let model = default_model_dir();
    let mut args = vec![
        "eval",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--format",
        "json",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = dpmp(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}
