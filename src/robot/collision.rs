//! Link collision geometry: convex hulls of meshes, capsules, spheres and
//! boxes in link frames, converted from URDF `<collision>` elements.
//!
//! Every shape here contains the geometry its URDF element describes, so a
//! distance measured to it never exceeds the distance to the real link:
//! - `<mesh>` becomes the convex hull of the mesh ([`super::hull`]), which
//!   contains every triangle by convexity;
//! - `<capsule>` (urdf-rs) and `<cylinder>` are both taken as capsules about
//!   the origin's z axis: a cylinder becomes the capsule with the same axis
//!   and radius, which contains it;
//! - `<sphere>` and `<box>` are exact.

use super::chain::isometry_from_xyz_rpy;
use super::hull::ConvexHull;
use super::mesh::{MeshFormat, TriangleMesh};
use super::mesh_files::MeshFiles;
use crate::error::ensure_positive;
use crate::geometry::{point_segment_distance, quaternion};
use crate::{Error, Result};
use nalgebra::{Isometry3, Point3};
use serde::Serialize;

/// A convex primitive in its link's frame.
#[derive(Clone, Debug, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ShapeGeometry {
    /// Points within `radius` of the segment `a`–`b`.
    Capsule {
        /// First end of the axis segment.
        a: [f64; 3],
        /// Second end of the axis segment.
        b: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// A ball.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// An oriented box.
    Box {
        /// Centre.
        center: [f64; 3],
        /// Half the side lengths along the box axes.
        half_extents: [f64; 3],
        /// Orientation of the box axes, quaternion `[x, y, z, w]`.
        rotation: [f64; 4],
    },
    /// The convex hull of a collision mesh (`vertices`, outward `faces`,
    /// and the `allowance_m` subtracted from distances measured to it).
    Convex(ConvexHull),
}

/// A collision primitive attached to a chain link.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct LinkShape {
    /// Index into `robot.link_names()`.
    pub link: usize,
    /// Name of that link.
    pub link_name: String,
    /// The primitive, in the link frame.
    pub geometry: ShapeGeometry,
}

impl ShapeGeometry {
    /// The same primitive expressed in the frame where `pose` maps its
    /// current frame (e.g. link frame to base frame).
    pub fn transformed(&self, pose: &Isometry3<f64>) -> ShapeGeometry {
        let map = |p: &[f64; 3]| -> [f64; 3] { (pose * Point3::from(*p)).coords.into() };
        match self {
            ShapeGeometry::Capsule { a, b, radius } => ShapeGeometry::Capsule {
                a: map(a),
                b: map(b),
                radius: *radius,
            },
            ShapeGeometry::Sphere { center, radius } => ShapeGeometry::Sphere {
                center: map(center),
                radius: *radius,
            },
            ShapeGeometry::Box {
                center,
                half_extents,
                rotation,
            } => {
                let q = quaternion::from_xyzw(rotation);
                let r = pose.rotation * q;
                ShapeGeometry::Box {
                    center: map(center),
                    half_extents: *half_extents,
                    rotation: quaternion::to_xyzw(&r),
                }
            }
            ShapeGeometry::Convex(hull) => ShapeGeometry::Convex(hull.transformed(pose)),
        }
    }

    /// Farthest distance from `origin` to a point of the shape (same frame).
    pub fn reach_from(&self, origin: &[f64; 3]) -> f64 {
        let d = |p: &[f64; 3]| (Point3::from(*p) - Point3::from(*origin)).norm();
        match self {
            ShapeGeometry::Capsule { a, b, radius } => d(a).max(d(b)) + radius,
            ShapeGeometry::Sphere { center, radius } => d(center) + radius,
            ShapeGeometry::Box {
                center,
                half_extents,
                ..
            } => d(center) + nalgebra::Vector3::from(*half_extents).norm(),
            ShapeGeometry::Convex(hull) => hull.reach_from(origin),
        }
    }

    /// Whether the point `p` (same frame) lies inside, within `tolerance`.
    pub fn contains(&self, p: &[f64; 3], tolerance: f64) -> bool {
        self.signed_distance(p) <= tolerance
    }

    /// Signed distance from `p` to the surface (negative inside).
    pub fn signed_distance(&self, p: &[f64; 3]) -> f64 {
        match self {
            ShapeGeometry::Capsule { a, b, radius } => {
                point_segment_distance(&(*p).into(), &(*a).into(), &(*b).into()) - radius
            }
            ShapeGeometry::Convex(hull) => hull.signed_distance(p),
            ShapeGeometry::Sphere { center, radius } => {
                (Point3::from(*p) - Point3::from(*center)).norm() - radius
            }
            ShapeGeometry::Box {
                center,
                half_extents,
                rotation,
            } => {
                let q = quaternion::from_xyzw(rotation);
                let local = q.inverse() * (Point3::from(*p) - Point3::from(*center));
                let outside =
                    nalgebra::Vector3::from_fn(|i, _| (local[i].abs() - half_extents[i]).max(0.0));
                let inside = (0..3)
                    .map(|i| local[i].abs() - half_extents[i])
                    .fold(f64::NEG_INFINITY, f64::max);
                if inside > 0.0 {
                    outside.norm()
                } else {
                    inside
                }
            }
        }
    }
}

/// Convert one URDF `<collision>` element (origin + geometry) into a
/// primitive in the frame `frame_from_link` maps the link frame into.
/// `element` names the element for errors; mesh files are read from
/// `files`, and what is worth knowing but not wrong (an open mesh) is
/// pushed to `warnings`.
pub fn geometry_from_urdf(
    element: &str,
    collision: &urdf_rs::Collision,
    frame_from_link: &Isometry3<f64>,
    files: &MeshFiles,
    warnings: &mut Vec<String>,
) -> Result<ShapeGeometry> {
    let xyz = collision.origin.xyz.0;
    let rpy = collision.origin.rpy.0;
    crate::error::ensure_finite(&format!("{element}.origin.xyz"), &xyz)?;
    crate::error::ensure_finite(&format!("{element}.origin.rpy"), &rpy)?;
    let origin = frame_from_link * isometry_from_xyz_rpy(xyz, rpy);
    let local = match &collision.geometry {
        urdf_rs::Geometry::Capsule { radius, length }
        | urdf_rs::Geometry::Cylinder { radius, length } => {
            ensure_positive(&format!("{element}.geometry.radius"), *radius)?;
            ensure_non_negative(&format!("{element}.geometry.length"), *length)?;
            ShapeGeometry::Capsule {
                a: [0.0, 0.0, -0.5 * length],
                b: [0.0, 0.0, 0.5 * length],
                radius: *radius,
            }
        }
        urdf_rs::Geometry::Sphere { radius } => {
            ensure_positive(&format!("{element}.geometry.radius"), *radius)?;
            ShapeGeometry::Sphere {
                center: [0.0; 3],
                radius: *radius,
            }
        }
        urdf_rs::Geometry::Box { size } => {
            for (i, s) in size.0.iter().enumerate() {
                ensure_positive(&format!("{element}.geometry.size[{i}]"), *s)?;
            }
            ShapeGeometry::Box {
                center: [0.0; 3],
                half_extents: size.0.map(|s| 0.5 * s),
                rotation: quaternion::IDENTITY_XYZW,
            }
        }
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let field = format!("{element}.geometry.mesh");
            let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
            let mesh = read_mesh(filename, scale, files).map_err(|m| Error::invalid(&field, m))?;
            let open = mesh.open_edges();
            if open > 0 {
                warnings.push(format!(
                    "urdf.{field}: mesh '{filename}' is not closed ({open} edges not shared by exactly \
                     two triangles); its convex hull is used and contains it all the same"
                ));
            }
            let placed = mesh.mapped(|p| (origin * Point3::from(*p)).coords.into());
            let hull = ConvexHull::of_mesh(&placed)
                .map_err(|m| Error::invalid(&field, format!("mesh '{filename}': {m}")))?;
            return Ok(ShapeGeometry::Convex(hull));
        }
    };
    Ok(local.transformed(&origin))
}

/// Read, parse, scale and validate one mesh file; messages name the file.
pub fn read_mesh(
    filename: &str,
    scale: [f64; 3],
    files: &MeshFiles,
) -> std::result::Result<TriangleMesh, String> {
    let format =
        MeshFormat::from_file_name(filename).map_err(|m| format!("mesh '{filename}': {m}"))?;
    let (location, bytes) = files.read(filename)?;
    TriangleMesh::parse(&bytes, format, scale).map_err(|m| format!("mesh file {location}: {m}"))
}

fn ensure_non_negative(field: &str, value: f64) -> Result<()> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("must be a finite number >= 0, got {value}"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_signed_distance_is_exact_on_axes_and_corners() {
        let b = ShapeGeometry::Box {
            center: [1.0, 0.0, 0.0],
            half_extents: [0.1, 0.2, 0.3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        assert!((b.signed_distance(&[1.0, 0.0, 0.0]) + 0.1).abs() < 1e-12);
        assert!((b.signed_distance(&[1.5, 0.0, 0.0]) - 0.4).abs() < 1e-12);
        let d = b.signed_distance(&[1.2, 0.3, 0.3]);
        assert!((d - (0.1f64.powi(2) * 2.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn transformed_capsule_keeps_its_radius_and_moves_its_ends() {
        let c = ShapeGeometry::Capsule {
            a: [0.0, 0.0, -0.1],
            b: [0.0, 0.0, 0.1],
            radius: 0.05,
        };
        let pose = isometry_from_xyz_rpy([1.0, 2.0, 3.0], [std::f64::consts::FRAC_PI_2, 0.0, 0.0]);
        match c.transformed(&pose) {
            ShapeGeometry::Capsule { a, b, radius } => {
                assert_eq!(radius, 0.05);
                assert!(
                    (a[1] - 2.1).abs() < 1e-12 && (b[1] - 1.9).abs() < 1e-12,
                    "{a:?} {b:?}"
                );
            }
            other => panic!("{other:?}"),
        }
    }
}
