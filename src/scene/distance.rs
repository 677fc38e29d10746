//! Signed distance between one robot primitive and one obstacle part, with
//! witness points and normal, from parry3d's `query::contact` (GJK when
//! apart, EPA when penetrating).

use super::shape::{from_glam, parry_pose_relative, Part, RobotPart};
use nalgebra::Vector3;

/// Signed distance and witness points of one robot/obstacle pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairContact {
    /// Signed distance (m), negative when penetrating.
    pub distance: f64,
    /// Witness point on the robot primitive (base frame).
    pub point_robot: Vector3<f64>,
    /// Witness point on the obstacle (base frame).
    pub point_obstacle: Vector3<f64>,
    /// Unit normal from the obstacle towards the robot.
    pub normal: Vector3<f64>,
}

/// Signed distance between `robot` and `part` when below `prediction` (m);
/// `None` when they are further apart. Both shapes are placed relative to
/// the robot primitive's origin so that parry's `f32` arithmetic only sees
/// small coordinates.
pub fn pair_contact(robot: &RobotPart, part: &Part, prediction: f64) -> Option<PairContact> {
    let (shape, pose) = robot.shape_and_pose();
    let origin = pose.translation.vector;
    let pos1 = parry_pose_relative(pose, &origin);
    let pos2 = parry_pose_relative(&part.pose, &origin);
    let contact = parry3d::query::contact(
        &pos1,
        shape,
        &pos2,
        part.shape.as_ref(),
        prediction.max(0.0) as f32,
    )
    .ok()??;
    let normal = -from_glam(contact.normal1);
    Some(PairContact {
        distance: contact.dist as f64,
        point_robot: from_glam(contact.point1) + origin,
        point_obstacle: from_glam(contact.point2) + origin,
        normal: normal.try_normalize(1e-12).unwrap_or_else(Vector3::z),
    })
}

/// Distance from `p` to the part (0 inside).
pub fn point_distance(part: &Part, p: &Vector3<f64>) -> f64 {
    let origin = part.pose.translation.vector;
    let pose = parry_pose_relative(&part.pose, &origin);
    part.shape
        .distance_to_point(&pose, super::shape::to_glam(&(p - origin)), true) as f64
}

/// Signed distance from `p` to the part's surface (negative inside).
pub fn point_signed_distance(part: &Part, p: &Vector3<f64>) -> f64 {
    let origin = part.pose.translation.vector;
    let pose = parry_pose_relative(&part.pose, &origin);
    part.shape
        .distance_to_point(&pose, super::shape::to_glam(&(p - origin)), false) as f64
}
