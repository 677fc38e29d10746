//! [`PlanRequest`]: every input of `/v1/plan` and `dpmp plan` (image, box,
//! mask flag, depth, camera, target position, standoff, approach and the
//! optimiser's [`Task`]), checked together once by its constructor, so the
//! HTTP route and the CLI cannot drift apart. [`PlanFields`] names the
//! fields as each interface spells them.

use super::world::{WorldSource, SENSED_OBSTACLE_ID};
use crate::net::Model;
use crate::optim::{GoalApproach, Task};
use crate::perception::{CameraModel, DepthImage};
use crate::{Error, Result};
use image::DynamicImage;
use nalgebra::Isometry3;

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

/// Largest accepted goal standoff (m).
pub const MAX_GOAL_STANDOFF_M: f64 = 0.5;

/// The names of a plan request's fields in one interface: what its errors
/// call them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlanFields {
    /// The colour image (`image_base64`, the multipart part `image`, `--image`).
    pub image: String,
    /// The target box.
    pub target_box: String,
    /// The aligned depth image.
    pub depth: String,
    /// Metres per depth unit.
    pub depth_scale: String,
    /// The client's 3-D target.
    pub target_position: String,
    /// The goal (an explicit one, or the approach of a derived one).
    pub goal: String,
    /// The derived goal's standoff.
    pub goal_standoff: String,
    /// The approach direction of a derived goal.
    pub approach: String,
    /// The camera that took the images.
    pub camera: String,
    /// Where the world comes from besides the posted obstacles.
    pub world: String,
}

impl PlanFields {
    /// `/v1/plan`'s JSON body.
    pub fn json() -> PlanFields {
        PlanFields {
            image: "image_base64".into(),
            target_box: "target_box".into(),
            depth: "depth_base64".into(),
            depth_scale: "depth_scale_m".into(),
            target_position: "target_position".into(),
            goal: "goal".into(),
            goal_standoff: "goal_standoff_m".into(),
            approach: "goal.position".into(),
            camera: "camera".into(),
            world: "world".into(),
        }
    }

    /// `/v1/plan`'s multipart form: the images are the parts `image` and
    /// `depth`, the rest the JSON part's fields.
    pub fn multipart() -> PlanFields {
        PlanFields {
            image: "image".into(),
            depth: "depth".into(),
            ..PlanFields::json()
        }
    }

    /// `dpmp plan`'s flags.
    pub fn flags() -> PlanFields {
        PlanFields {
            image: "--image".into(),
            target_box: "--box".into(),
            depth: "--depth".into(),
            depth_scale: "--depth-scale".into(),
            target_position: "--target-position".into(),
            goal: "--goal".into(),
            goal_standoff: "--goal-standoff".into(),
            approach: "--approach-axis".into(),
            camera: "--camera".into(),
            world: "--world".into(),
        }
    }
}

/// The inputs of a plan request as an interface reads them, before the
/// checks that involve more than one of them ([`PlanRequest::new`]).
#[derive(Clone, Debug)]
pub struct PlanParts {
    /// The decoded colour image.
    pub image: DynamicImage,
    /// Target berry box `[x1, y1, x2, y2]` in image pixels.
    pub target_box: [f64; 4],
    /// Whether the image already has the target painted (masked).
    pub mask_applied: bool,
    /// The aligned depth image, decoded.
    pub depth: Option<DepthImage>,
    /// The depth scale, when the client gave one (the depth image is
    /// decoded with it; it applies only to a depth image).
    pub depth_scale_m: Option<f64>,
    /// The client's own berry centre (m, base frame), instead of depth.
    pub target_position: Option<[f64; 3]>,
    /// Standoff of the derived goal (m); `None`: the default.
    pub goal_standoff_m: Option<f64>,
    /// An approach direction for the derived goal.
    pub approach: Option<GoalApproach>,
    /// The camera that took the images, when not the model's.
    pub camera: Option<CameraModel>,
    /// The camera's optical frame in the robot's base frame, when the
    /// images were not taken by the hand camera at the home configuration.
    pub camera_pose: Option<Isometry3<f64>>,
    /// Where the world comes from besides the posted obstacles.
    pub world: WorldSource,
    /// What to plan besides the prior (scene, limits, start, goal, options).
    pub task: Task,
}

impl PlanParts {
    /// The parts of a plan from `image` alone: the box, the task, and
    /// nothing else (no mask, depth, 3-D target, camera or sensed world);
    /// set the other fields with struct update syntax.
    pub fn new(image: DynamicImage, target_box: [f64; 4], task: Task) -> PlanParts {
        PlanParts {
            image,
            target_box,
            mask_applied: false,
            depth: None,
            depth_scale_m: None,
            target_position: None,
            goal_standoff_m: None,
            approach: None,
            camera: None,
            camera_pose: None,
            world: WorldSource::None,
            task,
        }
    }
}

/// A validated plan request (only [`PlanRequest::new`] makes one).
#[derive(Clone, Debug)]
pub struct PlanRequest {
    pub(super) image: DynamicImage,
    pub(super) image_field: String,
    pub(super) target_box: [f64; 4],
    pub(super) mask_applied: bool,
    pub(super) target: TargetInput,
    pub(super) goal_standoff_m: Option<f64>,
    pub(super) approach: Option<GoalApproach>,
    pub(super) camera: Option<CameraModel>,
    pub(super) camera_pose: Option<Isometry3<f64>>,
    pub(super) world: WorldSource,
    pub(super) world_field: String,
    /// The field a 3-D target comes from, named when it is out of reach:
    /// the target position, the depth image, or its scale when the client
    /// set one.
    pub(super) target_field: String,
    /// How the interface the request came through names its inputs.
    pub(super) names: PlanFields,
    pub(super) task: Task,
}

impl PlanRequest {
    /// Check the parts together; errors name the field as `fields` spells
    /// it: the box inside the image, depth or a target position (not both),
    /// the depth aligned with the image and its scale only with it, the
    /// target position within 5 m, the standoff and the approach only with
    /// a 3-D target (and no explicit goal beside a derived one), the camera.
    /// The camera's image size is checked against the model's camera when
    /// planning ([`super::predict_and_optimize`]), where the model is known.
    pub fn new(parts: PlanParts, fields: &PlanFields) -> Result<PlanRequest> {
        let (width, height) = (parts.image.width(), parts.image.height());
        check_target_box(&parts.target_box, width, height, &fields.target_box)?;
        let target = match (parts.depth, parts.target_position) {
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    &fields.target_position,
                    "send either a depth image or a target position, not both",
                ))
            }
            (Some(depth), None) => {
                check_aligned(&depth, width, height, fields)?;
                TargetInput::Depth(depth, fields.depth.clone())
            }
            (None, Some(p)) => {
                check_target_position(&p, &fields.target_position)?;
                TargetInput::Position(p)
            }
            (None, None) => TargetInput::None,
        };
        if parts.depth_scale_m.is_some() && !matches!(target, TargetInput::Depth(..)) {
            return Err(Error::invalid(
                &fields.depth_scale,
                "applies only with a depth image",
            ));
        }
        check_standoff(parts.goal_standoff_m, &target, &fields.goal_standoff)?;
        let derived_goal = !matches!(target, TargetInput::None);
        if derived_goal && parts.task.goal.is_some() {
            return Err(Error::invalid(
                &fields.goal,
                "a goal is derived from the depth / target_position; send one or the other",
            ));
        }
        if parts.approach.is_some() && !derived_goal {
            return Err(Error::invalid(
                &fields.approach,
                "an approach direction needs a goal: send goal.position, a depth image or a target position",
            ));
        }
        if parts.world == WorldSource::Depth && !matches!(target, TargetInput::Depth(..)) {
            return Err(Error::invalid(
                &fields.world,
                format!(
                    "\"depth\" senses the world from the depth image: send {}",
                    fields.depth
                ),
            ));
        }
        if parts.world == WorldSource::Depth
            && parts
                .task
                .obstacles
                .iter()
                .any(|o| o.id == SENSED_OBSTACLE_ID)
        {
            return Err(Error::invalid(
                &fields.world,
                format!("the sensed cloud is the obstacle {SENSED_OBSTACLE_ID:?}: rename the posted one"),
            ));
        }
        if let Some(camera) = &parts.camera {
            camera.validate(&fields.camera)?;
        }
        let target_field = match (&target, parts.depth_scale_m) {
            (TargetInput::Depth(..), Some(_)) => fields.depth_scale.clone(),
            (TargetInput::Depth(..), None) => fields.depth.clone(),
            _ => fields.target_position.clone(),
        };
        Ok(PlanRequest {
            image: parts.image,
            image_field: fields.image.clone(),
            target_box: parts.target_box,
            mask_applied: parts.mask_applied,
            target,
            goal_standoff_m: parts.goal_standoff_m,
            approach: parts.approach,
            camera: parts.camera,
            camera_pose: parts.camera_pose,
            world: parts.world,
            world_field: fields.world.clone(),
            target_field,
            names: fields.clone(),
            task: parts.task,
        })
    }

    /// What to plan besides the prior.
    pub fn task(&self) -> &Task {
        &self.task
    }

    /// The 3-D target, if any.
    pub fn target(&self) -> &TargetInput {
        &self.target
    }

    /// The colour image.
    pub fn image(&self) -> &DynamicImage {
        &self.image
    }

    /// The images' size must be the camera's when depth is back-projected
    /// (the request's camera, else `model`'s).
    pub(super) fn check_camera_size(&self, model: &Model) -> Result<()> {
        if !matches!(self.target, TargetInput::Depth(..)) {
            return Ok(());
        }
        let (w, h) = (self.image.width(), self.image.height());
        check_camera_size(model, self.camera.as_ref(), w, h, &self.image_field)
    }
}

/// The depth image must be aligned with the colour image (same camera, same
/// size); the error names the colour image, which is the one usually
/// resized.
fn check_aligned(depth: &DepthImage, width: u32, height: u32, fields: &PlanFields) -> Result<()> {
    if (depth.width(), depth.height()) == (width, height) {
        return Ok(());
    }
    Err(Error::invalid(
        &fields.image,
        format!(
            "the colour image is {width}x{height}, the depth image ({}) {}x{}: they must be aligned, from the same camera at the same size",
            fields.depth,
            depth.width(),
            depth.height()
        ),
    ))
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
fn check_camera_size(
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

/// Validate a client's target position (errors name `field`).
pub fn check_target_position(p: &[f64; 3], field: &str) -> Result<()> {
    crate::error::ensure_finite(field, p)?;
    if p.iter().any(|c| c.abs() > 5.0) {
        return Err(Error::invalid(
            field,
            format!("{p:?} is more than 5 m from the robot base"),
        ));
    }
    Ok(())
}

/// A goal standoff needs a 3-D target to stand off from, and stays within
/// [`MAX_GOAL_STANDOFF_M`]; `field` names the standoff in errors.
fn check_standoff(standoff: Option<f64>, target: &TargetInput, field: &str) -> Result<()> {
    let Some(standoff) = standoff else {
        return Ok(());
    };
    if matches!(target, TargetInput::None) {
        return Err(Error::invalid(
            field,
            "applies only with a depth image or a target position",
        ));
    }
    crate::error::ensure_in_range(field, standoff, 0.0, MAX_GOAL_STANDOFF_M)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::Goal;

    fn parts() -> PlanParts {
        PlanParts::new(
            DynamicImage::new_rgb8(64, 48),
            [10.0, 10.0, 20.0, 20.0],
            Task::default(),
        )
    }

    fn depth(w: u32, h: u32) -> DepthImage {
        DepthImage::new(w, h, 0.001, vec![400; (w * h) as usize], "d").unwrap()
    }

    /// The field `parts` is refused for, in the JSON and the flag names.
    fn refused(parts: PlanParts) -> (String, String) {
        let field = |names: &PlanFields| match PlanRequest::new(parts.clone(), names) {
            Err(Error::Invalid { field, .. }) => field,
            other => panic!("expected a refusal, got {other:?}"),
        };
        (field(&PlanFields::json()), field(&PlanFields::flags()))
    }

    #[test]
    fn every_check_across_inputs_names_the_field_in_each_interface() {
        let position = Some([0.5, 0.0, 0.4]);
        let cases: Vec<(PlanParts, (&str, &str))> = vec![
            (
                PlanParts {
                    target_box: [10.0, 10.0, 65.0, 20.0],
                    ..parts()
                },
                ("target_box", "--box"),
            ),
            (
                PlanParts {
                    depth: Some(depth(64, 48)),
                    target_position: position,
                    ..parts()
                },
                ("target_position", "--target-position"),
            ),
            (
                PlanParts {
                    depth_scale_m: Some(0.001),
                    target_position: position,
                    ..parts()
                },
                ("depth_scale_m", "--depth-scale"),
            ),
            (
                PlanParts {
                    depth: Some(depth(32, 24)),
                    ..parts()
                },
                ("image_base64", "--image"),
            ),
            (
                PlanParts {
                    target_position: Some([9.0, 0.0, 0.0]),
                    ..parts()
                },
                ("target_position", "--target-position"),
            ),
            (
                PlanParts {
                    goal_standoff_m: Some(0.1),
                    ..parts()
                },
                ("goal_standoff_m", "--goal-standoff"),
            ),
            (
                PlanParts {
                    goal_standoff_m: Some(MAX_GOAL_STANDOFF_M + 0.1),
                    target_position: position,
                    ..parts()
                },
                ("goal_standoff_m", "--goal-standoff"),
            ),
            (
                PlanParts {
                    target_position: position,
                    task: Task {
                        goal: Some(Goal::at([0.5, 0.0, 0.3], 0.01)),
                        ..Task::default()
                    },
                    ..parts()
                },
                ("goal", "--goal"),
            ),
            (
                PlanParts {
                    approach: Some(GoalApproach {
                        approach_axis: [0.0, 0.0, 1.0],
                        approach_tolerance_rad: 0.2,
                    }),
                    ..parts()
                },
                ("goal.position", "--approach-axis"),
            ),
            (
                PlanParts {
                    world: WorldSource::Depth,
                    target_position: position,
                    ..parts()
                },
                ("world", "--world"),
            ),
        ];
        for (i, (p, (json, flag))) in cases.into_iter().enumerate() {
            assert_eq!(refused(p), (json.to_string(), flag.to_string()), "case {i}");
        }
    }

    #[test]
    fn a_consistent_request_keeps_its_target() {
        let ok = PlanRequest::new(
            PlanParts {
                depth: Some(depth(64, 48)),
                depth_scale_m: Some(0.001),
                goal_standoff_m: Some(0.08),
                ..parts()
            },
            &PlanFields::multipart(),
        )
        .unwrap();
        assert!(matches!(ok.target(), TargetInput::Depth(_, f) if f == "depth"));
        let plain = PlanRequest::new(parts(), &PlanFields::json()).unwrap();
        assert!(matches!(plain.target(), TargetInput::None));
        assert_eq!(plain.task().clearance_m, Task::default().clearance_m);
    }
}
