//! `moveit_msgs/MotionPlanRequest` → where to start, where to end and how
//! fast, in the robot's joints.
//!
//! Read: `start_state.joint_state` (by joint name; the robot's joints must
//! all be there; the finger joints pose the fingers ([`super::fingers`]);
//! other joints are reported and not used), the first of `goal_constraints` (its `joint_constraints`: a final
//! configuration, every arm joint given, each within the joint's limits;
//! or a `position_constraints` region's centre and size with an
//! `orientation_constraints`' z axis as the approach direction),
//! `max_velocity_scaling_factor` and `max_acceleration_scaling_factor` (0
//! means 1, as in MoveIt) and `allowed_planning_time` (s).

use super::fingers::{finger_poses, robot_with_fingers, FingerPose};
use super::joint_goal::JointGoal;
use crate::optim::{Goal, GoalApproach};
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::Vector3;
use serde::Deserialize;

/// What a MoveIt motion plan request asks, in the robot's terms.
#[derive(Clone, Debug, PartialEq)]
pub struct MoveItRequest {
    /// The start configuration, one value per robot joint in its order.
    pub start: Vec<f64>,
    /// Where the start state puts the fingers (none when it does not give
    /// their joints or the robot has no finger links).
    pub fingers: Vec<FingerPose>,
    /// Where to end.
    pub goal: MoveItGoal,
    /// Factor in (0, 1] on the velocity limits.
    pub velocity_scaling: f64,
    /// Factor in (0, 1] on the acceleration limits.
    pub acceleration_scaling: f64,
    /// `allowed_planning_time` (s), when given.
    pub planning_time_s: Option<f64>,
    /// What was read and not used.
    pub warnings: Vec<String>,
}

/// A MoveIt goal.
#[derive(Clone, Debug, PartialEq)]
pub enum MoveItGoal {
    /// A configuration, one value per robot joint, with its tolerances.
    Configuration(JointGoal),
    /// A TCP position (and approach direction).
    Position(Goal),
}

/// Read a `MotionPlanRequest` from YAML or JSON `text` for `robot`; errors
/// name the field (`goal_constraints[0].joint_constraints[3].position`).
pub fn read_motion_plan_request(text: &str, robot: &Robot) -> Result<MoveItRequest> {
    let request: MotionPlanRequest = serde_yaml::from_str(text).map_err(|e| {
        Error::invalid(
            "motion_plan_request",
            format!("not a MotionPlanRequest: {e}"),
        )
    })?;
    request.for_robot(robot)
}

#[derive(Debug, Deserialize)]
struct MotionPlanRequest {
    start_state: RobotState,
    #[serde(default)]
    goal_constraints: Vec<Constraints>,
    #[serde(default)]
    max_velocity_scaling_factor: f64,
    #[serde(default)]
    max_acceleration_scaling_factor: f64,
    #[serde(default)]
    allowed_planning_time: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct RobotState {
    joint_state: JointState,
}

#[derive(Debug, Deserialize)]
struct JointState {
    #[serde(default)]
    name: Vec<String>,
    #[serde(default)]
    position: Vec<f64>,
}

#[derive(Debug, Default, Deserialize)]
struct Constraints {
    #[serde(default)]
    joint_constraints: Vec<JointConstraint>,
    #[serde(default)]
    position_constraints: Vec<PositionConstraint>,
    #[serde(default)]
    orientation_constraints: Vec<OrientationConstraint>,
}

#[derive(Debug, Deserialize)]
struct JointConstraint {
    joint_name: String,
    position: f64,
    #[serde(default)]
    tolerance_above: f64,
    #[serde(default)]
    tolerance_below: f64,
}

#[derive(Debug, Deserialize)]
struct PositionConstraint {
    constraint_region: BoundingVolume,
}

#[derive(Debug, Deserialize)]
struct BoundingVolume {
    #[serde(default)]
    primitives: Vec<RegionPrimitive>,
    #[serde(default)]
    primitive_poses: Vec<RegionPose>,
}

#[derive(Debug, Deserialize)]
struct RegionPrimitive {
    #[serde(default)]
    dimensions: Vec<f64>,
}

#[derive(Debug, Deserialize)]
struct RegionPose {
    position: super::planning_scene::Xyz,
}

#[derive(Debug, Deserialize)]
struct OrientationConstraint {
    orientation: super::planning_scene::Xyzw,
    #[serde(default)]
    absolute_z_axis_tolerance: Option<f64>,
}

impl MoveItRequest {
    /// `robot` with its fingers where the start state puts them (borrowed
    /// unchanged when they are already there).
    pub fn robot<'r>(&self, robot: &'r Robot) -> Result<std::borrow::Cow<'r, Robot>> {
        robot_with_fingers(robot, &self.fingers)
    }
}

impl MotionPlanRequest {
    fn for_robot(self, robot: &Robot) -> Result<MoveItRequest> {
        let mut warnings = Vec::new();
        let state = &self.start_state.joint_state;
        let (fingers, finger_joints) = finger_poses(
            "start_state.joint_state",
            &state.name,
            &state.position,
            robot,
            &mut warnings,
        )?;
        let start = configuration_by_name(state, robot, &finger_joints, &mut warnings)?;
        if self.goal_constraints.len() > 1 {
            warnings.push(format!(
                "{} goal constraint sets: the first is planned for",
                self.goal_constraints.len()
            ));
        }
        let goal = match self.goal_constraints.first() {
            Some(c) => c.goal(robot, &self.start_state.joint_state.name, &mut warnings)?,
            None => {
                return Err(Error::invalid(
                    "goal_constraints",
                    "no goal: give joint_constraints or a position constraint",
                ))
            }
        };
        Ok(MoveItRequest {
            start,
            fingers,
            goal,
            velocity_scaling: scaling(
                "max_velocity_scaling_factor",
                self.max_velocity_scaling_factor,
            )?,
            acceleration_scaling: scaling(
                "max_acceleration_scaling_factor",
                self.max_acceleration_scaling_factor,
            )?,
            planning_time_s: match self.allowed_planning_time {
                Some(t) if !(t.is_finite() && t > 0.0) => {
                    return Err(Error::invalid(
                        "allowed_planning_time",
                        format!("must be a positive number of seconds, got {t}"),
                    ))
                }
                t => t,
            },
            warnings,
        })
    }
}

/// A MoveIt scaling factor: 0 means 1 (MoveIt's default), else (0, 1].
fn scaling(field: &str, value: f64) -> Result<f64> {
    if value == 0.0 {
        return Ok(1.0);
    }
    if value.is_finite() && value > 0.0 && value <= 1.0 {
        return Ok(value);
    }
    Err(Error::invalid(
        field,
        format!("must be in [0, 1] (0 means 1), got {value}"),
    ))
}

/// The robot's joints from a joint state, by name; joints the robot lacks
/// (other than the finger joints `used` elsewhere) are reported in
/// `warnings`.
fn configuration_by_name(
    state: &JointState,
    robot: &Robot,
    used: &[String],
    warnings: &mut Vec<String>,
) -> Result<Vec<f64>> {
    const FIELD: &str = "start_state.joint_state";
    if state.name.len() != state.position.len() {
        return Err(Error::invalid(
            format!("{FIELD}.position"),
            format!(
                "{} positions for {} names",
                state.position.len(),
                state.name.len()
            ),
        ));
    }
    let mut q = Vec::with_capacity(robot.dof());
    for joint in robot.joint_names() {
        let Some(i) = state.name.iter().position(|n| n == joint) else {
            return Err(Error::invalid(
                format!("{FIELD}.name"),
                format!("the robot's joint {joint:?} is missing"),
            ));
        };
        q.push(state.position[i]);
    }
    let unused: Vec<&str> = state
        .name
        .iter()
        .filter(|n| !robot.joint_names().contains(n) && !used.contains(n))
        .map(String::as_str)
        .collect();
    if !unused.is_empty() {
        warnings.push(format!(
            "joints not in the planned chain, not used: {}",
            unused.join(", ")
        ));
    }
    robot.validate_configuration(&format!("{FIELD}.position"), &q)?;
    Ok(q)
}

impl Constraints {
    /// The goal of these constraints; a joint constraint on a joint of the
    /// robot's state (`state_joints`) outside the planned chain is reported
    /// in `warnings`, one on a joint neither knows is refused.
    fn goal(
        &self,
        robot: &Robot,
        state_joints: &[String],
        warnings: &mut Vec<String>,
    ) -> Result<MoveItGoal> {
        const FIELD: &str = "goal_constraints[0]";
        if !self.joint_constraints.is_empty() {
            for (k, c) in self.joint_constraints.iter().enumerate() {
                if robot.joint_names().contains(&c.joint_name) {
                    continue;
                }
                if !state_joints.contains(&c.joint_name) {
                    return Err(Error::invalid(
                        format!("{FIELD}.joint_constraints[{k}].joint_name"),
                        format!(
                            "INVALID_GOAL_CONSTRAINTS: no joint {:?} in the robot ({}) or its start state",
                            c.joint_name,
                            robot.joint_names().join(", ")
                        ),
                    ));
                }
                warnings.push(format!(
                    "goal joint {:?} is not in the planned chain: not used",
                    c.joint_name
                ));
            }
            let mut goal = JointGoal::exact(Vec::new());
            let mut indices = Vec::with_capacity(robot.dof());
            for joint in robot.joint_names() {
                let Some((k, c)) = self
                    .joint_constraints
                    .iter()
                    .enumerate()
                    .find(|(_, c)| &c.joint_name == joint)
                else {
                    return Err(Error::invalid(
                        format!("{FIELD}.joint_constraints"),
                        format!("the robot's joint {joint:?} has no constraint"),
                    ));
                };
                let at = format!("{FIELD}.joint_constraints[{k}]");
                for (name, value) in [
                    ("tolerance_above", c.tolerance_above),
                    ("tolerance_below", c.tolerance_below),
                ] {
                    if !(value.is_finite() && (0.0..=std::f64::consts::TAU).contains(&value)) {
                        return Err(Error::invalid(
                            format!("{at}.{name}"),
                            format!("must be in [0, 2π] rad, got {value}"),
                        ));
                    }
                }
                if !c.position.is_finite() {
                    return Err(Error::invalid(
                        format!("{at}.position"),
                        format!("must be finite, got {}", c.position),
                    ));
                }
                goal.position.push(c.position);
                goal.below.push(c.tolerance_below);
                goal.above.push(c.tolerance_above);
                indices.push(k);
            }
            if let Err(j) = goal.within_limits(robot) {
                let (limit, c) = (&robot.limits()[j], &self.joint_constraints[indices[j]]);
                return Err(Error::invalid(
                    format!("{FIELD}.joint_constraints[{}].position", indices[j]),
                    format!(
                        "INVALID_GOAL_CONSTRAINTS: {} at {} (-{}, +{}) is outside its limits [{}, {}]",
                        c.joint_name,
                        c.position,
                        c.tolerance_below,
                        c.tolerance_above,
                        limit.lower,
                        limit.upper
                    ),
                ));
            }
            return Ok(MoveItGoal::Configuration(goal));
        }
        let Some(position) = self.position_constraints.first() else {
            return Err(Error::invalid(
                FIELD,
                "no joint_constraints and no position_constraints: nothing to plan to",
            ));
        };
        let region = &position.constraint_region;
        let (Some(pose), Some(shape)) = (region.primitive_poses.first(), region.primitives.first())
        else {
            return Err(Error::invalid(
                format!("{FIELD}.position_constraints[0].constraint_region"),
                "needs a primitive and its pose",
            ));
        };
        let size = shape
            .dimensions
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        if !(size.is_finite() && size > 0.0) {
            return Err(Error::invalid(
                format!(
                    "{FIELD}.position_constraints[0].constraint_region.primitives[0].dimensions"
                ),
                "must hold positive sizes",
            ));
        }
        let mut goal = Goal::at(pose.position.array(), size.min(1.0));
        if let Some(o) = self.orientation_constraints.first() {
            let q = o.orientation.array();
            let axis = crate::geometry::quaternion::from_xyzw(&q) * Vector3::z();
            let approach = GoalApproach {
                approach_axis: axis.into(),
                approach_tolerance_rad: o.absolute_z_axis_tolerance.unwrap_or(0.1745),
            };
            goal = goal.with_approach(Some(&approach));
        }
        Ok(MoveItGoal::Position(goal))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MotionBenchMaker's layout: nine joints (two fingers), a joint goal.
    const REQUEST: &str = r#"
group_name: panda_arm
allowed_planning_time: 60
max_acceleration_scaling_factor: 0
max_velocity_scaling_factor: 0.5
goal_constraints:
  - joint_constraints:
      - {position: -0.16, joint_name: panda_joint1}
      - {position: 1.08, joint_name: panda_joint2}
      - {joint_name: panda_joint3, position: -1.40}
      - {position: -1.19, joint_name: panda_joint4}
      - {position: 2.43, joint_name: panda_joint5}
      - {position: 2.94, joint_name: panda_joint6}
      - {position: 2.56, joint_name: panda_joint7}
start_state:
  joint_state:
    name: [panda_joint1, panda_joint2, panda_joint3, panda_joint4, panda_joint5, panda_joint6, panda_joint7, panda_finger_joint1, panda_finger_joint2]
    position: [0, -0.785, 0, -2.356, 0, 1.571, 0.785, 0.065, 0.065]
"#;

    #[test]
    fn start_goal_and_factors_come_out_in_the_robots_joints() {
        let robot = Robot::panda().unwrap();
        let r = read_motion_plan_request(REQUEST, &robot).unwrap();
        assert_eq!(r.start, vec![0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]);
        assert_eq!(
            r.goal,
            MoveItGoal::Configuration(JointGoal::exact(vec![
                -0.16, 1.08, -1.40, -1.19, 2.43, 2.94, 2.56
            ]))
        );
        assert_eq!((r.velocity_scaling, r.acceleration_scaling), (0.5, 1.0));
        assert_eq!(r.planning_time_s, Some(60.0));
        // MotionBenchMaker's 0.065 m fingers are clamped to franka's 0.04.
        let openings: Vec<f64> = r.fingers.iter().map(|f| f.opening_m).collect();
        assert_eq!(openings, [0.04, 0.04]);
        assert!(
            r.warnings[0].contains("panda_finger_joint1 = 0.065 is outside its limits"),
            "{:?}",
            r.warnings
        );
        assert!(
            !r.warnings.iter().any(|w| w.contains("not used")),
            "{:?}",
            r.warnings
        );
        // JSON reads the same.
        let value: serde_json::Value = serde_yaml::from_str(REQUEST).unwrap();
        assert_eq!(
            read_motion_plan_request(&value.to_string(), &robot).unwrap(),
            r
        );
    }

    #[test]
    fn a_position_goal_takes_its_region_and_the_approach_its_z_axis() {
        let robot = Robot::panda().unwrap();
        let text = r#"
start_state: {joint_state: {name: [panda_joint1, panda_joint2, panda_joint3, panda_joint4, panda_joint5, panda_joint6, panda_joint7], position: [0, -0.785, 0, -2.356, 0, 1.571, 0.785]}}
goal_constraints:
  - position_constraints:
      - constraint_region:
          primitives: [{type: 2, dimensions: [0.01]}]
          primitive_poses: [{position: {x: 0.5, y: 0.1, z: 0.4}}]
    orientation_constraints:
      - {orientation: [1, 0, 0, 0], absolute_z_axis_tolerance: 0.2}
"#;
        let r = read_motion_plan_request(text, &robot).unwrap();
        let MoveItGoal::Position(goal) = r.goal else {
            panic!()
        };
        assert_eq!((goal.position, goal.tolerance_m), ([0.5, 0.1, 0.4], 0.01));
        let axis = goal.approach_axis.unwrap();
        assert!((axis[2] + 1.0).abs() < 1e-12, "{axis:?}");
        assert_eq!(goal.approach_tolerance_rad, 0.2);
    }

    #[test]
    fn bad_requests_name_the_field() {
        let robot = Robot::panda().unwrap();
        let cases = [
            (
                REQUEST.replace("panda_joint7, panda_finger", "panda_jointX, panda_finger"),
                "start_state.joint_state.name",
            ),
            (
                REQUEST.replace("position: 2.94", "position: 9.0"),
                "goal_constraints[0].joint_constraints[5].position",
            ),
            (
                REQUEST.replace(
                    "max_velocity_scaling_factor: 0.5",
                    "max_velocity_scaling_factor: 1.5",
                ),
                "max_velocity_scaling_factor",
            ),
            (
                REQUEST.replace("allowed_planning_time: 60", "allowed_planning_time: -1"),
                "allowed_planning_time",
            ),
            (
                REQUEST.replace("      - {position: 2.43, joint_name: panda_joint5}\n", ""),
                "goal_constraints[0].joint_constraints",
            ),
            (
                REQUEST.replace("0.065, 0.065]", "0.065]"),
                "start_state.joint_state.position",
            ),
        ];
        for (text, field) in cases {
            let e = read_motion_plan_request(&text, &robot).unwrap_err();
            assert_eq!(e.field(), Some(field), "{e}");
        }
        let e =
            read_motion_plan_request(&REQUEST.replace("position: 2.94", "position: 9.0"), &robot)
                .unwrap_err();
        assert!(
            e.to_string().contains("INVALID_GOAL_CONSTRAINTS")
                && e.to_string().contains("panda_joint6")
        );
    }
}
