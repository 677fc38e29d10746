//! The image → plan pipeline, as one library call ([`predict_and_optimize`]):
//!
//! ```text
//! image + target box ──► network prior (net)
//! depth + box + camera ──► 3-D berry centre (perception) ──► pre-grasp goal
//! prior + goal + scene ──► optimiser (optim) ──► trajectory + report
//! ```
//!
//! `POST /v1/plan` and `dpmp plan` are shells over it: they read their
//! inputs into [`PlanParts`], validate them once into a [`PlanRequest`]
//! ([`request`]) and print or send the [`PlanResponse`]. [`goal`] turns a
//! 3-D target into the optimiser's goal and conditions the prior on it.
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

pub mod goal;
pub mod request;
pub mod world;

pub use goal::{
    prior_towards_goal, TargetReport, TargetSource, DEFAULT_GOAL_STANDOFF_M, GOAL_PRIOR_STD_M,
    GOAL_TOLERANCE_M,
};
pub use request::{
    check_target_box, check_target_position, PlanFields, PlanParts, PlanRequest, TargetInput,
    MAX_GOAL_STANDOFF_M, MIN_BOX_PX,
};
pub use world::{WorldReport, WorldSource};

use crate::net::{Model, Space};
use crate::optim::{optimize_prior, OptimizeResponse, SolveControl};
use crate::promp::distribution::matrix_rows;
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::scene::ObstacleShape;
use crate::task_space::{joint_prior, JointPriorReport};
use crate::{Error, Result};
use goal::{goal_from_target, locate};
use serde::Serialize;
use std::sync::Arc;

/// The predicted prior as trajectories (`T x dof`, rows are time samples).
#[derive(Debug, Serialize)]
pub struct PriorTrajectory {
    /// Mean joint positions.
    pub mean: Vec<Vec<f64>>,
    /// Standard deviation of the joint positions.
    pub std: Vec<Vec<f64>>,
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
    /// The world sensed from depth, with `world: "depth"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub world: Option<WorldReport>,
    /// A task-space model's prior: how closely the joint-space prior the
    /// optimiser started from tracks the predicted TCP distribution.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub task_space: Option<JointPriorReport>,
    /// With `world: "depth"`, the points of the sensed cloud the plan kept
    /// clear of (m, base frame; empty when the camera saw nothing): the
    /// [`world::SENSED_OBSTACLE_ID`] obstacle's. Not part of the JSON
    /// answer; for pictures (`dpmp plan --plot`).
    #[serde(skip)]
    pub sensed_cloud: Option<Vec<[f64; 3]>>,
}

/// Network prior, goal from the target (if any), then the optimiser.
pub fn predict_and_optimize(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    request: PlanRequest,
    ctl: &SolveControl,
) -> Result<PlanResponse> {
    request.check_camera_size(model)?;
    let PlanRequest {
        image,
        target_box,
        mask_applied,
        target,
        goal_standoff_m,
        approach,
        camera,
        camera_pose,
        world: source,
        world_field,
        target_field,
        names,
        mut task,
        ..
    } = request;
    let camera = camera.unwrap_or_else(|| model.config().camera_model());
    // The posed camera, only when there is a 3-D target to see through it.
    let posed = match (&target, camera_pose) {
        (TargetInput::None, _) => None,
        (_, Some(pose)) => Some(crate::perception::Camera {
            intrinsics: camera.intrinsics,
            pose,
        }),
        (_, None) => Some(crate::perception::Camera::at_home(&camera, robot)?),
    };
    let located = match &posed {
        Some(posed) => locate(posed, &target, &target_box)?,
        None => None,
    };
    let depth_m = located.as_ref().map(|l| l.camera_depth_m);
    if model.config().depth_condition && depth_m.is_none() {
        return Err(Error::invalid(
            &names.depth,
            format!(
                "the model {:?} reads the berry's depth: give {} (an aligned depth image) or {} (the berry's 3-D position), or plan with a box-only model (models/rgb-only)",
                model.name(),
                names.depth,
                names.target_position
            ),
        ));
    }
    let world = match (source, &located, &posed) {
        (WorldSource::Depth, Some(l), Some(posed)) => {
            let TargetInput::Depth(depth, _) = &target else {
                return Err(Error::invalid(
                    &world_field,
                    "\"depth\" needs a depth image",
                ));
            };
            let keep = world::TargetKeepOut {
                target_box,
                center: l.position,
                depth_m: l.camera_depth_m,
            };
            let (sensed, report) = world::sensed_world(depth, posed, &keep, &world_field)?;
            task.obstacles.extend(sensed);
            Some(report)
        }
        _ => None,
    };
    let target = match located {
        Some(located) => {
            let report = goal_from_target(robot, located, goal_standoff_m, &target_field)?;
            task.goal = Some(report.goal(approach.as_ref()));
            Some(report)
        }
        None => None,
    };
    let prediction = model
        .predict_with_depth(&image, target_box, mask_applied, depth_m)
        .map_err(|e| match e {
            // The network's own output failed its checks: a model fault.
            Error::Invalid { ref field, .. } if field.starts_with("prediction") => {
                model_fault(model, &e)
            }
            other => other,
        })?;
    let basis = task.basis()?;
    check_dimensions(&prediction.distribution, robot, &basis)?;
    let (predicted, task_space) = joint_space(
        model,
        robot,
        &basis,
        prediction.distribution,
        task.start.as_deref(),
        ctl,
    )?;
    check_model_prior(model, &predicted, robot, &basis)?;
    let distribution = match &target {
        Some(report) => prior_towards_goal(&predicted, robot, &basis, report)?,
        None => predicted,
    };
    let prior = prior_trajectory(&distribution, &basis);
    // The optimiser checks the (conditioned) prior as it checks a
    // request's; a prior it refuses came from the model.
    let result = optimize_prior(&distribution, &task, &basis, robot, ctl).map_err(|e| match e {
        Error::Invalid { ref field, .. } if field.starts_with("prior") => model_fault(model, &e),
        other => other,
    })?;
    // The task is spent: the sensed cloud moves out of it, uncopied.
    let sensed_cloud = world.as_ref().map(|_| {
        std::mem::take(&mut task.obstacles)
            .into_iter()
            .rev()
            .find(|o| o.id == world::SENSED_OBSTACLE_ID)
            .and_then(|o| match o.shape {
                ObstacleShape::Points { points, .. } => Some(points),
                _ => None,
            })
            .unwrap_or_default()
    });
    Ok(PlanResponse {
        result,
        prior,
        model: model.name().to_string(),
        target,
        world,
        task_space,
        sensed_cloud,
    })
}

/// A task-space model's prediction as the joint-space prior the optimiser
/// takes ([`crate::task_space::joint_prior`] with the model's
/// [`crate::net::TaskPriorSettings`], tracked from the task's start or the
/// robot's home), with its tracking report; a joint-space model's as it is.
fn joint_space(
    model: &Model,
    robot: &Robot,
    basis: &Basis,
    predicted: WeightDistribution,
    start: Option<&[f64]>,
    ctl: &SolveControl,
) -> Result<(WeightDistribution, Option<JointPriorReport>)> {
    if model.config().space == Space::Joint {
        return Ok((predicted, None));
    }
    let start = start.map_or_else(|| robot.home(), <[f64]>::to_vec);
    let options = model.config().task_prior.unwrap_or_default().options();
    let (prior, report) = joint_prior(robot, basis, &predicted, &start, &options, &|| {
        ctl.should_stop()
    })
    .map_err(|e| match e {
        Error::Invalid { .. } | Error::Numerical(_) => model_fault(model, &e),
        other => other,
    })?;
    Ok((prior, Some(report)))
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
