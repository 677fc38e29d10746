//! `dpmp bench --model DIR --data DIR [--split test]`: the plan pipeline end
//! to end on a generated dataset (`dpmp data generate` output).
//!
//! Each target of the split becomes an in-memory problem built like
//! `dpmp plan` builds its request: the network's prior from the target's
//! image and box (and the measured depth, for a depth-conditioned model;
//! [`crate::net::Model::predict_with_depth`]; generated images already
//! carry the white box, imported ones say whether they do), the target's
//! scene as obstacles, the record's duration and basis, 2 cm clearance,
//! no start or goal constraint. The demonstrations' mean final TCP
//! position is kept as [`Meta::reference_final_tcp`], so the runner
//! reports every method's final-point TCP error against it
//! ([`super::RunRecord::final_tcp_error_m`]; for `prior-mean` that is the
//! network prior mean's error).

use super::problem_file::{Expect, Meta, ProblemFile};
use crate::net::Model;
use crate::synth::dataset::{load_image, load_manifest, load_record, TargetEntry};
use crate::{Error, Result};
use serde_json::json;
use std::path::Path;

/// Category of every model-mode problem in the reports.
pub const MODEL_CATEGORY: &str = "model";
/// Generator name in the problems' `meta.generator`.
pub const MODEL_GENERATOR: &str = "dpmp bench --model (network prior)";
/// Required clearance (m), the `dpmp plan` default.
pub const MODEL_CLEARANCE_M: f64 = 0.02;

/// One problem per target of `split` (first `limit` targets when given);
/// a target that cannot be loaded or predicted is an error in its slot,
/// counted by the runner.
pub fn model_problems(
    model: &Model,
    data: &Path,
    split: &str,
    limit: Option<usize>,
) -> Result<Vec<(String, Result<ProblemFile>)>> {
    let manifest = load_manifest(data)?;
    let mut entries = manifest.split(split).map_err(|e| e.within("--split"))?;
    if let Some(n) = limit {
        entries.truncate(n);
    }
    if entries.is_empty() {
        return Err(Error::invalid(
            "--split",
            format!("split {split:?} of {} has no targets", data.display()),
        ));
    }
    Ok(entries
        .into_iter()
        .map(|e| (e.id.clone(), target_problem(model, data, e, split)))
        .collect())
}

/// The plan-pipeline problem of one dataset target.
pub fn target_problem(
    model: &Model,
    data: &Path,
    entry: &TargetEntry,
    split: &str,
) -> Result<ProblemFile> {
    let record = load_record(data, entry)?;
    let image = image::DynamicImage::ImageRgb8(load_image(data, entry)?);
    let prediction = model.predict_with_depth(
        &image,
        record.bbox,
        entry.mask_applied,
        record.target_depth_m,
    )?;
    let request = json!({
        "prior": crate::optim::PriorSpec::from(&prediction.distribution),
        "promp": record.promp,
        "duration_s": record.duration_s,
        "obstacles": record.scene.obstacles(),
        "clearance_m": MODEL_CLEARANCE_M,
    });
    Ok(ProblemFile {
        name: entry.id.clone(),
        request,
        expect: Expect {
            feasible: Some(true),
            min_clearance_m: Some(MODEL_CLEARANCE_M),
            witness: None,
        },
        meta: Meta {
            generator: MODEL_GENERATOR.to_string(),
            seed: 0,
            category: MODEL_CATEGORY.to_string(),
            description: format!(
                "target {} of {} (split {split}), model {}; feasibility assumed from the demonstrations",
                entry.id,
                data.display(),
                model.name()
            ),
            reference_final_tcp: Some(record.final_tcp.position),
        },
    })
}
