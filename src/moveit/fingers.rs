//! The Panda's finger joints in a MoveIt start state → the fingers'
//! collision geometry where the state puts them.
//!
//! franka_description drives each finger with a prismatic joint
//! (`panda_finger_joint1` moves `panda_leftfinger`, `panda_finger_joint2`
//! moves `panda_rightfinger` and mimics the first), 0 to 0.04 m along the
//! finger's own y axis from the hand's middle plane. The shipped URDF fixes
//! both fully open (0.04 m) as side links of the hand; a start state that
//! gives the joints moves those side links there
//! ([`Robot::with_side_link_moved`]), a value outside the limits clamped to
//! them with a warning, so the planned motion keeps its clearance with the
//! fingers where they are. The fingers do not move during the motion.

use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::Vector3;
use std::borrow::Cow;

/// A MoveIt finger joint and the side link of the shipped URDF it moves.
#[derive(Clone, Copy, Debug)]
pub struct FingerJoint {
    /// The joint's name in MoveIt (franka_description).
    pub joint: &'static str,
    /// The finger link it moves.
    pub link: &'static str,
}

/// The Panda's finger joints; the second mimics the first when a state
/// gives only the first.
pub const PANDA_FINGER_JOINTS: [FingerJoint; 2] = [
    FingerJoint {
        joint: "panda_finger_joint1",
        link: "panda_leftfinger",
    },
    FingerJoint {
        joint: "panda_finger_joint2",
        link: "panda_rightfinger",
    },
];

/// franka_description's limits of each finger joint (m).
pub const PANDA_FINGER_LIMITS_M: [f64; 2] = [0.0, 0.04];

/// Where a start state puts one finger.
#[derive(Clone, Debug, PartialEq)]
pub struct FingerPose {
    /// The finger's link.
    pub link: String,
    /// Its opening (m): its frame's distance from the hand's middle plane
    /// along its own y axis, within [`PANDA_FINGER_LIMITS_M`].
    pub opening_m: f64,
}

/// The finger poses of a joint state (`names`, `positions`, read at
/// `field`) for `robot`: one per finger joint given whose link the robot
/// has, clamped to [`PANDA_FINGER_LIMITS_M`] with a warning. Also returns
/// the names of the joints used, so the caller does not report them unused.
pub fn finger_poses(
    field: &str,
    names: &[String],
    positions: &[f64],
    robot: &Robot,
    warnings: &mut Vec<String>,
) -> Result<(Vec<FingerPose>, Vec<String>)> {
    let value_of = |joint: &str| names.iter().position(|n| n == joint);
    let first = value_of(PANDA_FINGER_JOINTS[0].joint);
    let mut poses = Vec::new();
    let mut used = Vec::new();
    for finger in PANDA_FINGER_JOINTS {
        let Some(i) = value_of(finger.joint).or(first) else {
            continue;
        };
        if robot.side_link(finger.link).is_none() {
            continue;
        }
        let Some(&value) = positions.get(i) else {
            continue;
        };
        if !value.is_finite() {
            return Err(Error::invalid(
                format!("{field}.position[{i}]"),
                format!("{} must be finite, got {value}", names[i]),
            ));
        }
        let [lower, upper] = PANDA_FINGER_LIMITS_M;
        let opening_m = value.clamp(lower, upper);
        if opening_m != value {
            warnings.push(format!(
                "{} = {value} is outside its limits [{lower}, {upper}]: the finger is placed at {opening_m}",
                names[i]
            ));
        }
        used.push(finger.joint.to_string());
        poses.push(FingerPose {
            link: finger.link.to_string(),
            opening_m,
        });
    }
    Ok((poses, used))
}

/// `robot` with its fingers at `poses` (borrowed unchanged when they are
/// already there).
pub fn robot_with_fingers<'r>(robot: &'r Robot, poses: &[FingerPose]) -> Result<Cow<'r, Robot>> {
    let mut posed = Cow::Borrowed(robot);
    for pose in poses {
        let Some(side) = posed.side_link(&pose.link) else {
            continue;
        };
        let delta = pose.opening_m - side.offset_along(&Vector3::y());
        if delta.abs() > 1e-12 {
            posed = Cow::Owned(posed.with_side_link_moved(&pose.link, &(delta * Vector3::y()))?);
        }
    }
    Ok(posed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn finger_joints_are_read_clamped_and_mimicked() {
        let panda = Robot::panda().unwrap();
        let mut warnings = Vec::new();
        let (poses, used) = finger_poses(
            "s",
            &names(&["panda_finger_joint1", "panda_finger_joint2"]),
            &[0.065, 0.01],
            &panda,
            &mut warnings,
        )
        .unwrap();
        assert_eq!(poses[0].opening_m, 0.04);
        assert_eq!(poses[1].opening_m, 0.01);
        assert_eq!(used.len(), 2);
        assert!(
            warnings[0].contains("panda_finger_joint1 = 0.065"),
            "{warnings:?}"
        );
        let (poses, _) = finger_poses(
            "s",
            &names(&["panda_finger_joint1"]),
            &[0.02],
            &panda,
            &mut warnings,
        )
        .unwrap();
        assert_eq!(
            poses.iter().map(|p| p.opening_m).collect::<Vec<_>>(),
            [0.02, 0.02]
        );
        let e = finger_poses(
            "s",
            &names(&["a", "panda_finger_joint1"]),
            &[0.0, f64::NAN],
            &panda,
            &mut warnings,
        )
        .unwrap_err();
        assert!(e.to_string().contains("s.position[1]"), "{e}");
    }

    #[test]
    fn fingers_already_there_borrow_the_robot() {
        let panda = Robot::panda().unwrap();
        let open = |opening_m| {
            PANDA_FINGER_JOINTS.map(|f| FingerPose {
                link: f.link.to_string(),
                opening_m,
            })
        };
        assert!(matches!(
            robot_with_fingers(&panda, &open(0.04)).unwrap(),
            Cow::Borrowed(_)
        ));
        let closed = robot_with_fingers(&panda, &open(0.0)).unwrap();
        for f in PANDA_FINGER_JOINTS {
            let side = closed.side_link(f.link).unwrap();
            assert!(side.offset_along(&Vector3::y()).abs() < 1e-12);
        }
    }
}
