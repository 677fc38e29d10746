//! Where a fitted prior goes: the paper's annotation folder
//! (`J1..Jn/{index}.json`, each joint's mean weights and covariance code),
//! `prior.json` (the optimise request's `prior`, `promp` and `duration_s`:
//! itself a valid request with no obstacles) and `fit.json` (the report).
//! Every file is written whole or not at all.

use super::fit::{DemoReport, PriorFit};
use crate::optim::request::PriorSpec;
use crate::promp::{annotation, PrompConfig};
use crate::synth::dataset::write_json_atomic;
use crate::Result;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The optimise-request fragment written to `prior.json`.
#[derive(Debug, Serialize)]
pub struct PriorRequest<'a> {
    /// The full Gaussian (joint-major mean, covariance rows).
    pub prior: PriorSpec,
    /// The basis the weights belong to.
    pub promp: &'a PrompConfig,
    /// The demonstrations' median duration (s).
    pub duration_s: f64,
}

/// The report written to `fit.json` (and printed by `dpmp prior fit`).
#[derive(Debug, Serialize)]
pub struct FitReport<'a> {
    /// Robot name.
    pub robot: &'a str,
    /// Joint names, in weight order.
    pub joint_names: &'a [String],
    /// The basis.
    pub promp: &'a PrompConfig,
    /// Number of demonstrations.
    pub demonstrations: usize,
    /// Median duration (s).
    pub duration_s: f64,
    /// Largest RMS fit residual of any demonstration (rad).
    pub max_rms_residual_rad: f64,
    /// Each demonstration's figures.
    pub demos: &'a [DemoReport],
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Write `fit` under `out` (annotation index `index`); the report lists
/// the files.
pub fn write_prior<'a>(
    out: &Path,
    index: usize,
    fit: &'a PriorFit,
    config: &'a PrompConfig,
    robot: &'a crate::robot::Robot,
) -> Result<FitReport<'a>> {
    let dist = &fit.distribution;
    let joints = annotation::joints_from_distribution(dist)?;
    annotation::write_dir(out, index, &joints)?;
    let request = PriorRequest {
        prior: PriorSpec::from(dist),
        promp: config,
        duration_s: fit.median_duration_s(),
    };
    let (prior_path, fit_path) = (out.join("prior.json"), out.join("fit.json"));
    write_json_atomic(&prior_path, &request)?;
    let files: Vec<PathBuf> = (1..=dist.n_joints)
        .map(|j| out.join(format!("J{j}")).join(format!("{index}.json")))
        .chain([prior_path, fit_path.clone()])
        .collect();
    let report = FitReport {
        robot: robot.name(),
        joint_names: robot.joint_names(),
        promp: config,
        demonstrations: fit.demos.len(),
        duration_s: fit.median_duration_s(),
        max_rms_residual_rad: fit.max_rms_residual(),
        demos: &fit.demos,
        files,
    };
    write_json_atomic(&fit_path, &report)?;
    Ok(report)
}
