//! An oriented box grown by a radius, and a cheap lower bound on the
//! distance between two of them (or between one and a k-DOP,
//! [`crate::geometry::Slabs::rounded_box_gap`]).
//!
//! The set is `{c + Σ_j t_j h_j a_j : |t_j| ≤ 1} ⊕ ball(r)`: a box (`r =
//! 0`), a capsule (one non-zero half extent along its segment), a ball (no
//! extent). Along any unit direction `u` it spans `u·c ± reach(u)` with
//! `reach(u) = Σ_j |u·a_j| h_j + r`, so the gap between two such spans is
//! a lower bound on the distance between the two sets (a separating axis);
//! [`RoundedBox::gap`] takes the best of both boxes' face axes, a few dozen
//! flops where an exact query (GJK, or a separating-axis test on a mesh)
//! costs microseconds. The scene uses it to drop pairs before the exact
//! query, never as a distance it reports.

use nalgebra::{Isometry3, Matrix3, Vector3};

/// An oriented box grown by `radius` (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoundedBox {
    /// Centre.
    pub centre: Vector3<f64>,
    /// Unit axes (columns), orthonormal.
    pub axes: Matrix3<f64>,
    /// Half extents along the axes (≥ 0).
    pub half: Vector3<f64>,
    /// Radius grown around the box (≥ 0).
    pub radius: f64,
}

impl RoundedBox {
    /// The box of half extents `half` placed by `pose`.
    pub fn placed(pose: &Isometry3<f64>, half: Vector3<f64>) -> RoundedBox {
        RoundedBox {
            centre: pose.translation.vector,
            axes: pose.rotation.to_rotation_matrix().into_inner(),
            half,
            radius: 0.0,
        }
    }

    /// The capsule of segment `a`–`b` and `radius`.
    pub fn capsule(a: &Vector3<f64>, b: &Vector3<f64>, radius: f64) -> RoundedBox {
        let d = b - a;
        let length = d.norm();
        let axes = match d.try_normalize(1e-12) {
            Some(x) => {
                // Any unit vector off `x`'s axis completes a frame.
                let pick = if x.x.abs() < 0.6 {
                    Vector3::x()
                } else {
                    Vector3::y()
                };
                let y = x.cross(&pick).normalize();
                Matrix3::from_columns(&[x, y, x.cross(&y)])
            }
            None => Matrix3::identity(),
        };
        RoundedBox {
            centre: (a + b) * 0.5,
            axes,
            half: Vector3::new(0.5 * length, 0.0, 0.0),
            radius,
        }
    }

    /// The same set seen from the frame `to` maps into.
    pub fn transformed(&self, to: &Isometry3<f64>) -> RoundedBox {
        RoundedBox {
            centre: (to * nalgebra::Point3::from(self.centre)).coords,
            axes: to.rotation.to_rotation_matrix().into_inner() * self.axes,
            ..*self
        }
    }

    /// Half the set's width along the unit direction `u`.
    #[inline]
    pub fn reach(&self, u: &Vector3<f64>) -> f64 {
        (self.axes.transpose() * u).abs().dot(&self.half) + self.radius
    }

    /// A lower bound on the distance between the two sets (negative or
    /// zero when they may touch): the largest gap between their spans
    /// along either box's axes.
    pub fn gap(&self, other: &RoundedBox) -> f64 {
        let d = other.centre - self.centre;
        let along = |u: Vector3<f64>| d.dot(&u).abs() - self.reach(&u) - other.reach(&u);
        (0..3)
            .flat_map(|j| [self.axes.column(j).into(), other.axes.column(j).into()])
            .map(along)
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use parry3d_f64::math::{Pose, Rot3, Vector};
    use parry3d_f64::shape::Cuboid;
    use rand::{Rng, SeedableRng};

    fn pose(rng: &mut impl Rng) -> Isometry3<f64> {
        let t = Vector3::from_fn(|_, _| rng.gen_range(-0.3..0.3));
        let axis = crate::geometry::random_unit(rng);
        let angle = rng.gen_range(0.0..std::f64::consts::PI);
        Isometry3::from_parts(
            Translation3::from(t),
            UnitQuaternion::from_scaled_axis(axis * angle),
        )
    }

    fn parry_pose(p: &Isometry3<f64>) -> Pose {
        let (t, q) = (p.translation.vector, p.rotation);
        Pose::from_parts(
            Vector::new(t.x, t.y, t.z),
            Rot3::from_xyzw(q.i, q.j, q.k, q.w),
        )
    }

    #[test]
    fn boxes_apart_along_an_axis_give_the_closed_form() {
        let a = RoundedBox::placed(&Isometry3::identity(), Vector3::new(0.1, 0.2, 0.3));
        let moved = Isometry3::translation(0.5, 0.05, -0.02);
        let b = RoundedBox {
            radius: 0.01,
            ..RoundedBox::placed(&moved, Vector3::new(0.05, 0.1, 0.1))
        };
        assert!((a.gap(&b) - (0.5 - 0.1 - 0.05 - 0.01)).abs() < 1e-15);
    }

    #[test]
    fn a_capsule_spans_its_segment_and_radius() {
        let c = RoundedBox::capsule(
            &Vector3::new(0.0, 0.0, 0.0),
            &Vector3::new(0.3, 0.4, 0.0),
            0.02,
        );
        let u = Vector3::new(0.6, 0.8, 0.0);
        assert!((c.reach(&u) - (0.25 + 0.02)).abs() < 1e-15);
        assert!((c.reach(&Vector3::z()) - 0.02).abs() < 1e-15);
        assert!((c.centre - Vector3::new(0.15, 0.2, 0.0)).norm() < 1e-15);
    }

    /// Random box pairs: the gap never exceeds parry3d-f64's exact
    /// distance between the cuboids (less both radii), and it is positive
    /// for most pairs that exact query puts apart.
    #[test]
    fn the_gap_is_a_lower_bound_on_the_exact_distance() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut apart, mut seen) = (0, 0);
        for _ in 0..2000 {
            let (pa, pb) = (pose(&mut rng), pose(&mut rng));
            let ha = Vector3::from_fn(|_, _| rng.gen_range(0.005..0.2));
            let hb = Vector3::from_fn(|_, _| rng.gen_range(0.005..0.2));
            let (ra, rb) = (rng.gen_range(0.0..0.03), rng.gen_range(0.0..0.03));
            let a = RoundedBox {
                radius: ra,
                ..RoundedBox::placed(&pa, ha)
            };
            let b = RoundedBox {
                radius: rb,
                ..RoundedBox::placed(&pb, hb)
            };
            let exact = parry3d_f64::query::distance(
                &parry_pose(&pa),
                &Cuboid::new(Vector::new(ha.x, ha.y, ha.z)),
                &parry_pose(&pb),
                &Cuboid::new(Vector::new(hb.x, hb.y, hb.z)),
            )
            .unwrap()
            .distance
                - ra
                - rb;
            let gap = a.gap(&b);
            assert!(gap <= exact + 1e-12, "gap {gap} > exact {exact}");
            assert!((b.gap(&a) - gap).abs() < 1e-12);
            if exact > 0.05 {
                seen += 1;
                apart += usize::from(gap > 0.0);
            }
        }
        assert!(seen > 300 && apart * 10 > seen * 8, "{apart} / {seen}");
    }

    #[test]
    fn transforming_keeps_the_gap() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..100 {
            let at = pose(&mut rng);
            let a = RoundedBox::placed(&at, Vector3::new(0.1, 0.05, 0.02));
            let b = RoundedBox::capsule(
                &Vector3::new(0.2, 0.1, 0.0),
                &Vector3::new(0.4, -0.1, 0.3),
                0.03,
            );
            let to = pose(&mut rng);
            let moved = a.transformed(&to).gap(&b.transformed(&to));
            assert!((moved - a.gap(&b)).abs() < 1e-12);
            let composed = RoundedBox::placed(&(to * at), a.half);
            let c = a.transformed(&to);
            assert!((c.centre - composed.centre).norm() < 1e-12);
            assert!((c.axes - composed.axes).norm() < 1e-12);
        }
    }
}
