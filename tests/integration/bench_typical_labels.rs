//! The feasibility labels of the 100 typical problems
//! (`problems/typical/labels.json`, written by `dpmp bench label-typical`):
//! every witness still satisfies every constraint of its regenerated
//! request, and a corrupt labels file is refused with the file named.

use dpmp::bench::typical_labels::{verify_witness, TypicalLabels};
use dpmp::robot::Robot;
use std::path::PathBuf;

fn labels_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("problems/typical/labels.json")
}

#[test]
fn every_typical_problem_is_labelled_feasible_and_its_witness_verifies() {
    let labels = TypicalLabels::load(&labels_path()).unwrap();
    assert_eq!(labels.labels.len(), 100);
    assert_eq!(
        labels.feasible(),
        100,
        "every typical problem has a witness"
    );
    let robot = Robot::panda().unwrap();
    for label in &labels.labels {
        assert!(
            verify_witness(&robot, label).unwrap(),
            "seed {}: the witness no longer verifies",
            label.seed
        );
        assert!(label.mahalanobis.is_some_and(|m| m.is_finite() && m > 0.0));
    }
}

#[test]
fn corrupt_labels_are_refused_with_the_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(labels_path()).unwrap();
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["labels"][3]["seed"] = 7.into();
    let bad = dir.path().join("labels.json");
    std::fs::write(&bad, value.to_string()).unwrap();
    let err = TypicalLabels::load(&bad).unwrap_err().to_string();
    assert!(
        err.contains("labels.json") && err.contains("labels[3].seed"),
        "{err}"
    );
    std::fs::write(&bad, "{\"schema\": 1").unwrap();
    let err = TypicalLabels::load(&bad).unwrap_err().to_string();
    assert!(err.contains("malformed"), "{err}");
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["labels"][0]["witness"][5] = serde_json::Value::Null;
    std::fs::write(&bad, value.to_string()).unwrap();
    assert!(TypicalLabels::load(&bad).is_err());
}
