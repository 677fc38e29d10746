//! The broad phase: axis-aligned bounding boxes in f64 and the gap between
//! two of them, a lower bound on the distance between what they bound; and
//! the capsule around a shape ([`Core`]), whose gap is a tighter bound.

use crate::geometry::{quaternion, segment_distance, Primitive};
use nalgebra::{UnitQuaternion, Vector3};

/// An axis-aligned box `[min, max]` in the base frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Lowest corner.
    pub min: Vector3<f64>,
    /// Highest corner.
    pub max: Vector3<f64>,
}

impl Bounds {
    /// The box around a ball.
    pub fn ball(center: &Vector3<f64>, radius: f64) -> Bounds {
        let r = Vector3::repeat(radius);
        Bounds {
            min: center - r,
            max: center + r,
        }
    }

    /// The box around a capsule (segment `a`–`b`, radius).
    pub fn capsule(a: &Vector3<f64>, b: &Vector3<f64>, radius: f64) -> Bounds {
        let r = Vector3::repeat(radius);
        Bounds {
            min: a.inf(b) - r,
            max: a.sup(b) + r,
        }
    }

    /// The box around an oriented box.
    pub fn oriented_box(
        center: &Vector3<f64>,
        half_extents: &Vector3<f64>,
        rotation: &UnitQuaternion<f64>,
    ) -> Bounds {
        let m = rotation.to_rotation_matrix();
        let reach = m.matrix().abs() * half_extents;
        Bounds {
            min: center - reach,
            max: center + reach,
        }
    }

    /// The box around a primitive.
    #[inline]
    pub fn of_primitive(primitive: &Primitive) -> Bounds {
        let v = Vector3::from;
        match primitive {
            Primitive::Sphere(s) => Bounds::ball(&v(s.center), s.radius),
            Primitive::Capsule(c) => Bounds::capsule(&v(c.a), &v(c.b), c.radius),
            Primitive::Box(b) => Bounds::oriented_box(
                &v(b.center),
                &v(b.half_extents),
                &quaternion::from_xyzw(&b.rotation),
            ),
        }
    }

    /// The box around a set of points.
    pub fn points<'a>(points: impl IntoIterator<Item = &'a Vector3<f64>>) -> Bounds {
        let mut it = points.into_iter();
        let first = it.next().copied().unwrap_or_else(Vector3::zeros);
        it.fold(
            Bounds {
                min: first,
                max: first,
            },
            |b, p| Bounds {
                min: b.min.inf(p),
                max: b.max.sup(p),
            },
        )
    }

    /// The smallest box around both.
    pub fn merged(&self, other: &Bounds) -> Bounds {
        Bounds {
            min: self.min.inf(&other.min),
            max: self.max.sup(&other.max),
        }
    }

    /// Euclidean gap between the two boxes (0 when they overlap): a lower
    /// bound on the distance between any shapes inside them.
    #[inline]
    pub fn gap(&self, other: &Bounds) -> f64 {
        let mut sum = 0.0;
        for i in 0..3 {
            let d = (other.min[i] - self.max[i])
                .max(self.min[i] - other.max[i])
                .max(0.0);
            sum += d * d;
        }
        sum.sqrt()
    }

    /// Distance from the point `p` to the box (0 inside).
    pub fn point_gap(&self, p: &Vector3<f64>) -> f64 {
        self.gap(&Bounds { min: *p, max: *p })
    }
}

/// A capsule (segment `a`–`b` swept by `radius`) that contains a shape: the
/// distance between two cores, less both radii, is a lower bound on the
/// distance between the shapes (exact for balls and capsules).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Core {
    /// First end of the segment.
    pub a: Vector3<f64>,
    /// Second end of the segment.
    pub b: Vector3<f64>,
    /// Radius around the segment.
    pub radius: f64,
}

impl Core {
    /// A core from its segment and radius.
    pub fn new(a: Vector3<f64>, b: Vector3<f64>, radius: f64) -> Core {
        Core { a, b, radius }
    }

    /// The core around a primitive: its bounding capsule.
    #[inline]
    pub fn of_primitive(primitive: &Primitive) -> Core {
        let (a, b, radius) = primitive.bounding_capsule();
        Core::new(Vector3::from(a), Vector3::from(b), radius)
    }

    /// Lower bound on the distance between shapes inside `self` and `other`.
    #[inline]
    pub fn gap(&self, other: &Core) -> f64 {
        segment_distance(&self.a, &self.b, &other.a, &other.b) - self.radius - other.radius
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_is_euclidean_between_separated_boxes_and_zero_when_overlapping() {
        let a = Bounds::ball(&Vector3::zeros(), 1.0);
        let b = Bounds::ball(&Vector3::new(4.0, 5.0, 0.0), 1.0);
        assert!((a.gap(&b) - (4.0f64 + 9.0).sqrt()).abs() < 1e-12);
        let c = Bounds::ball(&Vector3::new(1.5, 0.0, 0.0), 1.0);
        assert_eq!(a.gap(&c), 0.0);
        let rotated = Bounds::oriented_box(
            &Vector3::zeros(),
            &Vector3::new(1.0, 0.0001, 0.0001),
            &UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_4),
        );
        assert!((rotated.max.x - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-3);
    }
}
