//! One MoveIt query planned: a `PlanningScene` and a `MotionPlanRequest`
//! (texts, YAML or JSON) and the optimiser's options in; the optimise
//! answer, a `moveit_msgs/RobotTrajectory` and a MoveIt error code out.
//! `dpmp plan-moveit` and `POST /v1/moveit/plan` are thin shells over
//! [`plan_moveit`], so both give the same answer to the same query.
//!
//! The request becomes an optimise request: the scene's obstacles, the
//! start, the goal (a final configuration, or a TCP position with an
//! approach axis), the scaling factors, and `allowed_planning_time` as a
//! deadline (the earlier of it and the caller's). Without a prior the
//! smoothness prior plans ([`crate::promp::smooth`]); without a duration
//! the shortest one that keeps the rate limits
//! ([`crate::optim::auto_duration`]).

use super::error_code::{ErrorCodeMsg, MoveItErrorCode};
use super::{read_motion_plan_request, read_planning_scene, MoveItGoal};
use crate::optim::report::{JointTrajectory, TrajectoryFormat};
use crate::optim::{
    optimize_auto_duration, optimize_with, OptimizeRequest, OptimizeResponse, PriorSpec,
    SolveControl, SolverOptions, Task,
};
use crate::promp::PrompConfig;
use crate::robot::Robot;
use crate::{Error, Result};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::time::{Duration, Instant};

/// Default clearance (m) of a MoveIt query: MoveIt plans to contact
/// (padding 0); dPMP keeps 5 mm, which the cage and shelf problems of
/// MotionBenchMaker leave room for.
pub const MOVEIT_DEFAULT_CLEARANCE_M: f64 = 0.005;

/// The motion's duration: `"auto"` (the default) or seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum DurationChoice {
    /// The shortest that keeps the rate limits
    /// ([`optimize_auto_duration`]).
    #[default]
    Auto,
    /// This many seconds.
    Seconds(f64),
}

impl std::str::FromStr for DurationChoice {
    type Err = String;

    /// `auto` or a number of seconds.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        if s == "auto" {
            return Ok(DurationChoice::Auto);
        }
        s.parse::<f64>()
            .map(DurationChoice::Seconds)
            .map_err(|_| format!("expected `auto` or seconds, got {s:?}"))
    }
}

impl Serialize for DurationChoice {
    fn serialize<S: Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            DurationChoice::Auto => serializer.serialize_str("auto"),
            DurationChoice::Seconds(s) => serializer.serialize_f64(*s),
        }
    }
}

impl<'de> Deserialize<'de> for DurationChoice {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Wire {
            Seconds(f64),
            Word(String),
        }
        match Wire::deserialize(deserializer)? {
            Wire::Seconds(s) => Ok(DurationChoice::Seconds(s)),
            Wire::Word(w) if w == "auto" => Ok(DurationChoice::Auto),
            Wire::Word(w) => Err(serde::de::Error::custom(format!(
                "expected \"auto\" or a number of seconds, got {w:?}"
            ))),
        }
    }
}

/// The optimiser's side of a MoveIt query; every field is optional.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MoveItPlanOptions {
    /// The prior (default `"smooth"`).
    #[serde(default)]
    pub prior: PriorSpec,
    /// The basis (default: the one that suits the prior,
    /// [`PriorSpec::default_basis`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub promp: Option<PrompConfig>,
    /// Required clearance (m).
    #[serde(default = "default_clearance")]
    pub clearance_m: f64,
    /// `"auto"` or seconds.
    #[serde(default)]
    pub duration_s: DurationChoice,
    /// Solver knobs (`final_configuration` comes from the request).
    #[serde(default)]
    pub options: SolverOptions,
}

fn default_clearance() -> f64 {
    MOVEIT_DEFAULT_CLEARANCE_M
}

impl Default for MoveItPlanOptions {
    fn default() -> Self {
        MoveItPlanOptions {
            prior: PriorSpec::default(),
            promp: None,
            clearance_m: MOVEIT_DEFAULT_CLEARANCE_M,
            duration_s: DurationChoice::Auto,
            options: SolverOptions::default(),
        }
    }
}

/// `moveit_msgs/RobotTrajectory`: the joint trajectory (ROS 2 form; no
/// points unless the answer is certified) and an empty multi-DOF one.
#[derive(Clone, Debug, Serialize)]
pub struct RobotTrajectory {
    /// `trajectory_msgs/JointTrajectory`.
    pub joint_trajectory: JointTrajectory,
    /// `trajectory_msgs/MultiDOFJointTrajectory` (dPMP plans no floating
    /// joints: always empty).
    pub multi_dof_joint_trajectory: MultiDofTrajectory,
}

/// An empty `trajectory_msgs/MultiDOFJointTrajectory`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct MultiDofTrajectory {
    /// Joint names (none).
    pub joint_names: Vec<String>,
    /// Points (none).
    pub points: Vec<()>,
}

/// The MoveIt side of the answer.
#[derive(Clone, Debug, Serialize)]
pub struct MoveItAnswer {
    /// `moveit_msgs/MoveItErrorCodes`.
    pub error_code: ErrorCodeMsg,
    /// The code's name (`SUCCESS`, `PLANNING_FAILED`, ...).
    pub error_code_name: &'static str,
    /// The certified trajectory (empty unless `SUCCESS`).
    pub trajectory: RobotTrajectory,
    /// Wall time of the planning (s); not deterministic.
    pub planning_time: f64,
    /// What the readers took differently from MoveIt (unused joints,
    /// allowed collisions dPMP does not honour, ...).
    pub warnings: Vec<String>,
}

/// The answer to a MoveIt query: the optimise answer with its MoveIt side.
#[derive(Clone, Debug, Serialize)]
pub struct MoveItPlanResponse {
    /// The optimiser's answer (the trajectory in the ROS 2 form).
    #[serde(flatten)]
    pub result: OptimizeResponse,
    /// MoveIt's view of it.
    pub moveit: MoveItAnswer,
}

impl MoveItPlanResponse {
    /// The response as JSON with its wall-clock fields set to 0 (identical
    /// bytes for identical queries).
    pub fn deterministic_json(&self) -> String {
        let mut copy = self.clone();
        copy.moveit.planning_time = 0.0;
        copy.result.report.solve_ms = 0.0;
        copy.result.prior_mean_report.solve_ms = 0.0;
        serde_json::to_string(&copy).unwrap_or_default()
    }
}

/// A MoveIt query as read: the world and the request, in the robot's terms.
#[derive(Clone, Debug)]
pub struct MoveItQuery {
    /// The `PlanningScene`'s obstacles and warnings.
    pub scene: super::MoveItScene,
    /// The `MotionPlanRequest`.
    pub request: super::MoveItRequest,
}

impl MoveItQuery {
    /// Read `scene` (a `PlanningScene`) and `request` (a
    /// `MotionPlanRequest`), YAML or JSON texts, for `robot`. Errors name
    /// the field (`planning_scene.…`, `motion_plan_request.…`).
    pub fn read(scene: &str, request: &str, robot: &Robot) -> Result<MoveItQuery> {
        let base = robot.link_names().first().map_or("", String::as_str);
        Ok(MoveItQuery {
            scene: read_planning_scene(scene, base).map_err(|e| under("planning_scene", e))?,
            request: read_motion_plan_request(request, robot)
                .map_err(|e| under("motion_plan_request", e))?,
        })
    }

    /// The optimise request of this query with `options`: the scene's
    /// obstacles, the start, the goal (the joint constraints' positions as
    /// the final configuration, which [`plan_moveit`] then settles within
    /// their tolerances; or a TCP position with an approach axis) and the
    /// scaling factors.
    pub fn optimize_request(&self, options: &MoveItPlanOptions) -> Result<OptimizeRequest> {
        let query = &self.request;
        let mut solver = options.options.clone();
        if solver.final_configuration.is_some() {
            return Err(Error::invalid(
                "options.final_configuration",
                "comes from the motion plan request's joint constraints",
            ));
        }
        let goal = match &query.goal {
            MoveItGoal::Configuration(joints) => {
                solver.final_configuration = Some(joints.position.clone());
                None
            }
            MoveItGoal::Position(goal) => Some(goal.clone()),
        };
        let task = Task {
            promp: options
                .promp
                .clone()
                .unwrap_or_else(|| options.prior.default_basis()),
            duration_s: match options.duration_s {
                DurationChoice::Seconds(s) => s,
                DurationChoice::Auto => crate::optim::auto_duration::AUTO_MIN_DURATION_S,
            },
            start: Some(query.start.clone()),
            goal,
            obstacles: self.scene.obstacles.clone(),
            clearance_m: options.clearance_m,
            options: solver,
            trajectory_format: TrajectoryFormat::Ros2,
            velocity_scaling: query.velocity_scaling,
            acceleration_scaling: query.acceleration_scaling,
            ..Task::default()
        };
        Ok(OptimizeRequest {
            prior: options.prior.clone(),
            task,
        })
    }

    /// Settle `request`'s final configuration within the joint
    /// constraints' tolerances for `robot` (its fingers posed) and the
    /// clearance asked ([`super::joint_goal`]); returns what to add to the
    /// warnings.
    fn settle_goal(&self, request: &mut OptimizeRequest, robot: &Robot) -> Result<Option<String>> {
        let MoveItGoal::Configuration(joints) = &self.request.goal else {
            return Ok(None);
        };
        let task = &mut request.task;
        let chosen = joints.choose(robot, &task.obstacles, task.clearance_m)?;
        task.options.final_configuration = Some(chosen.configuration);
        Ok(chosen.note)
    }
}

/// Plan `query` for `robot` (its fingers where the start state puts them)
/// with `options`, under `ctl` and the request's `allowed_planning_time`
/// (counted from the call).
pub fn plan_moveit(
    query: &MoveItQuery,
    options: &MoveItPlanOptions,
    robot: &Robot,
    ctl: &SolveControl,
) -> Result<MoveItPlanResponse> {
    let started = Instant::now();
    let robot = query.request.robot(robot)?;
    let mut optimize_request = query.optimize_request(options)?;
    let goal_note = query.settle_goal(&mut optimize_request, &robot)?;
    let planning_time = query.request.planning_time_s;
    let ctl = SolveControl {
        deadline: earliest(ctl.deadline, planning_time.map(|t| started + secs(t))),
        ..ctl.clone()
    };
    let result = match options.duration_s {
        DurationChoice::Auto => optimize_auto_duration(&optimize_request, &robot, &ctl)?,
        DurationChoice::Seconds(_) => optimize_with(&optimize_request, &robot, &ctl)?,
    };
    let code = MoveItErrorCode::of(&result);
    let mut joint_trajectory = result.trajectory.clone();
    if code != MoveItErrorCode::Success {
        joint_trajectory.points.clear();
    }
    let mut warnings = query.scene.warnings.clone();
    warnings.extend(query.request.warnings.iter().cloned());
    warnings.extend(goal_note);
    Ok(MoveItPlanResponse {
        moveit: MoveItAnswer {
            error_code: code.into(),
            error_code_name: code.name(),
            trajectory: RobotTrajectory {
                joint_trajectory,
                multi_dof_joint_trajectory: MultiDofTrajectory::default(),
            },
            planning_time: started.elapsed().as_secs_f64(),
            warnings,
        },
        result,
    })
}

/// `e` with its field under `prefix` (once).
fn under(prefix: &str, e: Error) -> Error {
    match &e {
        Error::Invalid { field, .. } if field.starts_with(prefix) => e,
        _ => e.within(prefix),
    }
}

fn secs(t: f64) -> Duration {
    Duration::from_secs_f64(t.clamp(0.0, 1e6))
}

fn earliest(a: Option<Instant>, b: Option<Instant>) -> Option<Instant> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}
