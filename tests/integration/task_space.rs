//! Task space (the paper's second space): generated records carry each
//! demonstration's TCP trajectory as ProMP weights, checked against the
//! forward kinematics of the demonstrations; records of older formats
//! derive the same weights; a depth-conditioned task-space model trains,
//! evaluates (Table III, task-space half) and plans through IK-tracked draws; the flags that only
//! mean something in joint space are refused.

use crate::common::cli::{arg, dpmp, dpmp_ok};
use crate::common::json::read_json;
use dpmp::net::{Arch, Space};
use dpmp::promp::fit::trajectory_from_weights;
use dpmp::promp::Basis;
use dpmp::robot::Robot;
use dpmp::synth::dataset::{load_manifest, load_record};
use dpmp::synth::generate::{generate, GenerateOptions, Generator};
use dpmp::synth::settings::SynthSettings;
use dpmp::task_space::{pose_of_row, TASK_DIMS};
use serde_json::Value;
use std::path::Path;

/// Five plants of one berry each, three demonstrations per berry: splits
/// of 3 / 1 / 1 plants.
fn small_dataset(out: &Path) {
    let mut settings = SynthSettings::new(5, 1);
    settings.demos.demos = 3;
    let g = Generator::new(settings, Robot::panda().unwrap()).unwrap();
    let options = GenerateOptions {
        out: out.to_path_buf(),
        seed: 5,
        workers: Some(2),
        progress: false,
        overwrite: false,
    };
    generate(&g, &options).unwrap();
}

#[test]
fn generated_task_weights_follow_the_demonstrations_and_older_records_derive_them() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    small_dataset(&data);
    let robot = Robot::panda().unwrap();
    let manifest = load_manifest(&data).unwrap();
    assert_eq!(manifest.format, "dpmp-dataset/4");
    // The largest representation error of the task-space fit (position m,
    // orientation rad), over every sample and at the final one.
    let mut worst = (0.0f64, 0.0f64);
    let mut worst_final = (0.0f64, 0.0f64);
    for entry in &manifest.targets {
        let record = load_record(&data, entry).unwrap();
        let basis = Basis::new(&record.promp).unwrap();
        let last = basis.n_samples() - 1;
        for demo in &record.demos {
            // The task trajectory's final pose is the FK of the joint
            // trajectory's final configuration (both fitted in one basis).
            let task = demo.task_weights.as_ref().expect("format 4 stores them");
            let poses = trajectory_from_weights(&basis, task, TASK_DIMS);
            let joints = trajectory_from_weights(&basis, &demo.weights, robot.dof());
            for t in 0..=last {
                let q: Vec<f64> = joints.row(t).iter().copied().collect();
                let truth = robot.tcp_pose(&q);
                let row: Vec<f64> = poses.row(t).iter().copied().collect();
                let pose = pose_of_row(&row).unwrap();
                let dp = (pose.translation.vector - truth.translation.vector).norm();
                let angle = pose.rotation.angle_to(&truth.rotation);
                worst = (worst.0.max(dp), worst.1.max(angle));
                if t == last {
                    worst_final = (worst_final.0.max(dp), worst_final.1.max(angle));
                }
            }
        }
        // The distribution's mean is the demonstrations' mean.
        let stored = record.task_space_distribution(&robot).unwrap();
        let n = record.demos.len() as f64;
        for k in 0..stored.dim() {
            let mean: f64 = record
                .demos
                .iter()
                .map(|d| d.task_weights.as_ref().unwrap()[k])
                .sum::<f64>()
                / n;
            assert!((stored.mean[k] - mean).abs() < 1e-12);
        }
        // A record of an older format (no task fields) derives the same.
        let mut older = record.clone();
        older.task_distribution = None;
        for d in &mut older.demos {
            d.task_weights = None;
        }
        let derived = older.task_space_distribution(&robot).unwrap();
        assert!((&derived.mean - &stored.mean).amax() < 1e-12);
        assert!((&derived.cov - &stored.cov).amax() < 1e-12);
    }
    println!("task-space fit error: all samples {worst:?}, final {worst_final:?}");
    assert!(worst.0 < 3e-3 && worst.1 < 2e-2, "{worst:?}");
    assert!(
        worst_final.0 < 2e-3 && worst_final.1 < 1e-2,
        "{worst_final:?}"
    );
}

#[test]
fn a_task_space_model_trains_evaluates_and_plans() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    small_dataset(&data);
    let out = dir.path().join("task-model");
    let mut s = crate::common::net::tiny_settings(&data, &out, Arch::Cvae);
    s.space = Space::Task;
    s.depth_condition = true;
    s.epochs_tp1 = 1;
    s.epochs_tp2 = 2;
    dpmp::train::train(&s).unwrap();
    let config = read_json(&out.join("config.json"));
    assert_eq!(config["space"], "task");
    assert_eq!(config["depth_condition"], true);

    // Table III's task-space half, with finite figures.
    let o = dpmp_ok(&[
        "eval",
        "--model",
        arg(&out),
        "--data",
        arg(&data),
        "--split",
        "test",
        "--format",
        "json",
        "--out",
        arg(&dir.path().join("eval")),
    ]);
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["space"], "task");
    for k in ["mean", "plus_3sigma", "minus_3sigma"] {
        let e = &report["table3"][k];
        assert!(e["position_m"].as_f64().unwrap().is_finite(), "{report}");
        assert!(e["orientation"].as_f64().unwrap().is_finite(), "{report}");
    }
    let md = std::fs::read_to_string(dir.path().join("eval/eval.md")).unwrap();
    assert!(
        md.contains("final point, task space") && md.contains("| qw |"),
        "{md}"
    );

    // A plan from the task-space model: the answer reports the tracking
    // and starts at the record's start configuration.
    let manifest = read_json(&data.join("manifest.json"));
    let record_file = data.join(manifest["targets"][0]["record"].as_str().unwrap());
    let o = dpmp_ok(&["plan", "--record", arg(&record_file), "--model", arg(&out)]);
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    let tracking = &answer["task_space"];
    assert_eq!(tracking["draws"], 64, "{answer}");
    for k in ["mean_position_error_m", "max_final_position_error_m"] {
        assert!(tracking[k].as_f64().unwrap().is_finite(), "{tracking}");
    }
    let status = answer["status"].as_str().unwrap();
    assert!(
        ["optimal", "infeasible", "max_iterations"].contains(&status),
        "{status}"
    );
    let record = read_json(&record_file);
    let first = &answer["trajectory"]["points"][0]["positions"];
    for (a, b) in first
        .as_array()
        .unwrap()
        .iter()
        .zip(record["start"].as_array().unwrap())
    {
        assert!((a.as_f64().unwrap() - b.as_f64().unwrap()).abs() < 1e-6);
    }

    // The model's config chooses the linearised propagation: one tracked
    // trajectory, the same tracked mean.
    let mut linear = config.clone();
    linear["task_prior"] = serde_json::json!({"propagation": "linearised"});
    std::fs::write(out.join("config.json"), linear.to_string()).unwrap();
    let o = dpmp_ok(&["plan", "--record", arg(&record_file), "--model", arg(&out)]);
    let again: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(again["task_space"]["draws"], 1, "{again}");
    assert_eq!(
        again["task_space"]["mean_position_error_m"],
        tracking["mean_position_error_m"]
    );
}

#[test]
fn joint_space_terms_are_refused_for_a_task_space_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m");
    let train = |extra: &[&str]| {
        let mut args = vec!["train", "--data", arg(dir.path()), "--arch", "cvae"];
        args.extend_from_slice(extra);
        args.extend(["--out", arg(&out)]);
        dpmp(&args)
    };
    for (flag, field) in [
        ("--tcp-weight", "tcp_weight"),
        ("--start-weight", "start_weight"),
    ] {
        let o = train(&["--space", "task", flag, "1"]);
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(field) && err.contains("task-space"), "{err}");
    }
    let o = train(&["--space", "cartesian"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("space"));
    assert!(!out.exists());
}
