//! Exact `f64` signed distance between a [`ConvexHull`] and a segment (a
//! point when both ends coincide): the query behind every clearance between
//! a mesh link and a ball or capsule obstacle (berries, stems).
//!
//! - Separated: the segment is clipped against every face plane; when
//!   nothing is left, the distance is the smallest segment-triangle
//!   distance over the faces that can see the segment (a face whose plane
//!   has the whole segment behind it cannot hold the closest point),
//!   starting from the face of largest separation and skipping faces whose
//!   lower bound (plane distance, distance to a ball around the face)
//!   already reaches the best distance found. Exact.
//! - Overlapping: the separating-axis bound `max_f min_{y ∈ segment}
//!   (n_f·y − d_f)` over the face normals, a lower bound on the signed
//!   distance (the true signed distance is the maximum of the separation
//!   over *all* directions), so a penetration is never understated.
//!
//! parry3d's `f32` GJK was measured on these hulls (dense point clouds of
//! near-coplanar vertices) to err by up to 1 cm either way, which is why the
//! robot side of the clearance does not use it.

use super::hull::{closest_on_triangle, ConvexHull};
use nalgebra::Vector3;

/// The closest features of a hull and a segment (hull frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HullContact {
    /// Signed distance (m) from the hull to the segment; for overlaps, the
    /// separating-axis lower bound (≤ 0).
    pub distance: f64,
    /// Witness point on the hull's surface.
    pub point_hull: Vector3<f64>,
    /// Witness point on the segment.
    pub point_segment: Vector3<f64>,
    /// Unit normal from the segment towards the hull: moving the hull
    /// along it increases the distance.
    pub normal: Vector3<f64>,
}

impl ConvexHull {
    /// Signed distance and witnesses between the hull and the segment
    /// `a`–`b` (hull frame).
    pub fn segment_contact(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> HullContact {
        self.segment_contact_within(a, b, f64::INFINITY)
            .unwrap_or_else(|| self.separated(a, b, 0))
    }

    /// [`ConvexHull::segment_contact`] when the distance is below `limit`;
    /// `None` as soon as one face plane separates the segment by `limit` or
    /// more (a lower bound on the distance), without the rest of the work.
    pub fn segment_contact_within(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        limit: f64,
    ) -> Option<HullContact> {
        let planes = self.planes();
        let mut best_face = 0;
        let mut best_sep = f64::NEG_INFINITY;
        let (mut t_lo, mut t_hi) = (0.0f64, 1.0f64);
        for (f, (n, d)) in planes.iter().enumerate() {
            let (da, db) = (n.dot(a) - d, n.dot(b) - d);
            let sep = da.min(db);
            if sep >= limit {
                return None;
            }
            if sep > best_sep {
                best_sep = sep;
                best_face = f;
            }
            clip(da, db, &mut t_lo, &mut t_hi);
        }
        if t_lo <= t_hi && best_sep <= 0.0 {
            return Some(self.overlap(a, b, best_face, best_sep));
        }
        Some(self.separated(a, b, best_face))
    }

    fn overlap(&self, a: &Vector3<f64>, b: &Vector3<f64>, face: usize, sep: f64) -> HullContact {
        let (n, d) = self.planes()[face];
        let deepest = if n.dot(a) <= n.dot(b) { *a } else { *b };
        HullContact {
            distance: sep,
            point_hull: deepest - n * (n.dot(&deepest) - d),
            point_segment: deepest,
            normal: -n,
        }
    }

    /// Exact distance for a segment outside the hull: starting from the
    /// face of largest separation, every face that can see the segment is
    /// tried unless a lower bound on its distance (its plane distance, then
    /// the distance to a ball around it) already reaches the best found.
    fn separated(&self, a: &Vector3<f64>, b: &Vector3<f64>, first: usize) -> HullContact {
        let vertices = self.vertices();
        let triangle = |f: usize| self.faces()[f].map(|i| Vector3::from(vertices[i as usize]));
        let [p, q, r] = triangle(first);
        let (x, y) = segment_triangle_closest(a, b, &p, &q, &r);
        let mut best = ((y - x).norm(), x, y, first);
        for (f, ((n, d), (centre, radius))) in
            self.planes().iter().zip(self.face_balls()).enumerate()
        {
            let (da, db) = (n.dot(a) - d, n.dot(b) - d);
            let plane = if da > 0.0 && db > 0.0 {
                da.min(db)
            } else {
                0.0
            };
            if f == first || da.max(db) <= 0.0 || plane >= best.0 {
                continue;
            }
            let (_, near) = closest_segments(centre, centre, a, b);
            if (near - centre).norm() - radius >= best.0 {
                continue;
            }
            let [p, q, r] = triangle(f);
            let (x, y) = segment_triangle_closest(a, b, &p, &q, &r);
            let dist = (y - x).norm();
            if dist < best.0 {
                best = (dist, x, y, f);
            }
        }
        let (distance, x, y, face) = best;
        HullContact {
            distance,
            point_hull: x,
            point_segment: y,
            normal: (x - y)
                .try_normalize(1e-15)
                .unwrap_or_else(|| -self.planes()[face].0),
        }
    }
}

/// Cyrus–Beck clipping of the segment parameter range by one half-space
/// (`da`, `db`: signed plane distances of the ends, inside ≤ 0).
fn clip(da: f64, db: f64, t_lo: &mut f64, t_hi: &mut f64) {
    if da > 0.0 && db > 0.0 {
        *t_lo = 1.0;
        *t_hi = 0.0;
    } else if da > 0.0 {
        *t_lo = t_lo.max(da / (da - db));
    } else if db > 0.0 {
        *t_hi = t_hi.min(da / (da - db));
    }
}

/// Distance between the segment `a`–`b` and the triangle `p, q, r`, for a
/// segment that does not pierce the triangle's interior.
pub fn segment_triangle_distance(
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    p: &Vector3<f64>,
    q: &Vector3<f64>,
    r: &Vector3<f64>,
) -> f64 {
    let (x, y) = segment_triangle_closest(a, b, p, q, r);
    (x - y).norm()
}

/// Closest points `(on triangle, on segment)` between the segment `a`–`b`
/// and the triangle `p, q, r`, for a segment that does not pierce the
/// triangle's interior: the best of both ends against the triangle and the
/// segment against the three edges.
fn segment_triangle_closest(
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    p: &Vector3<f64>,
    q: &Vector3<f64>,
    r: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let xa = closest_on_triangle(a, p, q, r);
    let mut best = ((xa - a).norm(), xa, *a);
    if a != b {
        let xb = closest_on_triangle(b, p, q, r);
        let candidates = [
            (xb, *b),
            closest_segments(p, q, a, b),
            closest_segments(q, r, a, b),
            closest_segments(r, p, a, b),
        ];
        for (x, y) in candidates {
            let d = (x - y).norm();
            if d < best.0 {
                best = (d, x, y);
            }
        }
    }
    (best.1, best.2)
}

/// Closest points between segments `p1`–`q1` and `p2`–`q2` (Ericson,
/// "Real-Time Collision Detection" §5.1.9).
pub fn closest_segments(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    const EPS: f64 = 1e-18;
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > EPS {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (p1 + d1 * s, p2 + d2 * t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn cube() -> ConvexHull {
        let mut v = Vec::new();
        for x in [-0.1, 0.1] {
            for y in [-0.1, 0.1] {
                for z in [-0.1, 0.1] {
                    v.push([x, y, z]);
                }
            }
        }
        ConvexHull::of_points(&v).unwrap()
    }

    /// Signed distance from a point to the axis-aligned cube of half side h.
    fn cube_sd(p: &Vector3<f64>, h: f64) -> f64 {
        let q = p.map(|c| c.abs() - h);
        let outside = q.map(|c| c.max(0.0)).norm();
        outside + q.max().min(0.0)
    }

    #[test]
    fn point_and_segment_distances_match_the_cube_closed_form() {
        let hull = cube();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..2000 {
            let p = Vector3::from_fn(|_, _| rng.gen_range(-0.3..0.3));
            let c = hull.segment_contact(&p, &p);
            let exact = cube_sd(&p, 0.1);
            assert!(
                (c.distance - exact).abs() < 1e-6,
                "{p:?}: {} vs {exact}",
                c.distance
            );
            if exact > 0.0 {
                assert!(((c.point_segment - c.point_hull).norm() - exact).abs() < 1e-6);
            }
            // A segment: compare with dense sampling of the segment.
            let q = Vector3::from_fn(|_, _| rng.gen_range(-0.3..0.3));
            let s = hull.segment_contact(&p, &q);
            let sampled = (0..=2000)
                .map(|k| cube_sd(&(p + (q - p) * (k as f64 / 2000.0)), 0.1))
                .fold(f64::INFINITY, f64::min);
            // The sampled minimum is within one step of the true one (the
            // signed distance is 1-Lipschitz).
            let step = (q - p).norm() / 2000.0;
            assert!(
                s.distance <= sampled + 1e-6,
                "{p:?}-{q:?}: {} > {sampled}",
                s.distance
            );
            if s.distance > 0.0 {
                assert!(
                    s.distance >= sampled - step - 1e-6,
                    "{p:?}-{q:?}: {} vs {sampled}",
                    s.distance
                );
            } else {
                assert!(
                    sampled <= step + 1e-6,
                    "overlap reported, sampled {sampled}"
                );
            }
        }
    }

    #[test]
    fn closest_segments_handles_parallel_and_crossing() {
        let z = Vector3::zeros;
        let (x, y) = closest_segments(
            &z(),
            &Vector3::x(),
            &Vector3::new(0.5, 1.0, -1.0),
            &Vector3::new(0.5, 1.0, 1.0),
        );
        assert!(
            (x - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-12
                && (y - Vector3::new(0.5, 1.0, 0.0)).norm() < 1e-12
        );
        let (x, y) = closest_segments(
            &z(),
            &Vector3::x(),
            &Vector3::new(0.0, 1.0, 0.0),
            &Vector3::new(1.0, 1.0, 0.0),
        );
        assert!(((x - y).norm() - 1.0).abs() < 1e-12);
    }
}
