//! One target's plan from matched messages: the messages become the
//! [`PlanParts`] `/v1/plan` makes from its body, validated into a
//! [`PlanRequest`] with the topics as field names, and planned by the one
//! pipeline ([`crate::plan::predict_and_optimize`]).

use super::config::NodeSettings;
use super::convert::{camera_model, colour_image, depth_image, start_configuration, target_box};
use super::inputs::Matched;
use super::msg::{RegionOfInterest, TransformStamped};
use crate::net::Model;
use crate::optim::report::TrajectoryFormat;
use crate::plan::{PlanFields, PlanParts, PlanRequest};
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// Farthest a camera may be from the robot's base (m).
const MAX_CAMERA_DISTANCE_M: f64 = 5.0;

/// The plan request's field names: the topics.
fn fields() -> PlanFields {
    PlanFields {
        image: "color".into(),
        target_box: "target".into(),
        depth: "depth".into(),
        depth_scale: "depth".into(),
        target_position: "target".into(),
        goal: "plan.goal".into(),
        goal_standoff: "plan.goal_standoff_m".into(),
        approach: "plan.goal".into(),
        camera: "camera_info".into(),
        world: "plan.world".into(),
    }
}

/// The plan request for `roi` from `matched` inputs and the node's
/// settings: the colour and depth images, the camera info's intrinsics on
/// the model's mount, the joint state as the start, the camera pose if
/// one came.
pub fn plan_request(
    matched: &Matched,
    roi: &RegionOfInterest,
    settings: &NodeSettings,
    model: &Model,
    robot: &Robot,
) -> Result<PlanRequest> {
    let max_pixels = settings.max_image_pixels;
    let image = colour_image(&matched.color, "color", max_pixels)?;
    let depth = depth_image(&matched.depth, "depth", max_pixels)?;
    let camera = match &matched.camera_info {
        Some(info) => {
            if (info.width, info.height) != (image.width(), image.height()) {
                return Err(Error::invalid(
                    "camera_info.width",
                    format!(
                        "{}x{} is not the colour image's {}x{}",
                        info.width,
                        info.height,
                        image.width(),
                        image.height()
                    ),
                ));
            }
            Some(camera_model(
                info,
                "camera_info",
                &model.config().camera_model(),
            )?)
        }
        None => None,
    };
    let camera_pose = matched
        .camera_pose
        .as_ref()
        .map(|tf| camera_pose(tf, "camera_pose"))
        .transpose()?;
    let mut task = settings.plan.task.clone();
    task.start = Some(start_configuration(
        &matched.joint_state,
        "joint_states",
        robot.joint_names(),
    )?);
    task.trajectory_format = TrajectoryFormat::Ros2;
    let parts = PlanParts {
        mask_applied: settings.plan.mask_applied,
        depth: Some(depth),
        goal_standoff_m: settings.plan.goal_standoff_m,
        approach: settings.plan.goal.clone(),
        camera,
        camera_pose,
        world: settings.plan.world,
        ..PlanParts::new(image, target_box(roi), task)
    };
    PlanRequest::new(parts, &fields())
}

/// The camera's optical frame (x right, y down, z forward: REP 103's
/// `_optical_frame`) in the robot's base frame, from a transform whose
/// parent is the base frame: finite, within 5 m of the base, a unit
/// quaternion (within 1e-3).
pub fn camera_pose(tf: &TransformStamped, field: &str) -> Result<Isometry3<f64>> {
    let t = &tf.transform.translation;
    let q = &tf.transform.rotation;
    crate::error::ensure_finite(
        &format!("{field}.transform"),
        &[t.x, t.y, t.z, q.x, q.y, q.z, q.w],
    )?;
    let distance = (t.x * t.x + t.y * t.y + t.z * t.z).sqrt();
    if distance > MAX_CAMERA_DISTANCE_M {
        return Err(Error::invalid(
            format!("{field}.transform.translation"),
            format!("{distance:.3} m from the base; at most {MAX_CAMERA_DISTANCE_M} m"),
        ));
    }
    let quaternion = Quaternion::new(q.w, q.x, q.y, q.z);
    if (quaternion.norm() - 1.0).abs() > 1e-3 {
        return Err(Error::invalid(
            format!("{field}.transform.rotation"),
            format!("norm {:.6}, expected a unit quaternion", quaternion.norm()),
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t.x, t.y, t.z),
        UnitQuaternion::from_quaternion(quaternion),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros2::msg::{Quaternion as Q, Transform, Vector3};

    #[test]
    fn a_camera_pose_is_checked_and_kept() {
        let (s, c) = (0.5f64.sqrt(), 0.5f64.sqrt());
        let mut tf = TransformStamped {
            transform: Transform {
                translation: Vector3 {
                    x: 0.4,
                    y: -0.1,
                    z: 0.7,
                },
                rotation: Q {
                    x: s,
                    y: 0.0,
                    z: 0.0,
                    w: c,
                },
            },
            ..TransformStamped::default()
        };
        let pose = camera_pose(&tf, "camera_pose").unwrap();
        // 90° about x: the optical axis (z) points along -y.
        let z = pose.rotation * nalgebra::Vector3::z();
        assert!(
            (z - nalgebra::Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12,
            "{z}"
        );
        assert_eq!(
            pose.translation.vector,
            nalgebra::Vector3::new(0.4, -0.1, 0.7)
        );
        tf.transform.rotation.w = 2.0;
        assert_eq!(
            camera_pose(&tf, "camera_pose").unwrap_err().field(),
            Some("camera_pose.transform.rotation")
        );
        tf.transform.rotation.w = c;
        tf.transform.translation.x = 9.0;
        assert_eq!(
            camera_pose(&tf, "camera_pose").unwrap_err().field(),
            Some("camera_pose.transform.translation")
        );
        tf.transform.translation.x = f64::NAN;
        assert!(camera_pose(&tf, "camera_pose")
            .unwrap_err()
            .field()
            .unwrap()
            .starts_with("camera_pose.transform"));
    }
}
