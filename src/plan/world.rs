//! The world a plan is made against, besides the posted obstacles: with
//! `world: "depth"` the aligned depth image becomes a `points` obstacle
//! ([`sensed_world`]) and the answer reports what went into it
//! ([`WorldReport`]). [`sensed_cloud`] is that cloud on its own, for a
//! target located with [`TargetKeepOut::locate`] (the pictures of
//! `dpmp data preview` use it).
//!
//! **From depth to obstacle.** The depth image is back-projected through
//! the camera that took it (posed at the robot's home configuration), cut
//! at [`crate::perception::cloud::DEFAULT_MAX_RANGE_M`], and downsampled to one point per
//! [`DEFAULT_VOXEL_M`] voxel ([`crate::perception::cloud`]). The target
//! berry is kept out of it (the gripper must reach it): the pixels of its
//! box, and every point within the berry's radius (from the box size at
//! its depth) plus [`TARGET_KEEP_OUT_MARGIN_M`] of the located centre.
//! Each point stands for the surface within its voxel and carries the
//! depth noise, so its ball has the radius
//! `voxel · √3 / 2 + NOISE_SIGMAS · σ(z_max)`, with the stereo noise model
//! `σ(z) = DEPTH_RMS_PER_M2 · z²` at the deepest point kept.
//!
//! **What it cannot hold.** A depth camera sees surfaces facing it: the far
//! side of a berry or leaf, whatever hides behind a nearer surface, and
//! everything outside the view are not in the cloud. The planner keeps
//! clear of what was seen, not of what was not; the report says so
//! ([`UNSEEN_NOTE`]).

use crate::perception::cloud::{depth_cloud, CloudSettings, KeepOut, SensedCloud, DEFAULT_VOXEL_M};
use crate::perception::{locate_target, Camera, DepthImage};
use crate::scene::obstacle::MAX_CLOUD_POINTS;
use crate::scene::{Obstacle, ObstacleShape};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// Where the planner's world comes from besides the posted obstacles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WorldSource {
    /// Only the posted obstacles (the default).
    #[default]
    None,
    /// The posted obstacles and the cloud the depth image sees.
    Depth,
}

impl WorldSource {
    /// Parse a flag or field value (`none` or `depth`).
    pub fn parse(value: &str, field: &str) -> Result<WorldSource> {
        match value {
            "none" => Ok(WorldSource::None),
            "depth" => Ok(WorldSource::Depth),
            other => Err(Error::invalid(
                field,
                format!("unknown world {other:?}: expected \"none\" or \"depth\""),
            )),
        }
    }
}

/// Id of the obstacle the sensed cloud becomes.
pub const SENSED_OBSTACLE_ID: &str = "sensed-depth";

/// Margin (m) beyond the berry's radius kept clear around the target's
/// centre, so that the berry's own returns (its rim, its calyx) are not
/// obstacles.
pub const TARGET_KEEP_OUT_MARGIN_M: f64 = 0.015;

/// Range-noise coefficient of the depth camera (1/m): `σ(z) = k · z²`,
/// about 0.8 mm at 0.45 m (a RealSense D435-class stereo camera; the
/// synthetic generator's default).
pub const DEPTH_RMS_PER_M2: f64 = 0.004;

/// Standard deviations of depth noise added to each point's ball.
pub const NOISE_SIGMAS: f64 = 2.0;

/// What the answer says the sensed cloud cannot hold.
pub const UNSEEN_NOTE: &str = "only surfaces the camera saw are obstacles: the far side of \
objects, whatever is hidden behind nearer surfaces and everything outside the view are not";

/// What went into the sensed world (`world` in the plan answer).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WorldReport {
    /// `"depth"`.
    pub source: WorldSource,
    /// Points in the obstacle (one per occupied voxel).
    pub points: usize,
    /// Pixels with a depth return.
    pub returns: usize,
    /// Returns beyond the range, dropped.
    pub out_of_range: usize,
    /// Returns removed as the target berry (its box and the ball around it).
    pub removed_as_target: usize,
    /// Voxel edge (m).
    pub voxel_m: f64,
    /// Range cut (m along the optical axis).
    pub max_range_m: f64,
    /// Radius of each point's ball (m).
    pub radius_m: f64,
    /// Radius (m) kept clear around the target's centre.
    pub target_keep_out_m: f64,
    /// What the cloud does not hold ([`UNSEEN_NOTE`]).
    pub note: &'static str,
}

/// The located target the cloud keeps out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetKeepOut {
    /// The target box (px).
    pub target_box: [f64; 4],
    /// The berry centre (m, base frame).
    pub center: [f64; 3],
    /// Its depth along the optical axis (m).
    pub depth_m: f64,
}

impl TargetKeepOut {
    /// The berry behind `target_box` of `depth`, located the way a plan
    /// with a depth image locates it ([`locate_target`] through `camera`,
    /// posed where the image was taken: [`Camera::at_home`]); errors name
    /// `field` (the depth input).
    pub fn locate(
        depth: &DepthImage,
        target_box: [f64; 4],
        camera: &Camera,
        field: &str,
    ) -> Result<TargetKeepOut> {
        let t = locate_target(depth, &target_box, camera, field)?;
        Ok(TargetKeepOut {
            target_box,
            center: t.position,
            depth_m: t.depth_m,
        })
    }

    /// What the cloud leaves out for this target seen by `camera`: the
    /// pixels of its box and the ball of the berry's radius (from the box
    /// at its depth) plus [`TARGET_KEEP_OUT_MARGIN_M`] around its centre.
    pub fn keep_out(&self, camera: &Camera) -> KeepOut {
        KeepOut {
            target_box: self.target_box,
            center: self.center,
            radius_m: target_radius_m(camera, self) + TARGET_KEEP_OUT_MARGIN_M,
        }
    }
}

/// The cloud `world: "depth"` senses, before it becomes the
/// [`SENSED_OBSTACLE_ID`] obstacle: `depth` seen by `camera` (posed where
/// it was taken, [`Camera::at_home`]) at the default [`CloudSettings`],
/// with `keep`'s target left out ([`TargetKeepOut::keep_out`]). No size
/// cap is applied (a plan refuses a cloud above [`MAX_CLOUD_POINTS`]).
pub fn sensed_cloud(depth: &DepthImage, camera: &Camera, keep: &TargetKeepOut) -> SensedCloud {
    let keep_out = keep.keep_out(camera);
    depth_cloud(depth, camera, &CloudSettings::default(), Some(&keep_out))
}

/// The sensed obstacle (none when nothing was seen) and its report, from
/// the request's depth image seen by `camera`.
pub(super) fn sensed_world(
    depth: &DepthImage,
    camera: &Camera,
    keep: &TargetKeepOut,
    field: &str,
) -> Result<(Option<Obstacle>, WorldReport)> {
    let settings = CloudSettings::default();
    let keep_out = keep.keep_out(camera);
    let cloud = sensed_cloud(depth, camera, keep);
    check_cloud_size(&cloud, depth, field)?;
    let radius_m = point_radius_m(&settings, cloud.max_depth_m);
    let report = WorldReport {
        source: WorldSource::Depth,
        points: cloud.points.len(),
        returns: cloud.returns,
        out_of_range: cloud.out_of_range,
        removed_as_target: cloud.removed_as_target,
        voxel_m: settings.voxel_m,
        max_range_m: settings.max_range_m,
        radius_m,
        target_keep_out_m: keep_out.radius_m,
        note: UNSEEN_NOTE,
    };
    let obstacle = (!cloud.points.is_empty()).then(|| Obstacle {
        id: SENSED_OBSTACLE_ID.to_string(),
        shape: ObstacleShape::Points {
            points: cloud.points,
            radius: radius_m,
        },
    });
    Ok((obstacle, report))
}

/// The berry's radius (m) from its box: half the box's larger side at the
/// berry's depth.
fn target_radius_m(camera: &Camera, keep: &TargetKeepOut) -> f64 {
    let b = &keep.target_box;
    let k = &camera.intrinsics;
    let half_px = 0.5 * (b[2] - b[0]).max(b[3] - b[1]);
    half_px * keep.depth_m / k.fx.min(k.fy)
}

/// The ball radius of a cloud whose deepest point is `max_depth_m` deep.
pub fn point_radius_m(settings: &CloudSettings, max_depth_m: f64) -> f64 {
    settings.voxel_m * 3f64.sqrt() / 2.0 + NOISE_SIGMAS * DEPTH_RMS_PER_M2 * max_depth_m.powi(2)
}

/// A cloud beyond the per-obstacle cap is refused, naming the depth image.
fn check_cloud_size(cloud: &SensedCloud, depth: &DepthImage, field: &str) -> Result<()> {
    if cloud.points.len() <= MAX_CLOUD_POINTS {
        return Ok(());
    }
    Err(Error::invalid(
        field,
        format!(
            "the {}x{} depth image gives {} points at {} m voxels, above the {MAX_CLOUD_POINTS} \
             a points obstacle may hold",
            depth.width(),
            depth.height(),
            cloud.points.len(),
            DEFAULT_VOXEL_M
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ball_covers_half_a_voxel_diagonal_and_the_noise() {
        let s = CloudSettings::default();
        let r = point_radius_m(&s, 0.5);
        let expected = 0.005 * 3f64.sqrt() / 2.0 + 2.0 * 0.004 * 0.25;
        assert!((r - expected).abs() < 1e-15, "{r}");
        assert!(point_radius_m(&s, 1.0) > r);
    }

    #[test]
    fn world_values_parse_and_unknown_ones_name_the_field() {
        assert_eq!(
            WorldSource::parse("depth", "world").unwrap(),
            WorldSource::Depth
        );
        assert_eq!(
            WorldSource::parse("none", "world").unwrap(),
            WorldSource::None
        );
        let e = WorldSource::parse("lidar", "--world").unwrap_err();
        assert!(e.to_string().contains("--world"), "{e}");
    }
}
