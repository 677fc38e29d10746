//! Acceleration and jerk limits, which URDF has no field for, read from a
//! MoveIt-style `joint_limits.yaml` beside the URDF:
//!
//! ```yaml
//! joint_limits:
//!   panda_joint1:
//!     has_acceleration_limits: true
//!     max_acceleration: 15.0
//!     has_jerk_limits: true
//!     max_jerk: 7500.0
//! ```
//!
//! Every actuated joint of the chain must be listed and every listed name
//! must be one of them; MoveIt's other keys (velocity, position, effort,
//! soft limits) are accepted and ignored — URDF stays the source of
//! positions and velocities. The Panda's file is shipped
//! (`models/panda/joint_limits.yaml`, Franka's published values) and
//! embedded in the binary.

use super::Robot;
use crate::{Error, Result};
use serde::de::IgnoredAny;
use serde::Deserialize;
use std::collections::BTreeMap;

/// The file name looked for beside a URDF.
pub const LIMITS_FILE_NAME: &str = "joint_limits.yaml";

/// The shipped Panda limits (`models/panda/joint_limits.yaml`).
pub const PANDA_JOINT_LIMITS: &str = include_str!("../../models/panda/joint_limits.yaml");

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)] // MoveIt's scaling defaults are parsed only to be accepted
struct LimitsFile {
    joint_limits: BTreeMap<String, JointEntry>,
    #[serde(default)]
    default_velocity_scaling_factor: Option<IgnoredAny>,
    #[serde(default)]
    default_acceleration_scaling_factor: Option<IgnoredAny>,
}

/// One joint's entry; the keys MoveIt defines besides acceleration and
/// jerk are read and ignored, any other key is an error.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)] // MoveIt's other keys are parsed only to be accepted
struct JointEntry {
    #[serde(default)]
    has_acceleration_limits: bool,
    #[serde(default)]
    max_acceleration: Option<f64>,
    #[serde(default)]
    has_jerk_limits: bool,
    #[serde(default)]
    max_jerk: Option<f64>,
    #[serde(default)]
    has_position_limits: Option<IgnoredAny>,
    #[serde(default)]
    min_position: Option<IgnoredAny>,
    #[serde(default)]
    max_position: Option<IgnoredAny>,
    #[serde(default)]
    has_velocity_limits: Option<IgnoredAny>,
    #[serde(default)]
    max_velocity: Option<IgnoredAny>,
    #[serde(default)]
    has_deceleration_limits: Option<IgnoredAny>,
    #[serde(default)]
    max_deceleration: Option<IgnoredAny>,
    #[serde(default)]
    has_effort_limits: Option<IgnoredAny>,
    #[serde(default)]
    max_effort: Option<IgnoredAny>,
    #[serde(default)]
    has_soft_limits: Option<IgnoredAny>,
    #[serde(default)]
    k_position: Option<IgnoredAny>,
    #[serde(default)]
    k_velocity: Option<IgnoredAny>,
    #[serde(default)]
    soft_lower_limit: Option<IgnoredAny>,
    #[serde(default)]
    soft_upper_limit: Option<IgnoredAny>,
}

impl Robot {
    /// Set every actuated joint's acceleration and jerk limits from the text
    /// of a `joint_limits.yaml`. Errors name the field
    /// (`joint_limits.panda_joint2.max_jerk`).
    pub fn with_limits_yaml(mut self, text: &str) -> Result<Robot> {
        let file: LimitsFile = serde_yaml::from_str(text)
            .map_err(|e| Error::invalid("joint_limits", format!("not a joint_limits.yaml: {e}")))?;
        for name in file.joint_limits.keys() {
            if !self.joint_names.contains(name) {
                return Err(Error::invalid(
                    format!("joint_limits.{name}"),
                    format!(
                        "not an actuated joint of this robot's chain ({})",
                        self.joint_names.join(", ")
                    ),
                ));
            }
        }
        for (j, name) in self.joint_names.clone().iter().enumerate() {
            let entry = file.joint_limits.get(name).ok_or_else(|| {
                Error::invalid(
                    format!("joint_limits.{name}"),
                    "missing: every actuated joint needs an entry",
                )
            })?;
            let field = format!("joint_limits.{name}");
            self.limits[j].acceleration = limit_value(
                &field,
                "acceleration",
                entry.has_acceleration_limits,
                entry.max_acceleration,
            )?;
            self.limits[j].jerk =
                limit_value(&field, "jerk", entry.has_jerk_limits, entry.max_jerk)?;
        }
        Ok(self)
    }
}

/// `max_<what>` when `has_<what>_limits` is true: present, finite, > 0.
fn limit_value(field: &str, what: &str, has: bool, value: Option<f64>) -> Result<Option<f64>> {
    match (has, value) {
        (false, _) => Ok(None),
        (true, None) => Err(Error::invalid(
            format!("{field}.max_{what}"),
            format!("missing although has_{what}_limits is true"),
        )),
        (true, Some(v)) if v.is_finite() && v > 0.0 => Ok(Some(v)),
        (true, Some(v)) => Err(Error::invalid(
            format!("{field}.max_{what}"),
            format!("must be a positive finite number, got {v}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_panda_has_franka_s_published_limits() {
        let robot = Robot::panda().unwrap();
        let acc: Vec<f64> = robot
            .limits()
            .iter()
            .filter_map(|l| l.acceleration)
            .collect();
        let jerk: Vec<f64> = robot.limits().iter().filter_map(|l| l.jerk).collect();
        assert_eq!(acc, [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0]);
        assert_eq!(
            jerk,
            [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0]
        );
    }

    fn field_of(text: &str) -> String {
        let robot = Robot::panda().unwrap();
        match robot.with_limits_yaml(text) {
            Err(Error::Invalid { field, .. }) => field,
            other => panic!("expected an error, got {other:?}"),
        }
    }

    #[test]
    fn wrong_names_missing_joints_and_bad_values_are_named() {
        let with = |extra: &str, j2: &str| {
            let mut t = String::from("joint_limits:\n");
            for j in 1..=7 {
                let body = if j == 2 { j2 } else { "max_acceleration: 1.0" };
                t += &format!("  panda_joint{j}:\n    has_acceleration_limits: true\n    {body}\n");
            }
            t + extra
        };
        assert_eq!(
            field_of(&with(
                "  panda_joint9:\n    max_jerk: 1.0\n",
                "max_acceleration: 1.0"
            )),
            "joint_limits.panda_joint9"
        );
        assert_eq!(
            field_of(&with("", "max_acceleration: -1.0")),
            "joint_limits.panda_joint2.max_acceleration"
        );
        assert_eq!(
            field_of(&with("", "max_acceleration: .nan")),
            "joint_limits.panda_joint2.max_acceleration"
        );
        assert_eq!(field_of(&with("", "max_acceleraton: 1.0")), "joint_limits");
        let missing = "joint_limits:\n  panda_joint1:\n    max_velocity: 1.0\n";
        assert_eq!(field_of(missing), "joint_limits.panda_joint2");
        assert_eq!(field_of("[1, 2"), "joint_limits");
        assert_eq!(
            field_of(&with("", "max_velocity: 2.0")),
            "joint_limits.panda_joint2.max_acceleration"
        );
        // MoveIt's other keys are accepted; no has_*: no limit.
        let mut ok = String::from("joint_limits:\n");
        for j in 1..=7 {
            let body = if j == 2 {
                "max_velocity: 2.0\n    has_effort_limits: false"
            } else {
                "has_acceleration_limits: true\n    max_acceleration: 1.0"
            };
            ok += &format!("  panda_joint{j}:\n    {body}\n");
        }
        let robot = Robot::panda().unwrap().with_limits_yaml(&ok).unwrap();
        assert_eq!(robot.limits()[1].acceleration, None);
        assert_eq!(robot.limits()[0].acceleration, Some(1.0));
        assert_eq!(robot.limits()[0].jerk, None);
    }
}
