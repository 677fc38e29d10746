//! The robot the tests use (the shipped Panda), configurations inside its
//! joint limits, and its mesh links' hulls.

use dpmp::robot::hull::ConvexHull;
use dpmp::robot::{Robot, ShapeGeometry};
use nalgebra::Isometry3;
use serde_json::Value;

/// The shipped Panda.
pub fn panda() -> Robot {
    Robot::panda().unwrap()
}

/// A configuration inside `robot`'s limits from unit-interval fractions:
/// `lower + f (upper - lower)` per joint.
pub fn at_fractions(robot: &Robot, fractions: &[f64]) -> Vec<f64> {
    robot
        .limits()
        .iter()
        .zip(fractions)
        .map(|(l, f)| l.lower + f * (l.upper - l.lower))
        .collect()
}

/// The TCP pose at the last point of a JSON answer's `trajectory`.
pub fn final_tcp_pose(robot: &Robot, answer: &Value) -> Isometry3<f64> {
    let last = answer["trajectory"]["points"]
        .as_array()
        .and_then(|points| points.last())
        .unwrap_or_else(|| panic!("no trajectory points in {answer}"));
    robot.tcp_pose(&crate::common::json::numbers(&last["positions"]))
}

/// Every mesh link of `robot`: (link index, hull in the link frame).
pub fn mesh_hulls(robot: &Robot) -> Vec<(usize, ConvexHull)> {
    robot
        .collision_shapes()
        .iter()
        .filter_map(|s| match &s.geometry {
            ShapeGeometry::Convex(h) => Some((s.link, h.clone())),
            _ => None,
        })
        .collect()
}
