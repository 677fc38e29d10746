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
//!
//! The primitives are the ones obstacles use ([`crate::geometry::Primitive`]).

use super::chain::isometry_from_xyz_rpy;
use super::hull::ConvexHull;
use super::mesh::{MeshFormat, TriangleMesh};
use super::mesh_files::MeshFiles;
use crate::error::ensure_positive;
use crate::geometry::{quaternion, Capsule, OrientedBox, Primitive, Sphere};
use crate::{Error, Result};
use nalgebra::{Isometry3, Point3};
use serde::Serialize;

/// A link's collision shape in its link's frame: a mesh hull or one of the
/// shared primitives, each serialised with its `"type"` tag.
#[derive(Clone, Debug, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ShapeGeometry {
    /// The convex hull of a collision mesh (`vertices`, outward `faces`,
    /// and the `allowance_m` subtracted from distances measured to it).
    Convex(ConvexHull),
    /// A sphere, capsule or box, written with its own `"type"` tag.
    #[serde(untagged)]
    Primitive(Primitive),
}

impl From<Primitive> for ShapeGeometry {
    fn from(p: Primitive) -> ShapeGeometry {
        ShapeGeometry::Primitive(p)
    }
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

impl LinkShape {
    /// A name for messages: the link and the kind of shape
    /// (`panda_hand hull`, `panda_leftfinger box`).
    pub fn describe(&self) -> String {
        let kind = match &self.geometry {
            ShapeGeometry::Convex(_) => "hull",
            ShapeGeometry::Primitive(crate::geometry::Primitive::Sphere(_)) => "sphere",
            ShapeGeometry::Primitive(crate::geometry::Primitive::Capsule(_)) => "capsule",
            ShapeGeometry::Primitive(crate::geometry::Primitive::Box(_)) => "box",
        };
        format!("{} {kind}", self.link_name)
    }
}

impl ShapeGeometry {
    /// The same shape expressed in the frame where `pose` maps its current
    /// frame (e.g. link frame to base frame).
    pub fn transformed(&self, pose: &Isometry3<f64>) -> ShapeGeometry {
        match self {
            ShapeGeometry::Convex(hull) => ShapeGeometry::Convex(hull.transformed(pose)),
            ShapeGeometry::Primitive(p) => ShapeGeometry::Primitive(p.transformed(pose)),
        }
    }

    /// Farthest distance from `origin` to a point of the shape (same frame).
    pub fn reach_from(&self, origin: &[f64; 3]) -> f64 {
        match self {
            ShapeGeometry::Convex(hull) => hull.reach_from(origin),
            ShapeGeometry::Primitive(p) => p.reach_from(origin),
        }
    }

    /// Whether the point `p` (same frame) lies inside, within `tolerance`.
    pub fn contains(&self, p: &[f64; 3], tolerance: f64) -> bool {
        self.signed_distance(p) <= tolerance
    }

    /// Signed distance from `p` to the surface (negative inside).
    pub fn signed_distance(&self, p: &[f64; 3]) -> f64 {
        match self {
            ShapeGeometry::Convex(hull) => hull.signed_distance(p),
            ShapeGeometry::Primitive(primitive) => primitive.signed_distance(p),
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
            Primitive::Capsule(Capsule {
                a: [0.0, 0.0, -0.5 * length],
                b: [0.0, 0.0, 0.5 * length],
                radius: *radius,
            })
        }
        urdf_rs::Geometry::Sphere { radius } => {
            ensure_positive(&format!("{element}.geometry.radius"), *radius)?;
            Primitive::Sphere(Sphere {
                center: [0.0; 3],
                radius: *radius,
            })
        }
        urdf_rs::Geometry::Box { size } => {
            for (i, s) in size.0.iter().enumerate() {
                ensure_positive(&format!("{element}.geometry.size[{i}]"), *s)?;
            }
            Primitive::Box(OrientedBox {
                center: [0.0; 3],
                half_extents: size.0.map(|s| 0.5 * s),
                rotation: quaternion::IDENTITY_XYZW,
            })
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
    Ok(local.transformed(&origin).into())
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
