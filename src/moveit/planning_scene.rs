//! `moveit_msgs/PlanningScene` → obstacles in the robot's base frame.
//!
//! Read: `world.collision_objects`, each with its `id`, optional object
//! `pose` and `header.frame_id`, `primitives` (box, sphere, cylinder; a
//! cone is refused) with their `primitive_poses`, `meshes` with their
//! `mesh_poses` (each becomes the convex hull of its vertices, which holds
//! the mesh, so clearance to it never overstates the clearance to the mesh),
//! and `operation` (ADD, APPEND and MOVE place the object; REMOVE drops an
//! earlier one by id); `fixed_frame_transforms`, for an object in another
//! named frame when that frame's transform to the base is the identity; the
//! allowed-collision matrix, whose robot-to-world entries are reported (the
//! planner keeps every link clear of every object). Positions are written
//! `[x, y, z]` or `{x, y, z}`, orientations `[x, y, z, w]` or `{x, y, z,
//! w}`; a primitive's type is its name (`box`) or MoveIt's number (1).
//!
//! A box's `dimensions` are its full sides; a cylinder's `[height,
//! radius]`, its axis the pose's z; a sphere's `[radius]` (MoveIt's
//! `shape_msgs/SolidPrimitive`).

use crate::geometry::quaternion::{from_xyzw, to_xyzw};
use crate::geometry::{OrientedBox, Sphere};
use crate::scene::{Obstacle, ObstacleShape};
use crate::{Error, Result};
use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use serde::Deserialize;

/// Largest deviation of a quaternion's norm from 1 that is accepted.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Most vertices of one mesh.
pub const MAX_MESH_VERTICES: usize = 100_000;

/// A planning scene's world, as dPMP plans around it.
#[derive(Clone, Debug, PartialEq)]
pub struct MoveItScene {
    /// One obstacle per primitive or mesh (`<object id>` for an object of
    /// one shape, `<object id>/<k>` for the k-th of several).
    pub obstacles: Vec<Obstacle>,
    /// What was read but is handled differently from MoveIt.
    pub warnings: Vec<String>,
}

/// Read a `PlanningScene` from YAML or JSON `text` (JSON is YAML); the
/// robot's base link is `base`. Errors name the field
/// (`world.collision_objects[2].primitives[0].dimensions`).
pub fn read_planning_scene(text: &str, base: &str) -> Result<MoveItScene> {
    let scene: PlanningScene = serde_yaml::from_str(text)
        .map_err(|e| Error::invalid("planning_scene", format!("not a PlanningScene: {e}")))?;
    scene.into_world(base)
}

#[derive(Debug, Default, Deserialize)]
struct PlanningScene {
    #[serde(default)]
    world: World,
    #[serde(default)]
    fixed_frame_transforms: Vec<TransformStamped>,
    #[serde(default)]
    allowed_collision_matrix: Option<AllowedCollisionMatrix>,
}

#[derive(Debug, Default, Deserialize)]
struct World {
    #[serde(default)]
    collision_objects: Vec<CollisionObject>,
}

#[derive(Debug, Default, Deserialize)]
struct Header {
    #[serde(default)]
    frame_id: String,
}

#[derive(Debug, Deserialize)]
struct TransformStamped {
    #[serde(default)]
    header: Header,
    child_frame_id: String,
    transform: Transform,
}

#[derive(Debug, Deserialize)]
struct Transform {
    translation: Xyz,
    rotation: Xyzw,
}

#[derive(Debug, Deserialize)]
struct AllowedCollisionMatrix {
    #[serde(default)]
    entry_names: Vec<String>,
    #[serde(default)]
    entry_values: Vec<AcmRow>,
}

/// A row of the matrix: `[true, false]` or `{enabled: [..]}` (ROS 2).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum AcmRow {
    Flat(Vec<bool>),
    Enabled { enabled: Vec<bool> },
}

#[derive(Debug, Deserialize)]
struct CollisionObject {
    #[serde(default)]
    id: String,
    #[serde(default)]
    header: Header,
    #[serde(default)]
    pose: Option<Pose>,
    #[serde(default)]
    primitives: Vec<SolidPrimitive>,
    #[serde(default)]
    primitive_poses: Vec<Pose>,
    #[serde(default)]
    meshes: Vec<Mesh>,
    #[serde(default)]
    mesh_poses: Vec<Pose>,
    #[serde(default)]
    operation: Option<Operation>,
}

#[derive(Debug, Deserialize)]
struct SolidPrimitive {
    #[serde(rename = "type")]
    kind: PrimitiveType,
    #[serde(default)]
    dimensions: Vec<f64>,
}

/// `shape_msgs/SolidPrimitive` type: by name or by MoveIt's number.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum PrimitiveType {
    Number(u8),
    Name(String),
}

#[derive(Debug, Deserialize)]
struct Mesh {
    #[serde(default)]
    vertices: Vec<Xyz>,
}

/// `CollisionObject.operation`: by name or by number (ADD 0, REMOVE 1,
/// APPEND 2, MOVE 3).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum Operation {
    Number(u8),
    Name(String),
}

#[derive(Debug, Deserialize)]
struct Pose {
    position: Xyz,
    #[serde(default = "Xyzw::identity")]
    orientation: Xyzw,
}

/// `[x, y, z]` or `{x, y, z}`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(untagged)]
pub(super) enum Xyz {
    List([f64; 3]),
    Map { x: f64, y: f64, z: f64 },
}

/// `[x, y, z, w]` or `{x, y, z, w}`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(untagged)]
pub(super) enum Xyzw {
    List([f64; 4]),
    Map { x: f64, y: f64, z: f64, w: f64 },
}

impl Xyz {
    pub(super) fn array(self) -> [f64; 3] {
        match self {
            Xyz::List(v) => v,
            Xyz::Map { x, y, z } => [x, y, z],
        }
    }
}

impl Xyzw {
    fn identity() -> Xyzw {
        Xyzw::List([0.0, 0.0, 0.0, 1.0])
    }

    pub(super) fn array(self) -> [f64; 4] {
        match self {
            Xyzw::List(v) => v,
            Xyzw::Map { x, y, z, w } => [x, y, z, w],
        }
    }
}

/// A finite pose with a unit quaternion, as an isometry; errors name
/// `field`.
fn isometry(field: &str, position: Xyz, orientation: Xyzw) -> Result<Isometry3<f64>> {
    let p = position.array();
    let q = orientation.array();
    crate::error::ensure_finite(&format!("{field}.position"), &p)?;
    crate::error::ensure_finite(&format!("{field}.orientation"), &q)?;
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(Error::invalid(
            format!("{field}.orientation"),
            format!("must be a unit quaternion (norm within {QUATERNION_NORM_TOLERANCE} of 1), got norm {norm}"),
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        from_xyzw(&q),
    ))
}

impl PlanningScene {
    fn into_world(self, base: &str) -> Result<MoveItScene> {
        let mut placed: Vec<(String, Vec<Obstacle>)> = Vec::new();
        for (i, object) in self.world.collision_objects.iter().enumerate() {
            let field = format!("world.collision_objects[{i}]");
            if object.id.trim().is_empty() {
                return Err(Error::invalid(format!("{field}.id"), "must not be empty"));
            }
            match operation(&field, object.operation.as_ref())? {
                Op::Remove => placed.retain(|(id, _)| *id != object.id),
                Op::Place => {
                    let frame = self.frame_pose(&field, &object.header.frame_id, base)?;
                    let shapes = object.shapes(&field, &frame)?;
                    for shape in &shapes {
                        shape.validate(0).map_err(|e| match e {
                            Error::Invalid { message, .. } => Error::invalid(&field, message),
                            other => other,
                        })?;
                    }
                    placed.retain(|(id, _)| *id != object.id);
                    placed.push((object.id.clone(), shapes));
                }
            }
        }
        let warnings = self.collision_warnings(&placed);
        Ok(MoveItScene {
            obstacles: placed.into_iter().flat_map(|(_, o)| o).collect(),
            warnings,
        })
    }

    /// The pose of `frame` in the base frame: the identity for the base
    /// (or no frame), else a fixed frame transform that is the identity.
    fn frame_pose(&self, field: &str, frame: &str, base: &str) -> Result<Isometry3<f64>> {
        let frame = frame.trim_start_matches('/');
        if frame.is_empty() || frame == base {
            return Ok(Isometry3::identity());
        }
        let known = self.fixed_frame_transforms.iter().find(|t| {
            t.child_frame_id.trim_start_matches('/') == frame
                && [base, ""].contains(&t.header.frame_id.trim_start_matches('/'))
        });
        let Some(t) = known else {
            return Err(Error::invalid(
                format!("{field}.header.frame_id"),
                format!("the frame {frame:?} is neither the robot's base {base:?} nor a fixed frame transform from it"),
            ));
        };
        let pose = isometry(
            &format!("{field}.header.frame_id ({frame:?} in fixed_frame_transforms)"),
            t.transform.translation,
            t.transform.rotation,
        )?;
        let identity = pose.translation.vector.norm() < 1e-9 && pose.rotation.angle() < 1e-9;
        if !identity {
            return Err(Error::invalid(
                format!("{field}.header.frame_id"),
                format!("the frame {frame:?} is offset from the robot's base {base:?}: give the objects in the base frame"),
            ));
        }
        Ok(pose)
    }

    /// A warning per allowed-collision entry between a robot link and a
    /// placed object (the planner keeps every link clear of every object).
    fn collision_warnings(&self, placed: &[(String, Vec<Obstacle>)]) -> Vec<String> {
        let Some(acm) = &self.allowed_collision_matrix else {
            return Vec::new();
        };
        let is_object = |name: &str| placed.iter().any(|(id, _)| id == name);
        let mut warnings = Vec::new();
        for (i, row) in acm.entry_values.iter().enumerate() {
            let values = match row {
                AcmRow::Flat(v) | AcmRow::Enabled { enabled: v } => v,
            };
            for (j, allowed) in values.iter().enumerate() {
                let (Some(a), Some(b)) = (acm.entry_names.get(i), acm.entry_names.get(j)) else {
                    continue;
                };
                if *allowed && is_object(b) && !is_object(a) {
                    warnings.push(format!(
                        "the allowed-collision matrix lets {a:?} touch {b:?}; dPMP keeps every link clear of every object"
                    ));
                }
            }
        }
        warnings
    }
}

enum Op {
    Place,
    Remove,
}

fn operation(field: &str, op: Option<&Operation>) -> Result<Op> {
    match op {
        None | Some(Operation::Number(0 | 2 | 3)) => Ok(Op::Place),
        Some(Operation::Number(1)) => Ok(Op::Remove),
        Some(Operation::Name(name)) => match name.to_ascii_lowercase().as_str() {
            "add" | "append" | "move" | "\0" => Ok(Op::Place),
            "remove" | "\u{1}" => Ok(Op::Remove),
            other => Err(Error::invalid(
                format!("{field}.operation"),
                format!("unknown operation {other:?}: ADD, REMOVE, APPEND or MOVE"),
            )),
        },
        Some(Operation::Number(n)) => Err(Error::invalid(
            format!("{field}.operation"),
            format!("unknown operation {n}: ADD (0), REMOVE (1), APPEND (2) or MOVE (3)"),
        )),
    }
}

impl CollisionObject {
    /// Every primitive and mesh of the object, posed in the base frame.
    fn shapes(&self, field: &str, frame: &Isometry3<f64>) -> Result<Vec<Obstacle>> {
        let object = match &self.pose {
            Some(p) => frame * isometry(&format!("{field}.pose"), p.position, p.orientation)?,
            None => *frame,
        };
        if self.primitives.len() != self.primitive_poses.len() {
            return Err(Error::invalid(
                format!("{field}.primitive_poses"),
                format!(
                    "{} poses for {} primitives: one each",
                    self.primitive_poses.len(),
                    self.primitives.len()
                ),
            ));
        }
        if self.meshes.len() != self.mesh_poses.len() {
            return Err(Error::invalid(
                format!("{field}.mesh_poses"),
                format!(
                    "{} poses for {} meshes: one each",
                    self.mesh_poses.len(),
                    self.meshes.len()
                ),
            ));
        }
        let count = self.primitives.len() + self.meshes.len();
        let name = |k: usize| {
            if count == 1 {
                self.id.clone()
            } else {
                format!("{}/{k}", self.id)
            }
        };
        let mut out = Vec::with_capacity(count);
        for (k, (primitive, pose)) in self
            .primitives
            .iter()
            .zip(&self.primitive_poses)
            .enumerate()
        {
            let f = format!("{field}.primitives[{k}]");
            let pose = object
                * isometry(
                    &format!("{field}.primitive_poses[{k}]"),
                    pose.position,
                    pose.orientation,
                )?;
            out.push(Obstacle {
                id: name(k),
                shape: primitive.shape(&f, &pose)?,
            });
        }
        for (k, (mesh, pose)) in self.meshes.iter().zip(&self.mesh_poses).enumerate() {
            let f = format!("{field}.meshes[{k}]");
            let pose = object
                * isometry(
                    &format!("{field}.mesh_poses[{k}]"),
                    pose.position,
                    pose.orientation,
                )?;
            out.push(Obstacle {
                id: name(self.primitives.len() + k),
                shape: mesh.hull(&f, &pose)?,
            });
        }
        Ok(out)
    }
}

impl SolidPrimitive {
    /// The obstacle shape of this primitive at `pose`.
    fn shape(&self, field: &str, pose: &Isometry3<f64>) -> Result<ObstacleShape> {
        let kind = match &self.kind {
            PrimitiveType::Number(1) => "box".to_string(),
            PrimitiveType::Number(2) => "sphere".to_string(),
            PrimitiveType::Number(3) => "cylinder".to_string(),
            PrimitiveType::Number(4) => "cone".to_string(),
            PrimitiveType::Number(n) => format!("{n}"),
            PrimitiveType::Name(name) => name.to_ascii_lowercase(),
        };
        let dims = |n: usize| -> Result<&[f64]> {
            if self.dimensions.len() != n {
                return Err(Error::invalid(
                    format!("{field}.dimensions"),
                    format!("a {kind} has {n} dimensions, got {}", self.dimensions.len()),
                ));
            }
            if let Some(i) = self
                .dimensions
                .iter()
                .position(|d| !(d.is_finite() && *d > 0.0))
            {
                return Err(Error::invalid(
                    format!("{field}.dimensions[{i}]"),
                    format!("must be a positive size (m), got {}", self.dimensions[i]),
                ));
            }
            Ok(&self.dimensions)
        };
        let center: [f64; 3] = pose.translation.vector.into();
        match kind.as_str() {
            "box" => {
                let d = dims(3)?;
                Ok(ObstacleShape::Box(OrientedBox {
                    center,
                    half_extents: [d[0] / 2.0, d[1] / 2.0, d[2] / 2.0],
                    rotation: to_xyzw(&pose.rotation),
                }))
            }
            "sphere" => Ok(ObstacleShape::Sphere(Sphere {
                center,
                radius: dims(1)?[0],
            })),
            "cylinder" => {
                let d = dims(2)?;
                let half = pose.rotation * Vector3::new(0.0, 0.0, d[0] / 2.0);
                Ok(ObstacleShape::Cylinder {
                    a: (pose.translation.vector - half).into(),
                    b: (pose.translation.vector + half).into(),
                    radius: d[1],
                })
            }
            "cone" => Err(Error::invalid(
                format!("{field}.type"),
                "a cone is not supported: give it as a mesh (its convex hull is used) or a cylinder around it",
            )),
            other => Err(Error::invalid(
                format!("{field}.type"),
                format!("unknown primitive {other:?}: box, sphere or cylinder"),
            )),
        }
    }
}

impl Mesh {
    /// The convex hull of the vertices at `pose` (it holds the mesh).
    fn hull(&self, field: &str, pose: &Isometry3<f64>) -> Result<ObstacleShape> {
        if self.vertices.len() > MAX_MESH_VERTICES {
            return Err(Error::invalid(
                format!("{field}.vertices"),
                format!(
                    "{} vertices, at most {MAX_MESH_VERTICES}",
                    self.vertices.len()
                ),
            ));
        }
        let mut points = Vec::with_capacity(self.vertices.len());
        for (i, v) in self.vertices.iter().enumerate() {
            let p = v.array();
            crate::error::ensure_finite(&format!("{field}.vertices[{i}]"), &p)?;
            points.push((pose * Point3::from(p)).coords.into());
        }
        Ok(ObstacleShape::Convex { points })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every primitive, both spellings of poses, a rotated object pose, a
    /// mesh, a removed object and an allowed-collision entry.
    const SCENE: &str = r#"
allowed_collision_matrix:
  entry_names: [panda_hand, shelf]
  entry_values:
    - [false, true]
    - [true, false]
world:
  collision_objects:
    - id: shelf
      primitives:
        - {type: box, dimensions: [0.4, 0.2, 0.1]}
      primitive_poses:
        - position: [0.5, 0.0, 0.3]
          orientation: [0, 0, 0.7071067811865476, 0.7071067811865476]
    - id: can
      header: {frame_id: panda_link0}
      pose:
        position: {x: 0.1, y: 0.0, z: 0.0}
        orientation: {x: 0.0, y: 0.0, z: 0.0, w: 1.0}
      primitives:
        - {type: 3, dimensions: [0.2, 0.03]}
        - {type: sphere, dimensions: [0.05]}
      primitive_poses:
        - position: {x: 0.4, y: 0.2, z: 0.5}
          orientation: [0.7071067811865476, 0, 0, 0.7071067811865476]
        - position: [0.4, 0.3, 0.5]
    - id: gone
      primitives: [{type: sphere, dimensions: [0.1]}]
      primitive_poses: [{position: [0.0, 0.0, 2.0]}]
    - id: gone
      operation: remove
    - id: rock
      meshes:
        - vertices: [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
      mesh_poses:
        - position: [0.6, -0.3, 0.2]
"#;

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
    }

    #[test]
    fn every_primitive_and_pose_lands_in_the_base_frame() {
        let scene = read_planning_scene(SCENE, "panda_link0").unwrap();
        let ids: Vec<&str> = scene.obstacles.iter().map(|o| o.id.as_str()).collect();
        assert_eq!(ids, ["shelf", "can/0", "can/1", "rock"]);
        let ObstacleShape::Box(b) = &scene.obstacles[0].shape else {
            panic!()
        };
        assert!(close(&b.center, &[0.5, 0.0, 0.3]) && close(&b.half_extents, &[0.2, 0.1, 0.05]));
        // The box's own x axis turned 90° about z: along the base's y.
        let x_axis = from_xyzw(&b.rotation) * Vector3::x();
        assert!(close(x_axis.as_slice(), &[0.0, 1.0, 0.0]), "{x_axis}");
        // The cylinder's axis (its pose's z) turned 90° about x: along -y,
        // offset by the object pose.
        let ObstacleShape::Cylinder { a, b, radius } = &scene.obstacles[1].shape else {
            panic!()
        };
        assert!(
            close(a, &[0.5, 0.3, 0.5]) && close(b, &[0.5, 0.1, 0.5]),
            "{a:?} {b:?}"
        );
        assert_eq!(*radius, 0.03);
        let ObstacleShape::Sphere(s) = &scene.obstacles[2].shape else {
            panic!()
        };
        assert!(close(&s.center, &[0.5, 0.3, 0.5]) && s.radius == 0.05);
        let ObstacleShape::Convex { points } = &scene.obstacles[3].shape else {
            panic!()
        };
        assert!(close(&points[1], &[0.7, -0.3, 0.2]));
        assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
        assert!(scene.warnings[0].contains("panda_hand") && scene.warnings[0].contains("shelf"));
        // The same scene as JSON reads the same.
        let value: serde_json::Value = serde_yaml::from_str(SCENE).unwrap();
        let json = read_planning_scene(&value.to_string(), "panda_link0").unwrap();
        assert_eq!(json, scene);
    }

    #[test]
    fn what_cannot_be_honoured_is_refused_naming_the_field() {
        let one = |object: &str| format!("world:\n  collision_objects:\n    - {object}\n");
        for (object, field) in [
            (
                "{id: c, primitives: [{type: cone, dimensions: [0.1, 0.1]}], primitive_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0].primitives[0].type",
            ),
            (
                "{id: c, primitives: [{type: torus, dimensions: [0.1]}], primitive_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0].primitives[0].type",
            ),
            (
                "{id: b, primitives: [{type: box, dimensions: [0.1, 0.1]}], primitive_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0].primitives[0].dimensions",
            ),
            (
                "{id: b, primitives: [{type: box, dimensions: [0.1, -1, 0.1]}], primitive_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0].primitives[0].dimensions[1]",
            ),
            (
                "{id: b, primitives: [{type: sphere, dimensions: [0.1]}], primitive_poses: [{position: [0, 0, 0], orientation: [0, 0, 0, 2]}]}",
                "world.collision_objects[0].primitive_poses[0].orientation",
            ),
            (
                "{id: b, primitives: [{type: sphere, dimensions: [0.1]}], primitive_poses: []}",
                "world.collision_objects[0].primitive_poses",
            ),
            (
                "{id: b, header: {frame_id: world}, primitives: [{type: sphere, dimensions: [0.1]}], primitive_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0].header.frame_id",
            ),
            (
                "{id: '', primitives: [{type: sphere, dimensions: [0.1]}], primitive_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0].id",
            ),
            (
                "{id: m, meshes: [{vertices: [[0, 0, 0], [1, 0, 0], [0, 1, 0]]}], mesh_poses: [{position: [0, 0, 0]}]}",
                "world.collision_objects[0]",
            ),
        ] {
            let e = read_planning_scene(&one(object), "panda_link0").unwrap_err();
            assert_eq!(e.field(), Some(field), "{object}: {e}");
        }
        // A named frame whose fixed transform is the identity is the base.
        let framed = format!(
            "fixed_frame_transforms:\n  - {{header: {{frame_id: panda_link0}}, child_frame_id: world, transform: {{translation: [0, 0, 0], rotation: [0, 0, 0, 1]}}}}\n{}",
            one("{id: b, header: {frame_id: world}, primitives: [{type: sphere, dimensions: [0.1]}], primitive_poses: [{position: [0.3, 0, 0]}]}")
        );
        assert_eq!(
            read_planning_scene(&framed, "panda_link0")
                .unwrap()
                .obstacles
                .len(),
            1
        );
        assert!(read_planning_scene("world: 3", "panda_link0").is_err());
    }
}
