//! The convex primitives that robot links and obstacles share: a sphere, an
//! end-point capsule and an oriented box, each a serde struct whose JSON is
//! the wire format of both (`{"center", "radius"}`, `{"a", "b", "radius"}`,
//! `{"center", "half_extents", "rotation"}`), and [`Primitive`], the one
//! place where their maths (placement, reach, signed distance, centre and
//! bounding capsule) is written.
//!
//! Each struct rejects unknown fields itself: serde does not carry an
//! enum's `deny_unknown_fields` into newtype variants.

use super::{point_segment_distance, quaternion};
use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

/// A ball.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Sphere {
    /// Centre (m).
    pub center: [f64; 3],
    /// Radius (m, > 0).
    pub radius: f64,
}

/// The points within `radius` of the segment `a`–`b`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Capsule {
    /// First end of the axis segment.
    pub a: [f64; 3],
    /// Second end of the axis segment.
    pub b: [f64; 3],
    /// Radius (m, > 0).
    pub radius: f64,
}

/// A box with its own axes (named so beside parry's `Cuboid`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OrientedBox {
    /// Centre (m).
    pub center: [f64; 3],
    /// Half the side lengths along the box axes (all > 0).
    pub half_extents: [f64; 3],
    /// Orientation of the box axes, quaternion `[x, y, z, w]`; identity
    /// when absent on input, always written.
    #[serde(default = "identity")]
    pub rotation: [f64; 4],
}

fn identity() -> [f64; 4] {
    quaternion::IDENTITY_XYZW
}

/// The one primitive vocabulary of robot links and obstacles, tagged by
/// `"type"` (`sphere`, `capsule`, `box`).
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum Primitive {
    /// A ball.
    Sphere(Sphere),
    /// An end-point capsule.
    Capsule(Capsule),
    /// An oriented box.
    Box(OrientedBox),
}

impl From<Sphere> for Primitive {
    fn from(s: Sphere) -> Primitive {
        Primitive::Sphere(s)
    }
}

impl From<Capsule> for Primitive {
    fn from(c: Capsule) -> Primitive {
        Primitive::Capsule(c)
    }
}

impl From<OrientedBox> for Primitive {
    fn from(b: OrientedBox) -> Primitive {
        Primitive::Box(b)
    }
}

/// The midpoint of `a` and `b`.
#[inline]
pub fn midpoint(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    ((Vector3::from(*a) + Vector3::from(*b)) * 0.5).into()
}

impl Primitive {
    /// The same primitive expressed in the frame where `pose` maps its
    /// current frame (e.g. link frame to base frame).
    #[inline]
    pub fn transformed(&self, pose: &Isometry3<f64>) -> Primitive {
        let map = |p: &[f64; 3]| -> [f64; 3] { (pose * Point3::from(*p)).coords.into() };
        match self {
            Primitive::Sphere(s) => Primitive::Sphere(Sphere {
                center: map(&s.center),
                radius: s.radius,
            }),
            Primitive::Capsule(c) => Primitive::Capsule(Capsule {
                a: map(&c.a),
                b: map(&c.b),
                radius: c.radius,
            }),
            Primitive::Box(b) => {
                let rotation = pose.rotation * quaternion::from_xyzw(&b.rotation);
                Primitive::Box(OrientedBox {
                    center: map(&b.center),
                    half_extents: b.half_extents,
                    rotation: quaternion::to_xyzw(&rotation),
                })
            }
        }
    }

    /// Farthest distance from `origin` to a point of the primitive (same
    /// frame).
    pub fn reach_from(&self, origin: &[f64; 3]) -> f64 {
        let d = |p: &[f64; 3]| (Point3::from(*p) - Point3::from(*origin)).norm();
        match self {
            Primitive::Sphere(s) => d(&s.center) + s.radius,
            Primitive::Capsule(c) => d(&c.a).max(d(&c.b)) + c.radius,
            Primitive::Box(b) => d(&b.center) + Vector3::from(b.half_extents).norm(),
        }
    }

    /// Signed distance from `p` (same frame) to the surface, negative
    /// inside.
    pub fn signed_distance(&self, p: &[f64; 3]) -> f64 {
        match self {
            Primitive::Sphere(s) => (Point3::from(*p) - Point3::from(s.center)).norm() - s.radius,
            Primitive::Capsule(c) => {
                point_segment_distance(&(*p).into(), &c.a.into(), &c.b.into()) - c.radius
            }
            Primitive::Box(b) => box_signed_distance(b, p),
        }
    }

    /// The centre: of the ball, of the capsule's axis, of the box.
    pub fn center(&self) -> [f64; 3] {
        match self {
            Primitive::Sphere(s) => s.center,
            Primitive::Capsule(c) => midpoint(&c.a, &c.b),
            Primitive::Box(b) => b.center,
        }
    }

    /// Segment and radius `(a, b, r)` of a capsule containing the
    /// primitive: sphere `(c, c, r)`, capsule `(a, b, r)`, box `(c, c, |h|)`
    /// (the same triple as `ConvexHull::bound`).
    #[inline]
    pub fn bounding_capsule(&self) -> ([f64; 3], [f64; 3], f64) {
        match self {
            Primitive::Sphere(s) => (s.center, s.center, s.radius),
            Primitive::Capsule(c) => (c.a, c.b, c.radius),
            Primitive::Box(b) => (b.center, b.center, Vector3::from(b.half_extents).norm()),
        }
    }
}

/// Exact signed distance from `p` to an oriented box.
fn box_signed_distance(b: &OrientedBox, p: &[f64; 3]) -> f64 {
    let q = quaternion::from_xyzw(&b.rotation);
    let local = q.inverse() * (Point3::from(*p) - Point3::from(b.center));
    let h = &b.half_extents;
    let outside = Vector3::from_fn(|i, _| (local[i].abs() - h[i]).max(0.0));
    let inside = (0..3)
        .map(|i| local[i].abs() - h[i])
        .fold(f64::NEG_INFINITY, f64::max);
    if inside > 0.0 {
        outside.norm()
    } else {
        inside
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_signed_distance_is_exact_on_axes_and_corners() {
        let b = Primitive::Box(OrientedBox {
            center: [1.0, 0.0, 0.0],
            half_extents: [0.1, 0.2, 0.3],
            rotation: quaternion::IDENTITY_XYZW,
        });
        assert!((b.signed_distance(&[1.0, 0.0, 0.0]) + 0.1).abs() < 1e-12);
        assert!((b.signed_distance(&[1.5, 0.0, 0.0]) - 0.4).abs() < 1e-12);
        let d = b.signed_distance(&[1.2, 0.3, 0.3]);
        assert!((d - (0.1f64.powi(2) * 2.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn transformed_capsule_keeps_its_radius_and_moves_its_ends() {
        let c = Primitive::Capsule(Capsule {
            a: [0.0, 0.0, -0.1],
            b: [0.0, 0.0, 0.1],
            radius: 0.05,
        });
        let pose = Isometry3::new(
            Vector3::new(1.0, 2.0, 3.0),
            Vector3::x() * std::f64::consts::FRAC_PI_2,
        );
        let Primitive::Capsule(Capsule { a, b, radius }) = c.transformed(&pose) else {
            panic!("a capsule stays a capsule");
        };
        assert_eq!(radius, 0.05);
        assert!(
            (a[1] - 2.1).abs() < 1e-12 && (b[1] - 1.9).abs() < 1e-12,
            "{a:?} {b:?}"
        );
    }

    #[test]
    fn centre_and_bounding_capsule_of_each_primitive() {
        let s = Primitive::Sphere(Sphere {
            center: [1.0, 2.0, 3.0],
            radius: 0.5,
        });
        assert_eq!(s.center(), [1.0, 2.0, 3.0]);
        assert_eq!(
            s.bounding_capsule(),
            ([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 0.5)
        );
        let c = Primitive::Capsule(Capsule {
            a: [0.0; 3],
            b: [0.0, 0.0, 2.0],
            radius: 0.1,
        });
        assert_eq!(c.center(), [0.0, 0.0, 1.0]);
        assert!((c.reach_from(&[0.0; 3]) - 2.1).abs() < 1e-15);
        let b = Primitive::Box(OrientedBox {
            center: [0.0; 3],
            half_extents: [3.0, 4.0, 0.0],
            rotation: quaternion::IDENTITY_XYZW,
        });
        assert_eq!(b.bounding_capsule().2, 5.0);
    }
}
