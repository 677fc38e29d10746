//! Depth-aware planning on a dataset split: for every target with an
//! aligned depth image, the full `/v1/plan` pipeline ([`crate::plan`]) runs
//! with the target's own scene as obstacles, and two things are compared
//! with the ground truth:
//!
//! - the back-projected berry centre against the true one
//!   (`target_position_error_m`, the median; and the 95th percentile);
//! - the plan's final TCP against the demonstrations' mean final TCP
//!   (`plan_mean_final_position_error_m`, `plan_p95_…`), the same reference
//!   as the network's `mean_final_position_error_m`;
//! - the final TCP of the prior the optimiser starts from (the network's
//!   prior conditioned on the goal, [`crate::plan::prior_towards_goal`])
//!   against the same reference (`plan_prior_mean_final_position_error_m`).
//!
//! Targets are planned in parallel; each is independent, so the figures do
//! not depend on the thread count.

use crate::net::Model;
use crate::optim::{Status, Task};
use crate::plan::{predict_and_optimize, PlanFields, PlanParts, PlanRequest};
use crate::robot::Robot;
use crate::synth::dataset::{self, Manifest, TargetEntry, TargetRecord};
use crate::{Error, Result};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Clearance (m) every evaluation plan keeps from its scene.
pub const EVAL_CLEARANCE_M: f64 = 0.02;

/// Planning figures of one split (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlanEval {
    /// Targets planned.
    pub plan_targets: usize,
    /// Mean distance (m) of the plan's final TCP to the demonstrations'
    /// mean final TCP.
    pub plan_mean_final_position_error_m: f64,
    /// Its 95th percentile (m).
    pub plan_p95_final_position_error_m: f64,
    /// Mean distance (m) of the goal-conditioned prior's final TCP to the
    /// demonstrations' mean final TCP.
    pub plan_prior_mean_final_position_error_m: f64,
    /// Fraction of plans verified `optimal`.
    pub plan_optimal_fraction: f64,
    /// Median distance (m) of the back-projected berry centre to the true
    /// one (datasets that know it: generated ones).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target_position_error_m: Option<f64>,
    /// Its 95th percentile (m).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target_position_p95_error_m: Option<f64>,
}

/// One target's outcome.
struct Outcome {
    final_error: f64,
    prior_error: f64,
    target_error: Option<f64>,
    optimal: bool,
}

/// Plan every target of `split` that has depth; `None` when the dataset
/// has no depth.
pub fn evaluate_plans(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    dir: &Path,
    split: &str,
) -> Result<Option<PlanEval>> {
    let manifest = dataset::load_manifest(dir)?;
    let scale = manifest.depth_scale_m();
    // The dataset's camera took its images (an imported dataset's may not
    // be the model's).
    let camera = manifest.camera_model();
    let entries: Vec<&TargetEntry> = manifest
        .split(split)?
        .into_iter()
        .filter(|e| e.depth.is_some())
        .collect();
    if entries.is_empty() {
        return Ok(None);
    }
    let outcomes = entries
        .par_iter()
        .map(|entry| plan_one(model, robot, dir, entry, scale, camera))
        .collect::<Result<Vec<_>>>()?;
    let mut finals: Vec<f64> = outcomes.iter().map(|o| o.final_error).collect();
    let mut targets: Vec<f64> = outcomes.iter().filter_map(|o| o.target_error).collect();
    let has_truth = !targets.is_empty();
    let n = outcomes.len() as f64;
    Ok(Some(PlanEval {
        plan_targets: outcomes.len(),
        plan_mean_final_position_error_m: finals.iter().sum::<f64>() / n,
        plan_p95_final_position_error_m: percentile(&mut finals, 0.95),
        plan_prior_mean_final_position_error_m: outcomes.iter().map(|o| o.prior_error).sum::<f64>()
            / n,
        plan_optimal_fraction: outcomes.iter().filter(|o| o.optimal).count() as f64 / n,
        target_position_error_m: has_truth.then(|| percentile(&mut targets, 0.5)),
        target_position_p95_error_m: has_truth.then(|| percentile(&mut targets, 0.95)),
    }))
}

/// The plan input of one dataset target, as the evaluation and `dpmp plan
/// --record` build it: the target's image, box and mask flag, its aligned
/// depth when the dataset has one (in the dataset's `depth_scale_m`), the
/// dataset's `camera`, the record's start configuration, duration and
/// scene, and `clearance_m`. Returns the record beside it.
pub fn record_plan_input(
    dir: &Path,
    entry: &TargetEntry,
    depth_scale_m: f64,
    camera: crate::perception::CameraModel,
    clearance_m: f64,
) -> Result<(PlanParts, TargetRecord)> {
    let record = dataset::load_record(dir, entry)?;
    let image = image::DynamicImage::ImageRgb8(dataset::load_image(dir, entry)?);
    let depth = dataset::load_depth(dir, entry, depth_scale_m)?;
    let task = Task {
        duration_s: record.duration_s,
        start: Some(record.start.clone()),
        obstacles: record.scene.obstacles(),
        clearance_m,
        ..Task::default()
    };
    let parts = PlanParts {
        mask_applied: entry.mask_applied,
        depth,
        camera: Some(camera),
        ..PlanParts::new(image, record.bbox, task)
    };
    Ok((parts, record))
}

/// The names errors give a record's inputs: the flags', the depth by its
/// target.
pub fn record_fields(entry: &TargetEntry) -> PlanFields {
    PlanFields {
        depth: format!("depth of {}", entry.id),
        ..PlanFields::flags()
    }
}

/// The dataset a target record file belongs to: the nearest folder above
/// it with a `manifest.json`, the manifest, and the entry whose `record`
/// is that file.
pub fn find_record(record_file: &Path) -> Result<(PathBuf, Manifest, TargetEntry)> {
    let not_found = |why: &str| Error::file(record_file, why.to_string());
    let file = record_file
        .canonicalize()
        .map_err(|e| Error::file(record_file, e.to_string()))?;
    let dir = file
        .ancestors()
        .skip(1)
        .take(MANIFEST_SEARCH_DEPTH)
        .find(|d| d.join("manifest.json").is_file())
        .ok_or_else(|| {
            not_found("no manifest.json in the folders above it: give a target record inside a dataset (DATA/targets/<id>.json)")
        })?
        .to_path_buf();
    let manifest = dataset::load_manifest(&dir)?;
    let entry = manifest
        .targets
        .iter()
        // Only entries with the same file name are resolved on disk.
        .filter(|e| Path::new(&e.record).file_name() == file.file_name())
        .find(|e| dir.join(&e.record).canonicalize().is_ok_and(|p| p == file))
        .cloned()
        .ok_or_else(|| {
            not_found(&format!(
                "not a target record of the dataset at {}",
                dir.display()
            ))
        })?;
    Ok((dir, manifest, entry))
}

/// Folders above a record file searched for its dataset's manifest.
const MANIFEST_SEARCH_DEPTH: usize = 3;

/// The plan of one target, compared with its record.
fn plan_one(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    dir: &Path,
    entry: &TargetEntry,
    scale: f64,
    camera: crate::perception::CameraModel,
) -> Result<Outcome> {
    let (parts, record) = record_plan_input(dir, entry, scale, camera, EVAL_CLEARANCE_M)?;
    if parts.depth.is_none() {
        return Err(Error::invalid(
            "depth",
            format!("target {} has no depth", entry.id),
        ));
    }
    let request = PlanRequest::new(parts, &record_fields(entry))?;
    let answer = predict_and_optimize(model, robot, request, &Default::default())?;
    let last = answer
        .result
        .trajectory
        .points
        .last()
        .ok_or_else(|| Error::Numerical(format!("{}: empty trajectory", entry.id)))?;
    let reference = Vector3::from(record.final_tcp.position);
    let final_error = (robot.tcp_pose(&last.positions).translation.vector - reference).norm();
    let prior_last = answer
        .prior
        .mean
        .last()
        .ok_or_else(|| Error::Numerical(format!("{}: empty prior", entry.id)))?;
    let prior_error = (robot.tcp_pose(prior_last).translation.vector - reference).norm();
    let located = answer
        .target
        .map(|t| Vector3::from(t.position))
        .ok_or_else(|| Error::Numerical(format!("{}: no target located", entry.id)))?;
    Ok(Outcome {
        final_error,
        prior_error,
        target_error: record
            .target_position
            .map(|truth| (located - Vector3::from(truth)).norm()),
        optimal: answer.result.status == Status::Optimal,
    })
}

/// The `p` quantile (nearest rank) of `values`.
fn percentile(values: &mut [f64], p: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    let i = ((values.len() as f64 - 1.0) * p).round() as usize;
    values[i.min(values.len() - 1)]
}
