//! The broad phase: axis-aligned bounding boxes in f64 and the gap between
//! two of them, a lower bound on the distance between what they bound.

use crate::robot::hull_query::closest_segments;
use crate::robot::ShapeGeometry;
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

/// Distance between the segments `p1`–`q1` and `p2`–`q2` (closest points
/// from [`closest_segments`]); points are segments of zero length.
pub fn segment_distance(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> f64 {
    let (x, y) = closest_segments(p1, q1, p2, q2);
    (x - y).norm()
}

/// Bounds of a robot primitive already expressed in the base frame.
pub fn geometry_bounds(geometry: &ShapeGeometry) -> Bounds {
    match geometry {
        ShapeGeometry::Capsule { a, b, radius } => {
            Bounds::capsule(&Vector3::from(*a), &Vector3::from(*b), *radius)
        }
        ShapeGeometry::Sphere { center, radius } => Bounds::ball(&Vector3::from(*center), *radius),
        ShapeGeometry::Box {
            center,
            half_extents,
            rotation,
        } => Bounds::oriented_box(
            &Vector3::from(*center),
            &Vector3::from(*half_extents),
            &super::shape::unit_quaternion(rotation),
        ),
        ShapeGeometry::Convex(hull) => {
            let (a, b, r) = hull.bound();
            Bounds::capsule(&Vector3::from(a), &Vector3::from(b), r)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distance_matches_dense_sampling() {
        let cases = [
            (
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.5, 1.0, -1.0],
                [0.5, 1.0, 1.0],
                1.0,
            ),
            (
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [3.0, 1.0, 0.0],
                1.0,
            ),
            (
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 0.5, 0.0],
                [1.0, 0.5, 0.0],
                0.5,
            ),
            (
                [0.2, 0.3, 0.1],
                [0.2, 0.3, 0.1],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0],
                0.36055512754639896,
            ),
        ];
        for (p1, q1, p2, q2, expect) in cases {
            let (p1, q1, p2, q2) = (
                Vector3::from(p1),
                Vector3::from(q1),
                Vector3::from(p2),
                Vector3::from(q2),
            );
            let d = segment_distance(&p1, &q1, &p2, &q2);
            assert!((d - expect).abs() < 1e-12, "{d} vs {expect}");
            let mut brute = f64::INFINITY;
            for i in 0..=200 {
                for j in 0..=200 {
                    let x = p1 + (q1 - p1) * (i as f64 / 200.0);
                    let y = p2 + (q2 - p2) * (j as f64 / 200.0);
                    brute = brute.min((x - y).norm());
                }
            }
            assert!(d <= brute + 1e-12 && brute - d < 1e-2, "{d} vs {brute}");
        }
    }

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
