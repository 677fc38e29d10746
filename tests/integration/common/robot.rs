//! The robot the tests use (the shipped Panda), configurations inside its
//! joint limits, and its mesh links' hulls.

use dpmp::robot::hull::ConvexHull;
use dpmp::robot::{Robot, ShapeGeometry};

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
