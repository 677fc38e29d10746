//! `dpmp bench --model --data` (model mode) end to end: a tiny dataset
//! from the real synthetic generator, a tiny network trained on it in the
//! test, then the plan pipeline through `run_model_suite`: every target
//! gives a record per method, and the final-point TCP error of
//! `prior-mean` equals the network prior mean's error computed here
//! independently.

use crate::common::json::read_json;
use dpmp::bench::{method_from_name, run_model_suite, ModelSource, RunSettings};
use dpmp::net::{Arch, Model};
use dpmp::robot::Robot;
use dpmp::synth::dataset::{load_image, load_manifest, load_record};
use dpmp::synth::generate::{generate, GenerateOptions, Generator};
use dpmp::synth::settings::SynthSettings;
use nalgebra::Vector3;

#[test]
fn model_mode_runs_the_plan_pipeline_and_reports_final_tcp_error() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let mut settings = SynthSettings::new(2, 2);
    settings.demos.demos = 4;
    // One plant for val: training refuses an empty val split.
    (settings.split.val_fraction, settings.split.test_fraction) = (0.5, 0.0);
    let robot = Robot::panda().unwrap();
    let generator = Generator::new(settings, robot.clone()).unwrap();
    generate(
        &generator,
        &GenerateOptions {
            out: data.clone(),
            seed: 3,
            workers: Some(2),
            progress: false,
            overwrite: false,
        },
    )
    .unwrap();
    let model_dir = dir.path().join("model");
    let mut train = crate::common::net::tiny_settings(&data, &model_dir, Arch::Direct);
    (train.epochs_tp1, train.epochs_tp2, train.epochs_tp3) = (1, 1, 1);
    dpmp::train::train(&train).unwrap();

    let out = dir.path().join("report");
    let methods = vec![
        method_from_name("prior-mean").unwrap(),
        method_from_name("dpmp-qp").unwrap(),
    ];
    let run = RunSettings {
        workers: Some(2),
        progress: false,
    };
    let report = run_model_suite(
        &dpmp::robot::Robot::panda().unwrap(),
        ModelSource {
            model: &model_dir,
            data: &data,
            split: "all",
        },
        &out,
        methods,
        None,
        &run,
        "test",
    )
    .unwrap();

    let manifest = load_manifest(&data).unwrap();
    let entries = manifest.split("all").unwrap();
    assert_eq!(entries.len(), 4);
    assert_eq!(report.records.len(), 2 * entries.len());
    let model = Model::load(&model_dir).unwrap();
    for entry in entries {
        let record = load_record(&data, entry).unwrap();
        let image = image::DynamicImage::ImageRgb8(load_image(&data, entry).unwrap());
        let prior = model
            .predict_with_depth(&image, record.bbox, true, record.target_depth_m)
            .unwrap()
            .distribution;
        let basis = dpmp::promp::Basis::new(&record.promp).unwrap();
        let q = prior.trajectory_mean(&basis);
        let last: Vec<f64> = q.row(q.nrows() - 1).iter().copied().collect();
        let tcp = robot.tcp_pose(&last).translation.vector;
        let expected = (tcp - Vector3::from(record.final_tcp.position)).norm();
        for r in report.records.iter().filter(|r| r.problem == entry.id) {
            assert!(
                r.error.is_none(),
                "{} / {}: {:?}",
                r.problem,
                r.method,
                r.error
            );
            assert_eq!(r.category, "model");
            let e = r.final_tcp_error_m.unwrap();
            assert!(e.is_finite() && e >= 0.0);
            if r.method == "prior-mean" {
                assert!((e - expected).abs() < 1e-9, "{e} vs {expected}");
            }
            if r.method == "dpmp-qp" && r.found {
                assert!(r.verified_feasible);
                assert!(r.min_clearance_m.unwrap() >= 0.02 - 1e-6);
            }
        }
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("Final TCP error"), "{md}");
    let json = read_json(&out.join("report.json"));
    assert!(json["summary"][0]["final_tcp_error_m"]["p50"]
        .as_f64()
        .is_some());
}

#[test]
fn model_mode_flags_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let no_model = dir.path().join("no-model");
    let e = run_model_suite(
        &dpmp::robot::Robot::panda().unwrap(),
        ModelSource {
            model: &no_model,
            data: dir.path(),
            split: "test",
        },
        &dir.path().join("out"),
        vec![method_from_name("prior-mean").unwrap()],
        None,
        &RunSettings::default(),
        "test",
    )
    .unwrap_err();
    assert!(e.to_string().contains("no-model"), "{e}");
}
