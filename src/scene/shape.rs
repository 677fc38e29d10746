//! Conversion of obstacles and robot primitives to parry3d shapes.
//!
//! parry3d works in `f32`; to keep its rounding small, every query places
//! both shapes relative to a local origin near them (see
//! [`super::distance`]), so parts keep their poses in `f64` here.

use super::broadphase::{Bounds, Core};
use super::obstacle::ObstacleShape;
use crate::geometry::quaternion;
use crate::robot::hull::ConvexHull;
use crate::robot::ShapeGeometry;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d::shape::{Ball, Capsule, ConvexPolyhedron, Cuboid, Cylinder, SharedShape};

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
    /// Convex parts (one, or two for a berry).
    pub parts: Vec<Part>,
    /// Bounds of all parts.
    pub bounds: Bounds,
}

/// Compile a validated obstacle; `None` only if parry rejects a hull that
/// passed validation (reported by the caller).
pub fn compile_obstacle(shape: &ObstacleShape) -> Option<CompiledObstacle> {
    let v = |p: &[f64; 3]| Vector3::from(*p);
    match shape {
        ObstacleShape::Sphere { center, radius } => Some(single(
            ball_part(&v(center), *radius),
            Bounds::ball(&v(center), *radius),
        )),
        ObstacleShape::Capsule { a, b, radius } => Some(single(
            capsule_part(&v(a), &v(b), *radius),
            Bounds::capsule(&v(a), &v(b), *radius),
        )),
        ObstacleShape::Cylinder { a, b, radius } => {
            let (a, b) = (v(a), v(b));
            let axis = b - a;
            let rotation =
                UnitQuaternion::rotation_between(&Vector3::y(), &axis).unwrap_or_else(|| {
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
                });
            let pose = Isometry3::from_parts(Translation3::from((a + b) * 0.5), rotation);
            let shape = SharedShape::new(Cylinder::new(0.5 * axis.norm() as f32, *radius as f32));
            // Bounds of a cylinder: the capsule bounds contain it.
            let core = Core::new(a, b, *radius);
            Some(single(
                Part { shape, pose, core },
                Bounds::capsule(&a, &b, *radius),
            ))
        }
        ObstacleShape::Box {
            center,
            half_extents,
            rotation,
        } => {
            let rotation = quaternion::from_xyzw(rotation);
            let h = v(half_extents);
            let pose = Isometry3::from_parts(Translation3::from(v(center)), rotation);
            let shape = SharedShape::new(Cuboid::new(to_glam(&h)));
            let core = Core::new(v(center), v(center), h.norm());
            Some(single(
                Part { shape, pose, core },
                Bounds::oriented_box(&v(center), &h, &rotation),
            ))
        }
        ObstacleShape::Convex { points } => {
            let pts: Vec<Vector3<f64>> = points.iter().map(v).collect();
            let centre = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
            let local: Vec<parry3d::math::Vector> =
                pts.iter().map(|p| to_glam(&(p - centre))).collect();
            let hull = ConvexPolyhedron::from_convex_hull(&local)?;
            let pose =
                Isometry3::from_parts(Translation3::from(centre), UnitQuaternion::identity());
            let reach = pts.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max);
            let core = Core::new(centre, centre, reach);
            Some(single(
                Part {
                    shape: SharedShape::new(hull),
                    pose,
                    core,
                },
                Bounds::points(&pts),
            ))
        }
        ObstacleShape::Berry {
            center,
            radius,
            elongation,
            stem_top,
            stem_radius,
        } => {
            let (c, top) = (v(center), v(stem_top));
            let up = (top - c).normalize();
            let body = if *elongation > 0.0 {
                let (lo, hi) = (c - up * *elongation, c + up * *elongation);
                (
                    capsule_part(&lo, &hi, *radius),
                    Bounds::capsule(&lo, &hi, *radius),
                )
            } else {
                (ball_part(&c, *radius), Bounds::ball(&c, *radius))
            };
            let stem_base = c + up * (*elongation + *radius - *stem_radius).max(0.0);
            let stem = (
                capsule_part(&stem_base, &top, *stem_radius),
                Bounds::capsule(&stem_base, &top, *stem_radius),
            );
            Some(CompiledObstacle {
                bounds: body.1.merged(&stem.1),
                parts: vec![body.0, stem.0],
            })
        }
    }
}

fn single(part: Part, bounds: Bounds) -> CompiledObstacle {
    CompiledObstacle {
        parts: vec![part],
        bounds,
    }
}

fn ball_part(center: &Vector3<f64>, radius: f64) -> Part {
    Part {
        shape: SharedShape::new(Ball::new(radius as f32)),
        pose: Isometry3::translation(center.x, center.y, center.z),
        core: Core::new(*center, *center, radius),
    }
}

/// A capsule part centred at the segment midpoint (small local coordinates).
fn capsule_part(a: &Vector3<f64>, b: &Vector3<f64>, radius: f64) -> Part {
    let mid = (a + b) * 0.5;
    Part {
        shape: SharedShape::new(Capsule::new(
            to_glam(&(a - mid)),
            to_glam(&(b - mid)),
            radius as f32,
        )),
        pose: Isometry3::translation(mid.x, mid.y, mid.z),
        core: Core::new(*a, *b, radius),
    }
}

/// A robot primitive (already in the base frame) as a parry shape in a local
/// frame plus that frame's pose.
pub enum RobotPart {
    /// Ball centred at the pose origin.
    Ball(Ball, Isometry3<f64>),
    /// Capsule about the pose origin.
    Capsule(Capsule, Isometry3<f64>),
    /// Box about the pose origin.
    Cuboid(Cuboid, Isometry3<f64>),
    /// A mesh link's convex hull (shared), the link's pose, and the pose of
    /// the hull's parry shape ([`crate::robot::hull`]).
    Convex(ConvexHull, Isometry3<f64>, Isometry3<f64>),
}

impl RobotPart {
    /// Build from a link-frame primitive and the link's pose; a hull keeps
    /// its shared parry shape and only composes the pose.
    pub fn placed(geometry: &ShapeGeometry, link_pose: &Isometry3<f64>) -> RobotPart {
        match geometry {
            ShapeGeometry::Convex(hull) => {
                RobotPart::Convex(hull.clone(), *link_pose, link_pose * hull.frame())
            }
            other => RobotPart::new(&other.transformed(link_pose)),
        }
    }

    /// Build from a base-frame primitive.
    pub fn new(geometry: &ShapeGeometry) -> RobotPart {
        match geometry {
            ShapeGeometry::Convex(hull) => {
                RobotPart::Convex(hull.clone(), Isometry3::identity(), *hull.frame())
            }
            ShapeGeometry::Sphere { center, radius } => RobotPart::Ball(
                Ball::new(*radius as f32),
                Isometry3::translation(center[0], center[1], center[2]),
            ),
            ShapeGeometry::Capsule { a, b, radius } => {
                let (a, b) = (Vector3::from(*a), Vector3::from(*b));
                let mid = (a + b) * 0.5;
                RobotPart::Capsule(
                    Capsule::new(to_glam(&(a - mid)), to_glam(&(b - mid)), *radius as f32),
                    Isometry3::translation(mid.x, mid.y, mid.z),
                )
            }
            ShapeGeometry::Box {
                center,
                half_extents,
                rotation,
            } => RobotPart::Cuboid(
                Cuboid::new(to_glam(&Vector3::from(*half_extents))),
                Isometry3::from_parts(
                    Translation3::from(Vector3::from(*center)),
                    quaternion::from_xyzw(rotation),
                ),
            ),
        }
    }

    /// The parry shape and its pose.
    pub fn shape_and_pose(&self) -> (&dyn parry3d::shape::Shape, &Isometry3<f64>) {
        match self {
            RobotPart::Ball(s, p) => (s, p),
            RobotPart::Capsule(s, p) => (s, p),
            RobotPart::Cuboid(s, p) => (s, p),
            RobotPart::Convex(hull, _, p) => (hull.shape().as_ref(), p),
        }
    }

    /// Distance (m) to subtract from parry's distance to this part so that
    /// it never exceeds the distance to the link's real geometry.
    pub fn allowance(&self) -> f64 {
        match self {
            RobotPart::Convex(hull, _, _) => hull.allowance(),
            _ => 0.0,
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
