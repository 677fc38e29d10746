//! Conversion of obstacles and robot primitives to parry3d shapes.
//!
//! parry3d works in `f32`; to keep its rounding small, every query places
//! both shapes relative to a local origin near them (see
//! [`super::distance`]), so parts keep their poses in `f64` here.

use super::broadphase::{Bounds, Core};
use super::obstacle::{BerryShape, ObstacleShape};
use super::part_tree::{PartTree, TREE_MIN_PARTS};
use crate::geometry::{quaternion, Capsule, OrientedBox, Primitive, Sphere};
use crate::robot::hull::ConvexHull;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use parry3d::shape::{
    Ball, Capsule as ParryCapsule, ConvexPolyhedron, Cuboid, Cylinder, SharedShape,
};

/// Parts longer than this (m; a box: any full extent) are cut per query.
pub const LONG_PART_M: f64 = 1.0;

/// The exact description of a long part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LongPart {
    /// The part's core segment with its radius: a capsule (round ends) or a
    /// cylinder (flat ends).
    Segment {
        /// Flat end faces (a cylinder).
        flat_ends: bool,
    },
    /// An oriented box.
    Box(OrientedBox),
}

/// One convex part of an obstacle: a parry shape in its own frame and that
/// frame's pose in the base frame.
#[derive(Clone)]
pub struct Part {
    /// The parry shape (local frame).
    pub shape: SharedShape,
    /// Local frame in the base frame.
    pub pose: Isometry3<f64>,
    /// A capsule around the part (base frame), for the broad phase.
    pub core: Core,
    /// The exact shape of a long part, cut near each robot shape per query
    /// ([`super::clip`]); `None` for short parts (boxed: a cloud holds
    /// thousands of short parts, which need only the pointer's room).
    pub long: Option<Box<LongPart>>,
}

impl std::fmt::Debug for Part {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Part")
            .field("shape", &self.shape.shape_type())
            .field("pose", &self.pose)
            .finish()
    }
}

/// A validated obstacle compiled into convex parts and bounds.
#[derive(Clone, Debug)]
pub struct CompiledObstacle {
    /// Convex parts (one, two for a berry, one ball per point of a cloud).
    pub parts: Vec<Part>,
    /// Bounds of all parts.
    pub bounds: Bounds,
    /// A tree over the parts' boxes, when there are many
    /// ([`TREE_MIN_PARTS`]): queries visit only the parts near them.
    pub tree: Option<PartTree>,
}

/// Compile a validated obstacle; `None` only if parry rejects a hull that
/// passed validation (reported by the caller).
pub fn compile_obstacle(shape: &ObstacleShape) -> Option<CompiledObstacle> {
    match shape {
        ObstacleShape::Sphere(s) => Some(primitive_obstacle(&(*s).into())),
        ObstacleShape::Capsule(c) => Some(primitive_obstacle(&(*c).into())),
        ObstacleShape::Box(b) => Some(primitive_obstacle(&(*b).into())),
        ObstacleShape::Cylinder { a, b, radius } => Some(cylinder_obstacle(a, b, *radius)),
        ObstacleShape::Convex { points } => convex_obstacle(points),
        ObstacleShape::Berry(berry) => Some(berry_obstacle(berry)),
        ObstacleShape::Points { points, radius } => Some(cloud_obstacle(points, *radius)),
    }
}

/// A point cloud: one ball of `radius` per point, with a tree over them.
/// The balls share one parry shape; each part is only its centre.
fn cloud_obstacle(points: &[[f64; 3]], radius: f64) -> CompiledObstacle {
    let ball = SharedShape::new(Ball::new(radius as f32));
    let parts: Vec<Part> = points
        .iter()
        .map(|&c| {
            let centre = Vector3::from(c);
            Part {
                shape: ball.clone(),
                pose: Isometry3::translation(c[0], c[1], c[2]),
                core: Core::new(centre, centre, radius),
                long: None,
            }
        })
        .collect();
    let boxes: Vec<Bounds> = points
        .iter()
        .map(|c| Bounds::ball(&Vector3::from(*c), radius))
        .collect();
    let bounds = boxes
        .iter()
        .copied()
        .reduce(|a, b| a.merged(&b))
        .unwrap_or_else(|| Bounds::ball(&Vector3::zeros(), radius));
    let tree = (boxes.len() > TREE_MIN_PARTS)
        .then(|| PartTree::new(&boxes))
        .flatten();
    CompiledObstacle {
        parts,
        bounds,
        tree,
    }
}

/// A sphere, capsule or box obstacle: one part.
fn primitive_obstacle(primitive: &Primitive) -> CompiledObstacle {
    single(primitive_part(primitive), Bounds::of_primitive(primitive))
}

/// A flat-ended cylinder between the end-face centres `a` and `b`: parry's
/// cylinder (about its y axis) turned onto the axis; the capsule with the
/// same axis bounds it.
fn cylinder_obstacle(a: &[f64; 3], b: &[f64; 3], radius: f64) -> CompiledObstacle {
    let (a, b) = (Vector3::from(*a), Vector3::from(*b));
    let axis = b - a;
    let pose = Isometry3::from_parts(Translation3::from((a + b) * 0.5), y_onto(&axis));
    let shape = SharedShape::new(Cylinder::new(0.5 * axis.norm() as f32, radius as f32));
    let core = Core::new(a, b, radius);
    let long = (axis.norm() > LONG_PART_M).then(|| Box::new(LongPart::Segment { flat_ends: true }));
    single(
        Part {
            shape,
            pose,
            core,
            long,
        },
        Bounds::capsule(&a, &b, radius),
    )
}

/// The rotation taking the y axis (parry's cylinder axis) onto `axis`
/// (a half turn about x when `axis` points along −y).
pub fn y_onto(axis: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(&Vector3::y(), axis).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    })
}

/// The convex hull of `points`, about their mean; `None` if parry cannot
/// build it.
fn convex_obstacle(points: &[[f64; 3]]) -> Option<CompiledObstacle> {
    let pts: Vec<Vector3<f64>> = points.iter().map(|p| Vector3::from(*p)).collect();
    let centre = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let local: Vec<parry3d::math::Vector> = pts.iter().map(|p| to_glam(&(p - centre))).collect();
    let hull = ConvexPolyhedron::from_convex_hull(&local)?;
    let pose = Isometry3::from_parts(Translation3::from(centre), UnitQuaternion::identity());
    let reach = pts.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max);
    let core = Core::new(centre, centre, reach);
    Some(single(
        Part {
            shape: SharedShape::new(hull),
            pose,
            core,
            long: None,
        },
        Bounds::points(&pts),
    ))
}

/// A berry: its body (a ball, or a capsule along the stem axis when
/// elongated) and its stem capsule, from the top of the body to `stem_top`.
fn berry_obstacle(berry: &BerryShape) -> CompiledObstacle {
    let BerryShape {
        center,
        radius,
        elongation,
        stem_top,
        stem_radius,
    } = *berry;
    let (c, top) = (Vector3::from(center), Vector3::from(stem_top));
    let up = (top - c).normalize();
    let body: Primitive = if elongation > 0.0 {
        Capsule {
            a: (c - up * elongation).into(),
            b: (c + up * elongation).into(),
            radius,
        }
        .into()
    } else {
        Sphere { center, radius }.into()
    };
    let stem_base = c + up * (elongation + radius - stem_radius).max(0.0);
    let stem: Primitive = Capsule {
        a: stem_base.into(),
        b: stem_top,
        radius: stem_radius,
    }
    .into();
    CompiledObstacle {
        bounds: Bounds::of_primitive(&body).merged(&Bounds::of_primitive(&stem)),
        parts: vec![primitive_part(&body), primitive_part(&stem)],
        tree: None,
    }
}

fn single(part: Part, bounds: Bounds) -> CompiledObstacle {
    CompiledObstacle {
        parts: vec![part],
        bounds,
        tree: None,
    }
}

/// A primitive as an obstacle part (base frame).
fn primitive_part(primitive: &Primitive) -> Part {
    let (shape, pose) = local_primitive(primitive);
    let long = match primitive {
        Primitive::Sphere(_) => None,
        Primitive::Capsule(c) => ((Vector3::from(c.b) - Vector3::from(c.a)).norm() > LONG_PART_M)
            .then(|| Box::new(LongPart::Segment { flat_ends: false })),
        Primitive::Box(b) => b
            .half_extents
            .iter()
            .any(|h| 2.0 * h > LONG_PART_M)
            .then(|| Box::new(LongPart::Box(*b))),
    };
    Part {
        shape: shape.shared(),
        pose,
        core: Core::of_primitive(primitive),
        long,
    }
}

/// A primitive as a parry shape about a local origin near it (parry works
/// in `f32`), without allocating.
pub enum LocalShape {
    /// Ball centred at the origin.
    Ball(Ball),
    /// Capsule whose segment's midpoint is the origin.
    Capsule(ParryCapsule),
    /// Box centred at the origin, along the frame axes.
    Cuboid(Cuboid),
}

impl LocalShape {
    /// The parry shape.
    pub fn shape(&self) -> &dyn parry3d::shape::Shape {
        match self {
            LocalShape::Ball(s) => s,
            LocalShape::Capsule(s) => s,
            LocalShape::Cuboid(s) => s,
        }
    }

    /// The shape behind a shared pointer (for compiled obstacles).
    fn shared(self) -> SharedShape {
        match self {
            LocalShape::Ball(s) => SharedShape::new(s),
            LocalShape::Capsule(s) => SharedShape::new(s),
            LocalShape::Cuboid(s) => SharedShape::new(s),
        }
    }
}

/// A primitive as a parry shape in a local frame, and that frame's pose in
/// the primitive's frame: the ball's centre, the capsule's midpoint, the
/// box's centre and rotation.
#[inline]
pub fn local_primitive(primitive: &Primitive) -> (LocalShape, Isometry3<f64>) {
    match primitive {
        Primitive::Sphere(s) => (
            LocalShape::Ball(Ball::new(s.radius as f32)),
            Isometry3::translation(s.center[0], s.center[1], s.center[2]),
        ),
        Primitive::Capsule(c) => {
            let (a, b) = (Vector3::from(c.a), Vector3::from(c.b));
            let mid = (a + b) * 0.5;
            (
                LocalShape::Capsule(ParryCapsule::new(
                    to_glam(&(a - mid)),
                    to_glam(&(b - mid)),
                    c.radius as f32,
                )),
                Isometry3::translation(mid.x, mid.y, mid.z),
            )
        }
        Primitive::Box(b) => (
            LocalShape::Cuboid(Cuboid::new(to_glam(&Vector3::from(b.half_extents)))),
            Isometry3::from_parts(
                Translation3::from(Vector3::from(b.center)),
                quaternion::from_xyzw(&b.rotation),
            ),
        ),
    }
}

/// A robot shape in the base frame as a parry shape in a local frame plus
/// that frame's pose.
pub enum RobotPart {
    /// A primitive ([`local_primitive`]) and its local frame's pose.
    Primitive(LocalShape, Isometry3<f64>),
    /// A mesh link's convex hull (shared), the link's pose, and the pose of
    /// the hull's parry shape ([`crate::robot::hull`]).
    Convex(ConvexHull, Isometry3<f64>, Isometry3<f64>),
}

impl RobotPart {
    /// A mesh link's hull (shared; only the poses are composed) at the
    /// link's pose.
    pub fn convex(hull: &ConvexHull, link_pose: &Isometry3<f64>) -> RobotPart {
        RobotPart::Convex(hull.clone(), *link_pose, link_pose * hull.frame())
    }

    /// Build from a base-frame primitive.
    #[inline]
    pub fn primitive(primitive: &Primitive) -> RobotPart {
        let (shape, pose) = local_primitive(primitive);
        RobotPart::Primitive(shape, pose)
    }

    /// The parry shape and its pose.
    pub fn shape_and_pose(&self) -> (&dyn parry3d::shape::Shape, &Isometry3<f64>) {
        match self {
            RobotPart::Primitive(s, p) => (s.shape(), p),
            RobotPart::Convex(hull, _, p) => (hull.shape().as_ref(), p),
        }
    }

    /// A ball (centre, radius; base frame) holding the whole shape.
    pub fn bounding_ball(&self) -> (Vector3<f64>, f64) {
        match self {
            RobotPart::Primitive(shape, pose) => {
                let radius = match shape {
                    LocalShape::Ball(b) => b.radius as f64,
                    LocalShape::Capsule(c) => 0.5 * c.height() as f64 + c.radius as f64,
                    LocalShape::Cuboid(c) => from_glam(c.half_extents).norm(),
                };
                (pose.translation.vector, radius)
            }
            RobotPart::Convex(hull, link_pose, _) => {
                let origin = hull.frame().translation.vector;
                let radius = hull.reach_from(&origin.into());
                ((link_pose * Point3::from(origin)).coords, radius)
            }
        }
    }

    /// Distance (m) to subtract from parry's distance to this part so that
    /// it never exceeds the distance to the link's real geometry.
    pub fn allowance(&self) -> f64 {
        match self {
            RobotPart::Convex(hull, _, _) => hull.allowance(),
            RobotPart::Primitive(..) => 0.0,
        }
    }
}

/// nalgebra f64 vector to parry's glam f32 vector.
pub fn to_glam(v: &Vector3<f64>) -> parry3d::math::Vector {
    parry3d::math::Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// parry's glam f32 vector to nalgebra f64.
pub fn from_glam(v: parry3d::math::Vector) -> Vector3<f64> {
    Vector3::new(v.x as f64, v.y as f64, v.z as f64)
}

/// An f64 pose relative to `origin`, as a parry (f32) pose.
pub fn parry_pose_relative(pose: &Isometry3<f64>, origin: &Vector3<f64>) -> parry3d::math::Pose {
    let t = pose.translation.vector - origin;
    let q = pose.rotation;
    parry3d::math::Pose::from_parts(
        to_glam(&t),
        parry3d::math::Rot3::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32),
    )
}
