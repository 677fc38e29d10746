//! The image → plan pipeline, as one library call ([`predict_and_optimize`]):
//!
//! ```text
//! image + target box ──► network prior (net)
//! depth + box + camera ──► 3-D berry centre (perception) ──► pre-grasp goal
//! prior + goal + scene ──► optimiser (optim) ──► trajectory + report
//! ```
//!
//! `POST /v1/plan` and `dpmp plan` are shells over it: they parse their
//! inputs into a [`PlanInput`] and print or send the [`PlanResponse`].
//!
//! **The goal from the target.** When the caller sends an aligned depth
//! image (or its own 3-D target position), the berry centre becomes a
//! pre-grasp goal the way the demonstrations were made: `goal_standoff_m`
//! ([`DEFAULT_GOAL_STANDOFF_M`]) short of the berry along the line from the
//! home TCP to it, with tolerance [`GOAL_TOLERANCE_M`]. The goal enters as
//! the optimiser's goal constraint (the final TCP within the tolerance),
//! so the answer meets it whenever it is `optimal`; the network's prior
//! still decides the shape of the motion. The depth is back-projected
//! through the camera the model records ([`crate::net::ModelConfig`]'s
//! `camera`, the synthetic generator's by default) posed at the robot's
//! home configuration, where the images are taken. Without depth and
//! target position the request is planned exactly as before (no goal is
//! added). A model conditioned on depth
//! ([`crate::net::ModelConfig::depth_condition`]) reads the measured depth,
//! or a client position's depth in the camera; it cannot plan without one.

use crate::net::Model;
use crate::optim::{optimize_prior, Goal, OptimizeResponse, SolveControl, Task};
use crate::perception::{locate_target, Camera, CameraModel, DepthImage};
use crate::promp::distribution::matrix_rows;
use crate::promp::{Basis, FinalPointObservation, WeightDistribution};
use crate::robot::Robot;
use crate::{Error, Result};
use image::DynamicImage;
use nalgebra::{DMatrix, Point3, Vector3};
use serde::Serialize;
use std::sync::Arc;

/// Pre-grasp standoff (m) of a goal derived from the target: the synthetic
/// demonstrations end this far short of the berry centre.
pub const DEFAULT_GOAL_STANDOFF_M: f64 = 0.10;

/// Tolerance (m) of a goal derived from the target.
pub const GOAL_TOLERANCE_M: f64 = 0.005;

/// Largest accepted standoff (m).
pub const MAX_GOAL_STANDOFF_M: f64 = 0.5;

/// Where the 3-D target comes from.
#[derive(Clone, Debug, Default)]
pub enum TargetInput {
    /// No 3-D target: plan from the image alone.
    #[default]
    None,
    /// An aligned depth image (same size as the camera's images); the
    /// string names the input in errors (`depth_base64`, `depth`, `--depth`).
    Depth(DepthImage, String),
    /// The client's own perception: the berry centre in the base frame (m).
    Position([f64; 3]),
}

/// A parsed, validated plan request.
pub struct PlanInput {
    /// The decoded image.
    pub image: DynamicImage,
    /// Target berry box `[x1, y1, x2, y2]` in image pixels.
    pub target_box: [f64; 4],
    /// Whether the image already has the target painted (masked).
    pub mask_applied: bool,
    /// The 3-D target, if any.
    pub target: TargetInput,
    /// Standoff of the derived goal (m); `None`: [`DEFAULT_GOAL_STANDOFF_M`].
    pub goal_standoff_m: Option<f64>,
    /// What to plan besides the prior (scene, limits, start, goal,
    /// options); the prior is the network's prediction.
    pub task: Task,
    /// An approach direction for the goal derived from the target.
    pub approach: Option<GoalApproach>,
    /// The camera that took the images, when not the model's (its
    /// intrinsics back-project the depth image).
    pub camera: Option<CameraModel>,
}

/// The approach direction of a goal derived from the 3-D target (the
/// request's `goal` without a `position`): the gripper's z axis at the end
/// within `approach_tolerance_rad` of `approach_axis`.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalApproach {
    /// Unit vector in the base frame.
    pub approach_axis: [f64; 3],
    /// Allowed angle (rad).
    #[serde(default = "default_approach_tolerance")]
    pub approach_tolerance_rad: f64,
}

fn default_approach_tolerance() -> f64 {
    crate::optim::task::DEFAULT_APPROACH_TOLERANCE_RAD
}

/// The predicted prior as trajectories (`T x dof`, rows are time samples).
#[derive(Debug, Serialize)]
pub struct PriorTrajectory {
    /// Mean joint positions.
    pub mean: Vec<Vec<f64>>,
    /// Standard deviation of the joint positions.
    pub std: Vec<Vec<f64>>,
}

/// Where the 3-D target came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetSource {
    /// Back-projected from the depth image.
    Depth,
    /// Sent by the client (`target_position`).
    Client,
}

/// The 3-D target and the goal derived from it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetReport {
    /// Berry centre (m, base frame).
    pub position: [f64; 3],
    /// Depth of the centre along the camera's optical axis (m), when
    /// measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_m: Option<f64>,
    /// Where it came from.
    pub source: TargetSource,
    /// The pre-grasp goal handed to the optimiser (m, base frame).
    pub goal: [f64; 3],
    /// The goal's tolerance (m).
    pub goal_tolerance_m: f64,
}

/// Body of a `/v1/plan` answer.
#[derive(Debug, Serialize)]
pub struct PlanResponse {
    /// The optimiser's answer for the predicted prior.
    #[serde(flatten)]
    pub result: OptimizeResponse,
    /// The prior the optimiser started from: the network's, conditioned on
    /// the goal when a 3-D target was given ([`prior_towards_goal`]).
    pub prior: PriorTrajectory,
    /// Name of the model that predicted it.
    pub model: String,
    /// The 3-D target, when depth or a target position was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<TargetReport>,
}

/// Network prior, goal from the target (if any), then the optimiser.
pub fn predict_and_optimize(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    input: PlanInput,
    ctl: &SolveControl,
) -> Result<PlanResponse> {
    let mut task = input.task;
    let camera = input
        .camera
        .unwrap_or_else(|| model.config().camera_model());
    let located = locate(&camera, robot, &input.target, &input.target_box)?;
    let depth_m = located.as_ref().map(|l| l.camera_depth_m);
    let target = match located {
        Some(located) => {
            let report = goal_from_target(robot, located, input.goal_standoff_m)?;
            if task.goal.is_some() {
                return Err(Error::invalid(
                    "goal",
                    "a goal is derived from the depth / target_position; send one or the other",
                ));
            }
            let mut goal = Goal::at(report.goal, report.goal_tolerance_m);
            if let Some(a) = &input.approach {
                goal.approach_axis = Some(a.approach_axis);
                goal.approach_tolerance_rad = a.approach_tolerance_rad;
            }
            task.goal = Some(goal);
            Some(report)
        }
        None if input.approach.is_some() => {
            return Err(Error::invalid(
                "goal.position",
                "an approach direction needs a goal: send goal.position, a depth image or a target position",
            ))
        }
        None => None,
    };
    let prediction = model
        .predict_with_depth(&input.image, input.target_box, input.mask_applied, depth_m)
        .map_err(|e| match e {
            // The network's own output failed its checks: a model fault.
            Error::Invalid { ref field, .. } if field.starts_with("prediction") => {
                model_fault(model, &e)
            }
            other => other,
        })?;
    let basis = task.basis()?;
    check_dimensions(&prediction.distribution, robot, &basis)?;
    check_model_prior(model, &prediction.distribution, robot, &basis)?;
    let distribution = match &target {
        Some(report) => prior_towards_goal(&prediction.distribution, robot, &basis, report)?,
        None => prediction.distribution,
    };
    let prior = prior_trajectory(&distribution, &basis);
    // The optimiser checks the (conditioned) prior as it checks a
    // request's; a prior it refuses came from the model.
    let result = optimize_prior(&distribution, &task, &basis, robot, ctl).map_err(|e| match e {
        Error::Invalid { ref field, .. } if field.starts_with("prior") => model_fault(model, &e),
        other => other,
    })?;
    Ok(PlanResponse {
        result,
        prior,
        model: model.name().to_string(),
        target,
    })
}

/// A goal standoff needs a 3-D target to stand off from; `field` names the
/// standoff in the error (`goal_standoff_m`, `--goal-standoff`).
pub fn check_standoff(standoff: Option<f64>, target: &TargetInput, field: &str) -> Result<()> {
    if standoff.is_some() && matches!(target, TargetInput::None) {
        return Err(Error::invalid(
            field,
            "applies only with a depth image or a target position",
        ));
    }
    Ok(())
}

/// Standard deviation of the goal observation the prior is conditioned on
/// (m): well inside the optimiser's goal tolerance, loose enough that the
/// update stays a small, well-conditioned correction.
pub const GOAL_PRIOR_STD_M: f64 = 0.001;

/// The network's prior conditioned on its final TCP reaching the goal
/// ([`WeightDistribution::condition_final_point`]): the network keeps the
/// posture and timing it learnt from the demonstrations, the kinematics
/// move the hand to the 3-D target, and the optimiser starts next to the
/// goal instead of pulling the whole trajectory there.
pub fn prior_towards_goal(
    prior: &WeightDistribution,
    robot: &Robot,
    basis: &Basis,
    target: &TargetReport,
) -> Result<WeightDistribution> {
    let kinematics = |q: &[f64]| {
        let position = robot.tcp_pose(q).translation.vector;
        let jacobian = robot.tcp_jacobian(q);
        let rows = jacobian.fixed_rows::<3>(0);
        (
            position,
            DMatrix::from_fn(3, rows.ncols(), |r, c| rows[(r, c)]),
        )
    };
    let observation = FinalPointObservation::new(Vector3::from(target.goal), GOAL_PRIOR_STD_M);
    Ok(prior
        .condition_final_point(basis, &observation, &kinematics)?
        .distribution)
}

/// A berry centre, its measured depth and where it came from.
struct Located {
    position: [f64; 3],
    depth_m: Option<f64>,
    /// Depth of the centre along the camera's optical axis: measured, or
    /// that of the client's position (what a depth-conditioned model reads).
    camera_depth_m: f64,
    source: TargetSource,
}

/// The berry centre, if the input has one.
fn locate(
    camera: &CameraModel,
    robot: &Robot,
    target: &TargetInput,
    target_box: &[f64; 4],
) -> Result<Option<Located>> {
    if let TargetInput::None = target {
        return Ok(None);
    }
    let camera = Camera::at_home(camera, robot)?;
    match target {
        TargetInput::None => Ok(None),
        TargetInput::Position(p) => {
            check_target_position(p)?;
            Ok(Some(Located {
                position: *p,
                depth_m: None,
                camera_depth_m: camera.to_camera(&Point3::from(*p)).z,
                source: TargetSource::Client,
            }))
        }
        TargetInput::Depth(depth, field) => {
            let t = locate_target(depth, target_box, &camera, field)?;
            Ok(Some(Located {
                position: t.position,
                depth_m: Some(t.depth_m),
                camera_depth_m: t.depth_m,
                source: TargetSource::Depth,
            }))
        }
    }
}

/// The target box `[x1, y1, x2, y2]` must be finite, ordered, inside the
/// `width x height` image and at least [`MIN_BOX_PX`] on each side; errors
/// name `field`.
pub fn check_target_box(b: &[f64; 4], width: u32, height: u32, field: &str) -> Result<()> {
    crate::error::ensure_finite(field, b)?;
    if b[0] >= b[2] || b[1] >= b[3] {
        return Err(Error::invalid(
            field,
            format!("needs x1 < x2 and y1 < y2, got {b:?}"),
        ));
    }
    let (w, h) = (f64::from(width), f64::from(height));
    if b[0] < 0.0 || b[1] < 0.0 || b[2] > w || b[3] > h {
        return Err(Error::invalid(
            field,
            format!("the box {b:?} is not inside the {width}x{height} image"),
        ));
    }
    if b[2] - b[0] < MIN_BOX_PX || b[3] - b[1] < MIN_BOX_PX {
        return Err(Error::invalid(
            field,
            format!(
                "the box {b:?} is {:.2} x {:.2} px, under {MIN_BOX_PX} px: it is in image pixels x1,y1,x2,y2, not normalised to 0..1",
                b[2] - b[0],
                b[3] - b[1]
            ),
        ));
    }
    Ok(())
}

/// Depth back-projection uses the camera's intrinsics: the colour image
/// (and the aligned depth image) must be of its size; errors name `field`
/// (the colour image's input). `camera`: the request's, else the model's.
pub fn check_camera_size(
    model: &Model,
    camera: Option<&CameraModel>,
    width: u32,
    height: u32,
    field: &str,
) -> Result<()> {
    let (given, k) = match camera {
        Some(c) => (true, c.intrinsics),
        None => (false, model.config().camera_model().intrinsics),
    };
    if (k.width, k.height) == (width, height) {
        return Ok(());
    }
    let whose = if given {
        "the given camera".to_string()
    } else {
        format!("model {}'s camera", model.name())
    };
    Err(Error::invalid(
        field,
        format!(
            "the colour image is {width}x{height}, but {whose} is {}x{}: depth is back-projected with that camera's intrinsics, so send its full images, give the camera that took them (`camera` / --camera), or a 3-D target position instead of depth",
            k.width, k.height
        ),
    ))
}

/// The smallest target box side accepted (px): a berry the camera sees
/// covers more, and a box under it is usually given in normalised units.
pub const MIN_BOX_PX: f64 = 2.0;

/// Validate a client's `target_position`.
pub fn check_target_position(p: &[f64; 3]) -> Result<()> {
    crate::error::ensure_finite("target_position", p)?;
    if p.iter().any(|c| c.abs() > 5.0) {
        return Err(Error::invalid(
            "target_position",
            format!("{p:?} is more than 5 m from the robot base"),
        ));
    }
    Ok(())
}

/// The pre-grasp goal `standoff` short of `position` on the line from the
/// home TCP (see the module docs).
fn goal_from_target(robot: &Robot, target: Located, standoff: Option<f64>) -> Result<TargetReport> {
    let Located {
        position,
        depth_m,
        source,
        ..
    } = target;
    let standoff = standoff.unwrap_or(DEFAULT_GOAL_STANDOFF_M);
    crate::error::ensure_in_range("goal_standoff_m", standoff, 0.0, MAX_GOAL_STANDOFF_M)?;
    let home = robot.tcp_pose(&robot.home()).translation.vector;
    let berry = Vector3::from(position);
    let axis = (berry - home)
        .try_normalize(1e-9)
        .ok_or_else(|| Error::invalid("target_position", "coincides with the home TCP position"))?;
    let goal = berry - axis * standoff;
    Ok(TargetReport {
        position,
        depth_m,
        source,
        goal: [goal.x, goal.y, goal.z],
        goal_tolerance_m: GOAL_TOLERANCE_M,
    })
}

/// The network's (conditioned) prediction must be a prior the optimiser
/// accepts; when it is not, the model is at fault (corrupt or badly trained
/// weights), never the request: [`Error::Model`].
fn check_model_prior(
    model: &Model,
    d: &WeightDistribution,
    robot: &Robot,
    basis: &Basis,
) -> Result<()> {
    crate::optim::request::check_prior(d, robot.dof(), basis.n_basis())
        .map_err(|e| model_fault(model, &e))
}

/// A model's output that failed a check, as [`Error::Model`].
fn model_fault(model: &Model, e: &Error) -> Error {
    Error::Model(format!(
        "the model {:?} predicted an invalid prior ({e}); its weights may be corrupt",
        model.name()
    ))
}

fn check_dimensions(d: &WeightDistribution, robot: &Robot, basis: &Basis) -> Result<()> {
    let expected = robot.dof() * basis.n_basis();
    if d.dim() == expected {
        return Ok(());
    }
    Err(Error::invalid(
        "promp.n_basis",
        format!(
            "the model predicts {} weights = {} joints x {} basis functions; \
             the request asks for {} x {}",
            d.dim(),
            robot.dof(),
            d.dim() / robot.dof().max(1),
            robot.dof(),
            basis.n_basis()
        ),
    ))
}

fn prior_trajectory(d: &WeightDistribution, basis: &Basis) -> PriorTrajectory {
    PriorTrajectory {
        mean: matrix_rows(&d.trajectory_mean(basis)),
        std: matrix_rows(&d.trajectory_std(basis, 0.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::example_distribution;
    use crate::promp::PrompConfig;

    #[test]
    fn the_conditioned_prior_ends_at_the_goal_with_the_real_kinematics() {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let prior = example_distribution(&basis, 20, 3).unwrap();
        let mean = prior.trajectory_mean(&basis);
        let last: Vec<f64> = mean.row(mean.nrows() - 1).iter().copied().collect();
        // A goal 4 cm from where the prior's mean ends, through the Panda's
        // real kinematics.
        let goal = robot.tcp_pose(&last).translation.vector + Vector3::new(0.02, -0.03, 0.015);
        let report = TargetReport {
            position: (goal + Vector3::new(0.1, 0.0, 0.0)).into(),
            depth_m: None,
            source: TargetSource::Client,
            goal: goal.into(),
            goal_tolerance_m: 0.005,
        };
        let posterior = prior_towards_goal(&prior, &robot, &basis, &report).unwrap();
        let m = posterior.trajectory_mean(&basis);
        let end: Vec<f64> = m.row(m.nrows() - 1).iter().copied().collect();
        let reached = (robot.tcp_pose(&end).translation.vector - goal).norm();
        assert!(reached < 2e-3, "final TCP {reached} m from the goal");
        // The start barely moves (the basis functions at the two ends
        // hardly overlap) and conditioning only removes uncertainty.
        for (a, b) in m.row(0).iter().zip(mean.row(0).iter()) {
            assert!((a - b).abs() < 0.02, "start moved from {b} to {a}");
        }
        let shrink = (&prior.cov - &posterior.cov).symmetric_eigenvalues().min();
        assert!(shrink > -1e-9, "{shrink}");
    }
}
