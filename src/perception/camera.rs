//! The gripper camera: a pinhole (OpenCV convention: x right, y down,
//! z forward) mounted on the gripper, looking along the gripper (TCP z) axis.
//!
//! The camera sits `mount_back_m` behind the TCP along the gripper axis and
//! `mount_up_m` above it (towards world up, perpendicular to the axis); its
//! image "up" is world up projected onto the image plane. Images are only
//! taken at the home configuration, so the mount is fixed by that pose.
//! [`CameraModel`] (intrinsics and mount) is what a dataset and a model
//! record, so planning back-projects through the camera the data came from.

use crate::{Error, Result};
use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics (the manifest's `camera` block).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Focal length x (px).
    pub fx: f64,
    /// Focal length y (px).
    pub fy: f64,
    /// Principal point x (px).
    pub cx: f64,
    /// Principal point y (px).
    pub cy: f64,
}

impl Default for Intrinsics {
    /// The gripper camera of the synthetic data: 640x480, 615 px focal
    /// length (a RealSense D435i's colour stream at that size).
    fn default() -> Self {
        Intrinsics {
            width: 640,
            height: 480,
            fx: 615.0,
            fy: 615.0,
            cx: 320.0,
            cy: 240.0,
        }
    }
}

/// The camera as data: intrinsics and its mount on the gripper.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraModel {
    /// Pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// Camera position behind the TCP along the gripper axis (m).
    pub mount_back_m: f64,
    /// Camera position above the gripper axis (m), towards world up.
    pub mount_up_m: f64,
}

impl Intrinsics {
    /// Check every field; errors name `<prefix>.<field>`.
    pub fn validate(&self, prefix: &str) -> Result<()> {
        for (name, size) in [("width", self.width), ("height", self.height)] {
            if !(16..=4096).contains(&size) {
                return Err(Error::invalid(
                    format!("{prefix}.{name}"),
                    format!("must be in 16..=4096, got {size}"),
                ));
            }
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 1.0) {
                return Err(Error::invalid(
                    format!("{prefix}.{name}"),
                    format!("must be a finite number > 1, got {v}"),
                ));
            }
        }
        for (name, v, size) in [("cx", self.cx, self.width), ("cy", self.cy, self.height)] {
            if !(v.is_finite() && v >= 0.0 && v <= size as f64) {
                return Err(Error::invalid(
                    format!("{prefix}.{name}"),
                    format!("must lie in the image [0, {size}], got {v}"),
                ));
            }
        }
        Ok(())
    }
}

impl CameraModel {
    /// Check every field; errors name `<prefix>.intrinsics.<field>` and
    /// `<prefix>.mount_back_m` / `<prefix>.mount_up_m` (the JSON paths).
    pub fn validate(&self, prefix: &str) -> Result<()> {
        self.intrinsics.validate(&format!("{prefix}.intrinsics"))?;
        self.validate_mount(prefix)
    }

    /// Check the mount offsets; errors name `<prefix>.<field>`.
    pub fn validate_mount(&self, prefix: &str) -> Result<()> {
        for (name, v) in [
            ("mount_back_m", self.mount_back_m),
            ("mount_up_m", self.mount_up_m),
        ] {
            if !(v.is_finite() && v.abs() <= 1.0) {
                return Err(Error::invalid(
                    format!("{prefix}.{name}"),
                    format!("must be a finite offset of at most 1 m, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

impl Default for CameraModel {
    fn default() -> Self {
        CameraModel {
            intrinsics: Intrinsics::default(),
            mount_back_m: 0.10,
            mount_up_m: 0.07,
        }
    }
}

/// The home TCP pose read off the real data (REFERENCE.md), used when no
/// robot model is at hand: position and gripper axis.
pub const REFERENCE_HOME_TCP: ([f64; 3], [f64; 3]) = ([0.380, -0.062, 0.708], [0.97, -0.06, -0.22]);

/// Nearest depth the camera sees (m).
pub const NEAR_M: f64 = 0.01;

/// A posed pinhole camera.
#[derive(Clone, Debug)]
pub struct Camera {
    /// Intrinsics.
    pub intrinsics: Intrinsics,
    /// Camera-to-base transform.
    pub pose: Isometry3<f64>,
}

impl Camera {
    /// A camera at `position` looking along `forward` with world `up` at the
    /// top of the image.
    pub fn looking_along(
        intrinsics: Intrinsics,
        position: Point3<f64>,
        forward: Vector3<f64>,
        up: Vector3<f64>,
    ) -> Result<Camera> {
        let f = forward
            .try_normalize(1e-12)
            .ok_or_else(|| Error::invalid("camera.forward", "must be a non-zero vector"))?;
        let right = f
            .cross(&up)
            .try_normalize(1e-9)
            .ok_or_else(|| Error::invalid("camera.forward", "must not be parallel to world up"))?;
        let down = f.cross(&right);
        let rot = Rotation3::from_basis_unchecked(&[right, down, f]);
        Ok(Camera {
            intrinsics,
            pose: Isometry3::from_parts(
                Translation3::from(position.coords),
                UnitQuaternion::from_rotation_matrix(&rot),
            ),
        })
    }

    /// The gripper camera of `robot` at its home configuration, where the
    /// images are captured.
    pub fn at_home(model: &CameraModel, robot: &crate::robot::Robot) -> Result<Camera> {
        let home = robot.tcp_pose(&robot.home());
        Camera::on_gripper(
            model,
            Point3::from(home.translation.vector),
            home.rotation * Vector3::z(),
        )
    }

    /// The gripper camera for a TCP at `tcp` with gripper axis `axis`.
    pub fn on_gripper(model: &CameraModel, tcp: Point3<f64>, axis: Vector3<f64>) -> Result<Camera> {
        let f = axis
            .try_normalize(1e-12)
            .ok_or_else(|| Error::invalid("camera.axis", "must be a non-zero vector"))?;
        let world_up = Vector3::z();
        let up = (world_up - f * f.dot(&world_up))
            .try_normalize(1e-9)
            .ok_or_else(|| {
                Error::invalid(
                    "camera.axis",
                    "gripper axis must not point straight up or down",
                )
            })?;
        let position = tcp - f * model.mount_back_m + up * model.mount_up_m;
        Camera::looking_along(model.intrinsics, position, f, world_up)
    }

    /// The gripper camera at the reference home TCP pose (no robot model).
    pub fn reference_home(model: &CameraModel) -> Result<Camera> {
        let (p, a) = REFERENCE_HOME_TCP;
        Camera::on_gripper(model, Point3::from(p), Vector3::from(a))
    }

    /// Camera centre in the base frame.
    pub fn position(&self) -> Point3<f64> {
        Point3::from(self.pose.translation.vector)
    }

    /// A base-frame point in camera coordinates.
    pub fn to_camera(&self, p: &Point3<f64>) -> Point3<f64> {
        self.pose.inverse_transform_point(p)
    }

    /// Pixel `(u, v)` and depth of a base-frame point; `None` behind the near plane.
    pub fn project(&self, p: &Point3<f64>) -> Option<([f64; 2], f64)> {
        let c = self.to_camera(p);
        if c.z < NEAR_M {
            return None;
        }
        let k = &self.intrinsics;
        Some(([k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy], c.z))
    }

    /// The base-frame point at pixel `(u, v)` and z-depth `z` (distance
    /// along the optical axis): the inverse of [`Camera::project`].
    pub fn back_project(&self, u: f64, v: f64, z: f64) -> Point3<f64> {
        let k = &self.intrinsics;
        let c = Point3::new((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z);
        self.pose.transform_point(&c)
    }

    /// Unit ray direction (base frame) through pixel `(u, v)`; pixel centres
    /// are at half-integer coordinates.
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let k = &self.intrinsics;
        let d = Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
        self.pose.rotation * d.normalize()
    }

    /// Whether a pixel box `[x1, y1, x2, y2]` lies inside the image with `border` pixels to spare.
    pub fn box_inside(&self, b: &[f64; 4], border: f64) -> bool {
        let k = &self.intrinsics;
        b[0] >= border
            && b[1] >= border
            && b[2] <= k.width as f64 - border
            && b[3] <= k.height as f64 - border
    }
}

/// Bounding box `[x1, y1, x2, y2]` of the projections of `points`; `None`
/// when any point is behind the camera.
pub fn bounding_box(camera: &Camera, points: &[Point3<f64>]) -> Option<[f64; 4]> {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in points {
        let (uv, _) = camera.project(p)?;
        b = [
            b[0].min(uv[0]),
            b[1].min(uv[1]),
            b[2].max(uv[0]),
            b[3].max(uv[1]),
        ];
    }
    (b[0] <= b[2]).then_some(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::reference_home(&CameraModel::default()).unwrap()
    }

    #[test]
    fn point_on_axis_projects_to_principal_point() {
        let c = cam();
        let p = c.position() + c.pose.rotation * Vector3::new(0.0, 0.0, 0.4);
        let (uv, depth) = c.project(&p).unwrap();
        assert!((uv[0] - 320.0).abs() < 1e-9 && (uv[1] - 240.0).abs() < 1e-9);
        assert!((depth - 0.4).abs() < 1e-12);
    }

    #[test]
    fn known_point_projects_by_pinhole_formula() {
        let c = cam();
        // 0.05 right, 0.02 down, 0.5 forward in camera coordinates.
        let p = c.pose.transform_point(&Point3::new(0.05, 0.02, 0.5));
        let (uv, _) = c.project(&p).unwrap();
        assert!((uv[0] - (320.0 + 615.0 * 0.1)).abs() < 1e-9);
        assert!((uv[1] - (240.0 + 615.0 * 0.04)).abs() < 1e-9);
    }

    #[test]
    fn ray_and_projection_are_inverse() {
        let c = cam();
        for (u, v) in [(10.5, 20.5), (320.0, 240.0), (600.25, 470.75)] {
            let p = c.position() + c.ray(u, v) * 0.7;
            let (uv, _) = c.project(&p).unwrap();
            assert!((uv[0] - u).abs() < 1e-9 && (uv[1] - v).abs() < 1e-9);
        }
    }

    #[test]
    fn world_up_is_image_up_and_camera_looks_along_axis() {
        let c = cam();
        let centre = c.position() + c.ray(320.0, 240.0) * 0.5;
        let above = centre + Vector3::z() * 0.05;
        let (a, _) = c.project(&above).unwrap();
        assert!(a[1] < 240.0 && (a[0] - 320.0).abs() < 1e-6);
        let axis = Vector3::from(REFERENCE_HOME_TCP.1).normalize();
        assert!((c.ray(320.0, 240.0).dot(&axis) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn back_projection_inverts_projection() {
        let c = cam();
        for p in [
            Point3::new(0.8, -0.1, 0.6),
            Point3::new(0.7, 0.12, 0.75),
            Point3::new(0.9, 0.0, 0.4),
        ] {
            let (uv, z) = c.project(&p).unwrap();
            let back = c.back_project(uv[0], uv[1], z);
            assert!((back - p).norm() < 1e-9, "{back} vs {p}");
        }
    }

    #[test]
    fn points_behind_are_not_projected() {
        let c = cam();
        let p = c.position() - c.ray(320.0, 240.0) * 0.3;
        assert!(c.project(&p).is_none());
        assert!(bounding_box(&c, &[p]).is_none());
    }
}
