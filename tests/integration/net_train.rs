//! Training tests on a tiny dataset written to a temp dir: a tiny model
//! overfits 4 samples (loss falls 10x), training is deterministic for a
//! seed, an interrupted run resumes to the same weights, every architecture
//! trains through its phases and evaluates to finite tables.

use crate::common::json::read_json;
use dpmp::net::checkpoint::read_tensors;
use dpmp::net::{Arch, Model};
use dpmp::train::log::EpochRecord;
use dpmp::train::{train, TrainSettings};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::path::Path;

fn records(out: &Path) -> Vec<EpochRecord> {
    std::fs::read_to_string(out.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn tiny_model_overfits_four_samples() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // 2 configurations x 4 berries: config 0 -> val, config 1 -> train (4 samples).
    crate::common::net::write_dataset(&data, 2, 4, 32, 24, 1);
    let out = dir.path().join("model");
    let mut s = crate::common::net::tiny_settings(&data, &out, Arch::Direct);
    s.epochs_tp2 = 150;
    s.patience = 1000;
    s.batch = 4;
    s.lr = 3e-3;
    s.lr_final_ratio = 1.0;
    let outcome = train(&s).unwrap();
    assert_eq!(outcome.summary.epochs["direct"], 150);
    let r = records(&out);
    let first = r.first().unwrap().train_loss;
    let best = r.iter().map(|e| e.train_loss).fold(f64::INFINITY, f64::min);
    assert!(
        first / best >= 10.0,
        "loss fell only from {first} to {best}"
    );
    assert!(out.join("loss_curves.png").exists());
    assert!(out.join("metrics.csv").exists());
}

#[test]
fn the_task_space_and_start_terms_and_latent_dropout_train_and_are_recorded() {
    // The tiny dataset's targets are 7-joint weights, so the Panda's
    // kinematics apply; the term adds (never removes) loss, and both
    // settings end up in the model's config.
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::net::write_dataset(&data, 2, 4, 32, 24, 1);
    let run = |name: &str, tcp_weight: f64, start_weight: f64, latent_dropout: f64| {
        let out = dir.path().join(name);
        let mut s = crate::common::net::tiny_settings(&data, &out, Arch::Cvae);
        s.epochs_tp1 = 1;
        s.epochs_tp2 = 3;
        s.tcp_weight = tcp_weight;
        s.start_weight = start_weight;
        s.latent_dropout = latent_dropout;
        let outcome = train(&s).unwrap();
        (outcome, records(&out))
    };
    let (_, plain) = run("plain", 0.0, 0.0, 0.0);
    let (outcome, with_term) = run("tcp", 0.5, 10.0, 0.25);
    let summary = &outcome.summary;
    assert_eq!(
        (
            summary.tcp_weight,
            summary.start_weight,
            summary.latent_dropout
        ),
        (0.5, 10.0, 0.25)
    );
    let tp2 = |r: &[EpochRecord]| r.iter().find(|e| e.phase == "tp2").unwrap().val_loss;
    assert!(tp2(&with_term).is_finite());
    assert!(
        tp2(&with_term) > tp2(&plain),
        "{} vs {}",
        tp2(&with_term),
        tp2(&plain)
    );
    let config = dpmp::net::Model::load(&dir.path().join("tcp"))
        .unwrap()
        .config()
        .clone();
    // The robot it was trained for is recorded.
    let panda = dpmp::robot::Robot::panda().unwrap();
    assert_eq!(config.robot, Some(panda.identity()));
    let recorded = config.training.unwrap();
    assert_eq!(
        (
            recorded.tcp_weight,
            recorded.start_weight,
            recorded.latent_dropout
        ),
        (0.5, 10.0, 0.25)
    );
}

fn weights(out: &Path) -> Vec<(String, Vec<f32>)> {
    read_tensors(&out.join("model.safetensors"))
        .unwrap()
        .into_iter()
        .map(|(k, (_, v))| (k, v))
        .collect()
}

#[test]
fn training_is_deterministic_and_resumes_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::net::write_dataset(&data, 3, 3, 32, 24, 2);
    let run = |name: &str, f: &dyn Fn(&mut TrainSettings)| {
        let out = dir.path().join(name);
        let mut s = crate::common::net::tiny_settings(&data, &out, Arch::Vae);
        s.latent_tuning = true;
        s.seed = 7;
        f(&mut s);
        train(&s).unwrap();
        out
    };
    let a = run("a", &|_| {});
    let b = run("b", &|_| {});
    assert_eq!(weights(&a), weights(&b));
    let c = run("c", &|s| s.seed = 8);
    assert_ne!(weights(&a), weights(&c));

    // Interrupt after 4 epochs (inside tp2), then resume.
    let r = dir.path().join("r");
    let mut s = crate::common::net::tiny_settings(&data, &r, Arch::Vae);
    s.latent_tuning = true;
    s.seed = 7;
    s.stop_after_epochs = Some(4);
    train(&s).unwrap();
    assert_ne!(weights(&a), weights(&r));
    s.stop_after_epochs = None;
    s.resume = true;
    train(&s).unwrap();
    assert_eq!(weights(&a), weights(&r));
    assert_eq!(records(&a).len(), records(&r).len());
}

#[test]
fn latent_tuning_extends_a_finished_run_to_the_same_weights() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::net::write_dataset(&data, 3, 3, 32, 24, 3);
    let settings = |out: &Path, latent_tuning: bool| {
        let mut s = crate::common::net::tiny_settings(&data, out, Arch::Ae);
        s.latent_tuning = latent_tuning;
        s.seed = 5;
        s
    };
    let full = dir.path().join("full");
    train(&settings(&full, true)).unwrap();
    let ext = dir.path().join("ext");
    train(&settings(&ext, false)).unwrap();
    assert_ne!(weights(&full), weights(&ext));
    let mut s = settings(&ext, true);
    s.resume = true;
    let outcome = train(&s).unwrap();
    assert!(outcome.summary.epochs.contains_key("tp3"));
    assert_eq!(weights(&full), weights(&ext));
    assert_eq!(records(&full).len(), records(&ext).len());
    // The tp3 run cannot be resumed as a run without latent tuning.
    let mut s = settings(&full, false);
    s.resume = true;
    assert_eq!(train(&s).unwrap_err().field(), Some("resume"));
}

/// A toy forward kinematics for evaluation: position = first three joints.
fn toy_fk(q: &[f64]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(q[0], q[1], q[2]),
        UnitQuaternion::from_euler_angles(q[3], q[4], q[5]),
    )
}

#[test]
fn every_architecture_trains_and_evaluates() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::net::write_dataset(&data, 4, 3, 32, 24, 3);
    for (arch, tuning) in [(Arch::Ae, false), (Arch::Cvae, true), (Arch::Direct, false)] {
        let out = dir.path().join(arch.as_str());
        let mut s = crate::common::net::tiny_settings(&data, &out, arch);
        s.latent_tuning = tuning;
        let outcome = train(&s).unwrap();
        let phases: Vec<&String> = outcome.summary.epochs.keys().collect();
        let expected: Vec<&str> = match (arch, tuning) {
            (Arch::Direct, _) => vec!["direct"],
            (_, true) => vec!["tp1", "tp2", "tp3"],
            _ => vec!["tp1", "tp2"],
        };
        assert_eq!(phases, expected);
        let model = Model::load(&out).unwrap();
        assert_eq!(model.config().latent_tuning, tuning);
        let samples = dpmp::train::data::load_split(
            &data,
            "all",
            &model.config().preprocess,
            dpmp::train::data::Targets::Joint,
        )
        .unwrap();
        let (report, embedding) =
            dpmp::train::eval::evaluate(&model, &samples.samples, "all", 1.0, &toy_fk).unwrap();
        assert_eq!(report.targets, 12);
        assert_eq!(report.table1.len(), 7);
        assert!(report
            .table1
            .iter()
            .all(|r| r.eq7.is_finite() && r.mean_mse >= 0.0));
        assert!(report.mean_final_position_error_m.is_finite());
        assert_eq!(report.table2.clusters, 4);
        assert!(report.table2.method.starts_with("t-SNE"));
        assert!(report.table2.davies_bouldin.unwrap() > 0.0);
        let eval_dir = out.join("eval");
        dpmp::train::eval::write_outputs(&eval_dir, &report, &embedding).unwrap();
        for f in ["eval.json", "eval.md", "embedding.png"] {
            assert!(eval_dir.join(f).exists(), "{f}");
        }
        let json = read_json(&eval_dir.join("eval.json"));
        assert!(json["mean_final_position_error_m"].is_number());
    }
}

#[test]
fn bad_dataset_and_settings_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let out = dir.path().join("m");
    let s = crate::common::net::tiny_settings(&data, &out, Arch::Ae);
    let msg = train(&s).unwrap_err().to_string();
    assert!(msg.contains("manifest.json"), "{msg}");
    crate::common::net::write_dataset(&data, 2, 2, 32, 24, 4);
    std::fs::write(data.join("targets/c0001_b00.json"), "{\"box\": [1, 2]}").unwrap();
    let msg = train(&s).unwrap_err().to_string();
    assert!(msg.contains("c0001_b00.json"), "{msg}");
    let mut s2 = s.clone();
    s2.batch = 0;
    assert_eq!(train(&s2).unwrap_err().field(), Some("batch"));
    let mut s3 = s.clone();
    s3.latent_dropout = 1.0;
    assert_eq!(train(&s3).unwrap_err().field(), Some("latent_dropout"));
    let mut s4 = s.clone();
    s4.tcp_weight = f64::NAN;
    assert_eq!(train(&s4).unwrap_err().field(), Some("tcp_weight"));
    let mut s5 = s.clone();
    s5.start_weight = -1.0;
    assert_eq!(train(&s5).unwrap_err().field(), Some("start_weight"));
}
