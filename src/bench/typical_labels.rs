//! Feasibility labels of the typical problems
//! ([`typical_request`], the optimiser benchmark's set): a success rate is
//! only meaningful on problems known to be feasible, and the generator
//! builds no witness of its own. [`label_typical`] solves each problem with
//! a generous restart budget and keeps every `optimal` answer as its
//! *witness* (weights whose dense verification and continuous certificate
//! meet every constraint); a problem without one stays unlabelled (its
//! feasibility unknown). The labels live in `problems/typical/labels.json`
//! and the test suite re-verifies every witness against the regenerated
//! request ([`verify_witness`]), so a change of the generator or of the
//! geometry cannot leave them stale.

use super::problem_file::write_atomic;
use crate::error::ensure_finite;
use crate::fixtures::{typical_request, ExampleSettings};
use crate::optim::{optimize, Status};
use crate::robot::Robot;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of the labels file.
pub const SCHEMA: &str = "dpmp-typical-labels/1";

/// The labels of the first `count` typical problems.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TypicalLabels {
    /// [`SCHEMA`].
    pub schema: String,
    /// Restarts each labelling solve was allowed.
    pub restarts: usize,
    /// One per seed `0..count`, in order.
    pub labels: Vec<TypicalLabel>,
}

/// One problem's label.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TypicalLabel {
    /// Seed of [`typical_request`] (default settings).
    pub seed: u64,
    /// `true` with a witness; `null`: unknown (no solve found one).
    pub feasible: Option<bool>,
    /// Joint-major weights that satisfy every constraint.
    pub witness: Option<Vec<f64>>,
    /// Mahalanobis distance of the witness to the prior.
    pub mahalanobis: Option<f64>,
    /// Which run found the witness (`prior mean` or `restart`), or why
    /// none was found.
    pub note: String,
}

/// Solve typical problems `0..count` with `restarts` restarts each and
/// label them; `progress` prints one line per problem to stderr.
pub fn label_typical(
    robot: &Robot,
    count: usize,
    restarts: usize,
    progress: bool,
) -> Result<TypicalLabels> {
    let settings = ExampleSettings::default();
    let mut labels = Vec::with_capacity(count);
    for seed in 0..count as u64 {
        let mut request = typical_request(robot, seed, &settings)?;
        request.task.options.restarts = restarts;
        let response = optimize(&request, robot)?;
        let label = if response.status == Status::Optimal {
            let restarted = response
                .report
                .warnings
                .iter()
                .any(|w| w.contains("restart"));
            TypicalLabel {
                seed,
                feasible: Some(true),
                witness: Some(response.weights),
                mahalanobis: Some(response.mahalanobis),
                note: if restarted { "restart" } else { "prior mean" }.into(),
            }
        } else {
            TypicalLabel {
                seed,
                feasible: None,
                witness: None,
                mahalanobis: None,
                note: response.reason.unwrap_or_default(),
            }
        };
        if progress {
            eprintln!("[{}/{count}] seed {seed}: {}", seed + 1, label.note);
        }
        labels.push(label);
    }
    Ok(TypicalLabels {
        schema: SCHEMA.into(),
        restarts,
        labels,
    })
}

/// Whether `label`'s witness satisfies every constraint of the regenerated
/// typical request (dense verification and continuous certificate); `false`
/// without a witness.
pub fn verify_witness(robot: &Robot, label: &TypicalLabel) -> Result<bool> {
    let Some(witness) = &label.witness else {
        return Ok(false);
    };
    let request = typical_request(robot, label.seed, &ExampleSettings::default())?;
    let problem = request.validate(robot)?;
    Ok(problem.is_feasible(&problem.evaluate(witness)))
}

impl TypicalLabels {
    /// Load and check a labels file (schema, seeds in order, finite
    /// witnesses); errors name the file.
    pub fn load(path: &Path) -> Result<TypicalLabels> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        let labels: TypicalLabels = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("malformed labels: {e}")))?;
        labels
            .check()
            .map_err(|e| Error::file(path, e.to_string()))?;
        Ok(labels)
    }

    fn check(&self) -> Result<()> {
        if self.schema != SCHEMA {
            return Err(Error::invalid(
                "schema",
                format!("expected {SCHEMA}, got {}", self.schema),
            ));
        }
        for (i, label) in self.labels.iter().enumerate() {
            if label.seed != i as u64 {
                return Err(Error::invalid(
                    format!("labels[{i}].seed"),
                    format!("expected {i}, got {}", label.seed),
                ));
            }
            if label.feasible == Some(true) && label.witness.is_none() {
                return Err(Error::invalid(
                    format!("labels[{i}].witness"),
                    "a feasible label needs a witness",
                ));
            }
            if let Some(w) = &label.witness {
                ensure_finite(&format!("labels[{i}].witness"), w)?;
            }
        }
        Ok(())
    }

    /// Write the labels as pretty JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e.to_string()))?;
        }
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::file(path, format!("cannot serialise: {e}")))?;
        write_atomic(path, text.as_bytes())
    }

    /// Problems labelled feasible.
    pub fn feasible(&self) -> usize {
        self.labels
            .iter()
            .filter(|l| l.feasible == Some(true))
            .count()
    }
}
