//! An optimiser answer over its prior, per joint: the prior mean ± 2σ band,
//! the optimised trajectory and the joint limits (`dpmp optimize --plot`,
//! `dpmp plan --plot`).

use super::{joint_panels, JointSeries};
use crate::optim::OptimizeResponse;
use crate::promp::Basis;
use crate::robot::Robot;
use crate::Result;
use nalgebra::{DMatrix, DVector};
use plotters::style::RGBColor;
use std::path::Path;

/// The prior an answer is drawn over: mean and standard deviation of the
/// joint positions at the basis phases (`T x dof`).
pub struct PriorBand {
    /// Mean joint positions.
    pub mean: DMatrix<f64>,
    /// Their standard deviations.
    pub std: DMatrix<f64>,
}

/// Draw `response` over `prior` (at `basis`'s phases, the motion lasting
/// `duration` s) into `path` (`.png` or `.svg`), titled `title`.
pub fn prior_and_answer(
    path: &Path,
    title: &str,
    (basis, duration): (&Basis, f64),
    prior: PriorBand,
    response: &OptimizeResponse,
    robot: &Robot,
) -> Result<()> {
    let times: Vec<f64> = basis.phases().iter().map(|z| z * duration).collect();
    let nb = basis.n_basis();
    let dof = response.weights.len() / nb.max(1);
    let w = DVector::from_column_slice(&response.weights);
    let wm = DMatrix::from_fn(nb, dof, |i, j| w[j * nb + i]);
    let series = [
        JointSeries::band(
            "prior mean ± 2σ".into(),
            RGBColor(70, 110, 200),
            prior.mean,
            prior.std,
            2.0,
        ),
        JointSeries::line(
            format!("optimised ({})", response.status.as_str()),
            RGBColor(220, 60, 40),
            basis.matrix() * wm,
            2,
        ),
    ];
    let limits: Vec<(f64, f64)> = robot.limits().iter().map(|l| (l.lower, l.upper)).collect();
    joint_panels(
        path,
        title,
        &times,
        &series,
        robot.joint_names(),
        Some(&limits),
    )
}
