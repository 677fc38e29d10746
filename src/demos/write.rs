//! Where a fitted prior goes: the paper's annotation folder
//! (`J1..Jn/{index}.json`, each joint's mean weights and covariance code),
//! `prior.json` (the optimise request's `prior`, `promp` and `duration_s`:
//! itself a valid request with no obstacles) and `fit.json` (the report).
//! Every file is written whole or not at all.

use super::fit::{DemoReport, PriorFit};
use crate::fsio::write_atomic;
use crate::optim::request::PriorSpec;
use crate::promp::{annotation, PrompConfig};
use crate::{Error, Result};
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
    let mut files: Vec<PathBuf> = (1..=dist.n_joints)
        .map(|j| out.join(format!("J{j}")).join(format!("{index}.json")))
        .collect();
    let request = PriorRequest {
        prior: PriorSpec::from(dist),
        promp: config,
        duration_s: fit.median_duration_s(),
    };
    files.push(write_json(&out.join("prior.json"), &request)?);
    let report = FitReport {
        robot: robot.name(),
        joint_names: robot.joint_names(),
        promp: config,
        demonstrations: fit.demos.len(),
        duration_s: fit.median_duration_s(),
        max_rms_residual_rad: fit
            .demos
            .iter()
            .map(|d| d.rms_residual_rad)
            .fold(0.0, f64::max),
        demos: &fit.demos,
        files: {
            let mut all = files.clone();
            all.push(out.join("fit.json"));
            all
        },
    };
    write_json(&out.join("fit.json"), &report)?;
    Ok(report)
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<PathBuf> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::Numerical(format!("cannot serialise {}: {e}", path.display())))?;
    write_atomic(path, text.as_bytes())?;
    Ok(path.to_path_buf())
}
