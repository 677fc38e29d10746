//! A discrete oriented polytope ("k-DOP"): the intersection of the lower
//! half-spaces `u_k·x ≤ o_k` of a fixed set of directions, each as tight as
//! the points it bounds allow. It contains the convex hull of those points,
//! so the largest separation `max_k (u_k·y − o_k)` of anything `y` from it
//! is a lower bound on `y`'s distance to the hull — a bound that costs a
//! few dozen dot products, against the hull query's walk over hundreds of
//! faces, and that stays within millimetres of the truth where a bounding
//! capsule is centimetres off.
//!
//! The directions are given by the caller in the frame of the points (a
//! link frame): for a hull, the normals of its largest faces, where the
//! bound is exact for points facing them, plus the 26 of a cube's faces,
//! edges and corners ([`cube_directions`]) so that no direction is far from
//! one of them. [`Slabs::placed`] moves them with a rigid motion once per
//! query, so a point or a box costs only the dot products.

use super::rounded_box::RoundedBox;
use nalgebra::{Isometry3, Vector3};

/// The 26 unit directions of a cube's 6 faces, 12 edges and 8 corners.
pub fn cube_directions() -> Vec<Vector3<f64>> {
    let mut out = Vec::with_capacity(26);
    for x in -1i32..=1 {
        for y in -1i32..=1 {
            for z in -1i32..=1 {
                if (x, y, z) != (0, 0, 0) {
                    out.push(Vector3::new(f64::from(x), f64::from(y), f64::from(z)).normalize());
                }
            }
        }
    }
    out
}

/// A k-DOP around a point set, in the points' frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Slabs {
    /// Unit directions.
    normals: Vec<Vector3<f64>>,
    /// `o_k = max_p u_k·p`.
    offsets: Vec<f64>,
}

impl Slabs {
    /// The tightest k-DOP around `points` along `directions` (each
    /// normalised; `None` when there are no points or no directions, or a
    /// number is not finite, or a direction is zero).
    pub fn around(points: &[[f64; 3]], directions: &[Vector3<f64>]) -> Option<Slabs> {
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        if points.is_empty()
            || directions.is_empty()
            || !points.iter().all(|p| finite(p))
            || !directions.iter().all(|u| finite(u.as_slice()))
        {
            return None;
        }
        let normals = directions
            .iter()
            .map(|u| u.try_normalize(1e-12))
            .collect::<Option<Vec<_>>>()?;
        let offsets = normals
            .iter()
            .map(|u| {
                points
                    .iter()
                    .map(|p| u.dot(&Vector3::from(*p)))
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect();
        Some(Slabs { normals, offsets })
    }

    /// A polytope given by no half-space yet (every gap is −∞), to which
    /// [`Slabs::add_plane`] adds them.
    pub fn unbounded() -> Slabs {
        Slabs {
            normals: Vec::new(),
            offsets: Vec::new(),
        }
    }

    /// Add the half-space `u·x ≤ offset` (`u` unit length, from the caller):
    /// the polytope is cut by it, so it must hold whatever the gaps bound.
    pub fn add_plane(&mut self, u: Vector3<f64>, offset: f64) {
        self.normals.push(u);
        self.offsets.push(offset);
    }

    /// Number of directions.
    pub fn len(&self) -> usize {
        self.normals.len()
    }

    /// Whether there are no directions (never for [`Slabs::around`]).
    pub fn is_empty(&self) -> bool {
        self.normals.is_empty()
    }

    /// The same polytope moved by the rigid motion `pose`.
    pub fn placed(&self, pose: &Isometry3<f64>) -> Slabs {
        let t = pose.translation.vector;
        let normals: Vec<Vector3<f64>> = self.normals.iter().map(|u| pose.rotation * u).collect();
        let offsets = self
            .offsets
            .iter()
            .zip(&normals)
            .map(|(o, u)| o + u.dot(&t))
            .collect();
        Slabs { normals, offsets }
    }

    /// `max_k (u_k·p − o_k)`: a lower bound on the distance from `p` to
    /// anything inside (≤ 0 when `p` is inside the polytope).
    #[inline]
    pub fn point_gap(&self, p: &Vector3<f64>) -> f64 {
        self.max_over(|u| u.dot(p))
    }

    /// A lower bound on the distance from the segment `a`–`b` to anything
    /// inside: `max_k (min(u_k·a, u_k·b) − o_k)`.
    #[inline]
    pub fn segment_gap(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        if a == b {
            return self.point_gap(a);
        }
        self.max_over(|u| u.dot(a).min(u.dot(b)))
    }

    /// A lower bound on the distance from the axis-aligned box `min`–`max`
    /// to anything inside: `max_k (min_{y ∈ box} u_k·y − o_k)`.
    #[inline]
    pub fn box_gap(&self, min: &Vector3<f64>, max: &Vector3<f64>) -> f64 {
        let centre = (min + max) * 0.5;
        let half = (max - min) * 0.5;
        self.max_over(|u| u.dot(&centre) - u.abs().dot(&half))
    }

    /// `max_k (low(u_k) − o_k)`.
    /// Lower bound on the distance from the k-DOP to `b` (in the k-DOP's
    /// frame): the largest gap between their extents along the k-DOP's
    /// directions.
    #[inline]
    pub fn rounded_box_gap(&self, b: &RoundedBox) -> f64 {
        self.max_over(|u| u.dot(&b.centre) - b.reach(u))
    }

    #[inline]
    fn max_over(&self, low: impl Fn(&Vector3<f64>) -> f64) -> f64 {
        self.normals
            .iter()
            .zip(&self.offsets)
            .map(|(u, o)| low(u) - o)
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::random_unit;
    use nalgebra::{Translation3, UnitQuaternion};
    use rand::{Rng, SeedableRng};

    /// The 8 corners of the cube `[-h, h]³` (bit k of the index: the sign
    /// of coordinate k).
    fn cube(h: f64) -> Vec<[f64; 3]> {
        (0..8)
            .map(|i: u32| [0, 1, 2].map(|k| if i >> k & 1 == 1 { h } else { -h }))
            .collect()
    }

    #[test]
    fn the_directions_are_unit_and_distinct() {
        let d = cube_directions();
        assert_eq!(d.len(), 26);
        for (i, u) in d.iter().enumerate() {
            assert!((u.norm() - 1.0).abs() < 1e-15);
            for v in &d[..i] {
                assert!((u - v).norm() > 0.5);
            }
        }
    }

    #[test]
    fn a_cube_is_exact_on_its_faces_and_a_bound_at_its_corners() {
        let slabs = Slabs::around(&cube(1.0), &cube_directions()).unwrap();
        assert!((slabs.point_gap(&Vector3::new(3.0, 0.2, -0.4)) - 2.0).abs() < 1e-12);
        assert!(slabs.point_gap(&Vector3::new(0.5, 0.5, 0.5)) < 0.0);
        // Off a corner: the corner normal gives (3·2 - 3)/√3 = √3, the exact
        // distance √3.
        let corner = slabs.point_gap(&Vector3::new(2.0, 2.0, 2.0));
        assert!((corner - 3f64.sqrt()).abs() < 1e-12, "{corner}");
        let d = cube_directions();
        assert!(Slabs::around(&[], &d).is_none());
        assert!(Slabs::around(&cube(1.0), &[]).is_none());
        assert!(Slabs::around(&[[f64::NAN, 0.0, 0.0]], &d).is_none());
        assert!(Slabs::around(&cube(1.0), &[Vector3::zeros()]).is_none());
        // Planes added one by one: no plane bounds nothing, one is its
        // half-space.
        let mut planes = Slabs::unbounded();
        assert_eq!(planes.point_gap(&Vector3::zeros()), f64::NEG_INFINITY);
        planes.add_plane(Vector3::z(), 0.5);
        assert!((planes.point_gap(&Vector3::new(3.0, -2.0, 1.25)) - 0.75).abs() < 1e-15);
    }

    /// Random point sets moved by random poses: the gap of a point, a
    /// segment or a box never exceeds the distance from a point of it to a
    /// point inside the hull (a random convex combination of the set).
    #[test]
    fn gaps_never_exceed_the_distance_to_any_point_inside() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..200 {
            let points: Vec<[f64; 3]> = (0..12)
                .map(|_| {
                    [
                        rng.gen_range(-0.2..0.2),
                        rng.gen_range(-0.1..0.1),
                        rng.gen_range(-0.05..0.3),
                    ]
                })
                .collect();
            let pose = Isometry3::from_parts(
                Translation3::new(rng.gen(), rng.gen(), rng.gen()),
                UnitQuaternion::from_scaled_axis(random_unit(&mut rng) * rng.gen_range(0.0..3.0)),
            );
            let mut directions = cube_directions();
            directions.push(random_unit(&mut rng) * 3.0);
            let slabs = Slabs::around(&points, &directions).unwrap().placed(&pose);
            let world: Vec<Vector3<f64>> = points
                .iter()
                .map(|p| (pose * nalgebra::Point3::from(*p)).coords)
                .collect();
            // Points inside the hull: random convex combinations.
            let inside = |rng: &mut rand_chacha::ChaCha8Rng| {
                let w: Vec<f64> = world.iter().map(|_| rng.gen::<f64>()).collect();
                let s: f64 = w.iter().sum();
                world
                    .iter()
                    .zip(&w)
                    .map(|(p, w)| p * (w / s))
                    .sum::<Vector3<f64>>()
            };
            for _ in 0..20 {
                let y = pose.translation.vector + random_unit(&mut rng) * rng.gen_range(0.0..0.6);
                let x = inside(&mut rng);
                assert!(slabs.point_gap(&y) <= (y - x).norm() + 1e-12);
                assert!(slabs.point_gap(&x) <= 1e-12, "a point inside is inside");
                let b = y + random_unit(&mut rng) * 0.1;
                let on_segment = y + (b - y) * rng.gen::<f64>();
                assert!(slabs.segment_gap(&y, &b) <= (on_segment - x).norm() + 1e-12);
                let h = Vector3::new(rng.gen(), rng.gen(), rng.gen()) * 0.05;
                let in_box = y + h.component_mul(&Vector3::new(
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                ));
                assert!(slabs.box_gap(&(y - h), &(y + h)) <= (in_box - x).norm() + 1e-12);
            }
        }
    }
}
