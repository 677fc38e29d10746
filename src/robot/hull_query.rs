//! Exact `f64` signed distance between a [`ConvexHull`] and a segment (a
//! point when both ends coincide): the query behind every clearance between
//! a mesh link and a ball or capsule obstacle (berries, stems).
//!
//! - **Local, certified** (almost every query): start at the face facing
//!   the segment ([`super::hull_topology`]) and climb to neighbouring faces
//!   while the segment's separation from the face plane grows (again from
//!   the best of a few seed faces when that shows no separation); a plane that
//!   separates by the caller's limit ends the query. With the segment
//!   outside, the closest triangle among the faces around the climbed face
//!   is the answer when the separating axis through its witness points
//!   proves it: the hull's support along that axis (every vertex) leaves a
//!   lower bound within [`CERTIFICATE_GAP_M`] of the distance found. A
//!   failed proof adds the faces around the offending vertex and retries.
//! - **Full scan** (overlaps, and whatever the walk cannot certify): the
//!   segment is clipped against every face plane; when nothing is left,
//!   the distance is the smallest segment-triangle distance over the faces
//!   that can see the segment (a face whose plane has the whole segment
//!   behind it cannot hold the closest point), tried in increasing order of
//!   a lower bound (plane distance, distance to a ball around the face)
//!   until the bound reaches the best distance. Exact.
//! - **Overlapping**: the separating-axis bound `max_f min_{y ∈ segment}
//!   (n_f·y − d_f)` over the face normals, a lower bound on the signed
//!   distance (the true signed distance is the maximum of the separation
//!   over *all* directions), so a penetration is never understated.
//!
//! `tests/robot_hull_query.rs` checks the local answer against the full
//! scan and the brute-force minimum over every triangle on the Panda's
//! hulls.
//!
//! parry3d's `f32` GJK was measured on these hulls (dense point clouds of
//! near-coplanar vertices) to err by up to 1 cm either way, which is why the
//! robot side of the clearance does not use it.

use super::hull::{closest_on_triangle, ConvexHull};
use crate::geometry::closest_segments;
use nalgebra::Vector3;
use smallvec::SmallVec;

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
    /// `a`–`b` (hull frame); the distance is -∞ (never a clearance) when an
    /// end is not finite.
    pub fn segment_contact(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> HullContact {
        self.segment_contact_within(a, b, f64::INFINITY)
            .unwrap_or(HullContact {
                distance: f64::INFINITY,
                point_hull: *a,
                point_segment: *a,
                normal: Vector3::z(),
            })
    }

    /// [`ConvexHull::segment_contact`] when the distance is below `limit`,
    /// `None` otherwise. The local walk answers almost every query
    /// ([`ConvexHull::local_contact`]); what it cannot certify (overlaps,
    /// the rare walk that stops short) goes to the full scan
    /// ([`ConvexHull::segment_contact_scan`]).
    pub fn segment_contact_within(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        limit: f64,
    ) -> Option<HullContact> {
        if !a.iter().chain(b.iter()).all(|c| c.is_finite()) {
            return Some(HullContact {
                distance: f64::NEG_INFINITY,
                point_hull: *a,
                point_segment: *a,
                normal: Vector3::z(),
            });
        }
        match self.local_contact(a, b, limit) {
            Local::Far => None,
            Local::Found(c) => (c.distance < limit).then_some(c),
            Local::Unsure => self.segment_contact_scan(a, b, limit),
        }
    }

    /// The reference query: every face plane scanned (Cyrus–Beck clipping
    /// tells overlap from separation), then the exact distance over every
    /// face that can see the segment. `None` when the distance is `limit` or
    /// more: at once when one face plane separates the segment by `limit`,
    /// and without finishing once every candidate face is ruled out.
    pub fn segment_contact_scan(
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
        self.separated(a, b, best_face, limit)
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

    /// Exact distance for a segment outside the hull, when below `limit`
    /// (`None` otherwise), over every face, starting from face `first`.
    fn separated(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        first: usize,
        limit: f64,
    ) -> Option<HullContact> {
        let all = (0..self.faces().len() as u32).filter(|&f| f as usize != first);
        let (distance, x, y, face) = self.closest_triangle(a, b, first, all, limit)?;
        Some(HullContact {
            distance,
            point_hull: x,
            point_segment: y,
            normal: (x - y)
                .try_normalize(1e-15)
                .unwrap_or_else(|| -self.planes()[face].0),
        })
    }

    /// The closest triangle to a segment outside the hull among `first`
    /// and `others`, when closer than `limit`: `(distance, point on the
    /// hull, point on the segment, face)`. The triangle of `first` gives a
    /// first distance; every other face that can see the segment (a face
    /// whose plane has the whole segment behind it cannot hold the closest
    /// point) and whose lower bound (its plane distance, then the distance
    /// to a ball around it) is below the best so far is a candidate, and
    /// candidates are tried in increasing order of bound until the bound
    /// reaches the best distance.
    fn closest_triangle(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        first: usize,
        others: impl Iterator<Item = u32>,
        limit: f64,
    ) -> Option<(f64, Vector3<f64>, Vector3<f64>, usize)> {
        let vertices = self.vertices();
        let triangle = |f: usize| self.faces()[f].map(|i| Vector3::from(vertices[i as usize]));
        let [p, q, r] = triangle(first);
        let (x, y) = segment_triangle_closest(a, b, &p, &q, &r);
        let mut best = ((y - x).norm(), x, y, first);
        let cutoff = best.0.min(limit);
        let (planes, balls) = (self.planes(), self.face_balls());
        let mut candidates: SmallVec<[(f64, usize); STACK_FACES]> = SmallVec::new();
        for f in others.map(|f| f as usize) {
            let ((n, d), (centre, radius)) = (planes[f], balls[f]);
            let (da, db) = (n.dot(a) - d, n.dot(b) - d);
            let plane = if da > 0.0 && db > 0.0 {
                da.min(db)
            } else {
                0.0
            };
            if da.max(db) <= 0.0 || plane >= cutoff {
                continue;
            }
            let (_, near) = closest_segments(&centre, &centre, a, b);
            let bound = plane.max((near - centre).norm() - radius);
            if bound < cutoff {
                candidates.push((bound, f));
            }
        }
        candidates.sort_unstable_by(|u, v| u.0.total_cmp(&v.0).then(u.1.cmp(&v.1)));
        for (bound, f) in candidates {
            if bound >= best.0.min(limit) {
                break;
            }
            let [p, q, r] = triangle(f);
            let (x, y) = segment_triangle_closest(a, b, &p, &q, &r);
            let dist = (y - x).norm();
            if dist < best.0 {
                best = (dist, x, y, f);
            }
        }
        (best.0 < limit).then_some(best)
    }

    /// The query by a local walk, certified: from the best of the seed
    /// faces, climb to neighbouring faces while the segment's separation
    /// from the face plane grows (`Far` as soon as one plane separates it
    /// by `limit`). With a positive separation the segment is outside; the
    /// closest triangle among the faces around the climbed face is then
    /// exact when the separating axis through its witnesses (the hull's
    /// support along it over every vertex) proves a lower bound within
    /// [`CERTIFICATE_GAP_M`] of it. A failed proof adds the faces around
    /// the vertex that broke it and tries again; `Unsure` leaves the
    /// query to the full scan.
    fn local_contact(&self, a: &Vector3<f64>, b: &Vector3<f64>, limit: f64) -> Local {
        let topology = self.topology();
        let planes = self.planes();
        let separation = |f: usize| {
            let (n, d) = planes[f];
            (n.dot(a) - d).min(n.dot(b) - d)
        };
        // Climb to neighbouring faces while the separation grows (stopping
        // once it reaches the limit).
        let climb = |mut face: usize, mut best: f64| {
            for _ in 0..MAX_WALK_STEPS {
                if best >= limit {
                    break;
                }
                let Some(next) = topology
                    .face_neighbours
                    .get(face)
                    .iter()
                    .map(|&g| (g as usize, separation(g as usize)))
                    .max_by(|u, v| u.1.total_cmp(&v.1))
                    .filter(|&(_, sep)| sep > best)
                else {
                    break;
                };
                (face, best) = next;
            }
            (face, best)
        };
        // From the face facing the segment (most far pairs end there), then,
        // if that climb does not show the segment outside, from the best seed.
        let (ca, cb, _) = self.bound();
        let towards = (a + b - Vector3::from(ca) - Vector3::from(cb)) * 0.5;
        let start = topology.seed_towards(&towards) as usize;
        let (mut face, mut best) = climb(start, separation(start));
        if best <= 0.0 {
            let seed = topology
                .seeds
                .iter()
                .map(|&f| (f as usize, separation(f as usize)))
                .max_by(|u, v| u.1.total_cmp(&v.1));
            if let Some((f, sep)) = seed.filter(|&(_, sep)| sep > best) {
                (face, best) = climb(f, sep);
            }
        }
        if best >= limit {
            return Local::Far;
        }
        if best <= 0.0 {
            return Local::Unsure;
        }
        let mut around: SmallVec<[u32; STACK_FACES]> =
            SmallVec::from_slice(topology.face_neighbours.get(face));
        for _ in 0..MAX_CERTIFY_ROUNDS {
            let Some((distance, x, y, _)) =
                self.closest_triangle(a, b, face, around.iter().copied(), f64::INFINITY)
            else {
                return Local::Unsure;
            };
            let n = (y - x) / distance;
            let (vertex, support) = self.support(&n);
            let lower = n.dot(a).min(n.dot(b)) - support;
            if lower >= limit {
                return Local::Far;
            }
            if lower >= distance - CERTIFICATE_GAP_M {
                return Local::Found(HullContact {
                    distance,
                    point_hull: x,
                    point_segment: y,
                    normal: -n,
                });
            }
            for &g in topology.vertex_faces.get(vertex) {
                if g as usize != face && !around.contains(&g) {
                    around.push(g);
                }
            }
        }
        Local::Unsure
    }

    /// The vertex farthest along `n` and its projection.
    fn support(&self, n: &Vector3<f64>) -> (usize, f64) {
        self.vertices()
            .iter()
            .map(|v| n.x * v[0] + n.y * v[1] + n.z * v[2])
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |best, (i, h)| {
                if h > best.1 {
                    (i, h)
                } else {
                    best
                }
            })
    }
}

/// What the local walk found.
enum Local {
    /// The distance is `limit` or more.
    Far,
    /// The exact contact, certified.
    Found(HullContact),
    /// No certificate: the full scan decides.
    Unsure,
}

/// Faces a query keeps on the stack (the faces around a climbed face and
/// the candidates of the local walk are a few dozen at most; the full scan's
/// spill to the heap): one query is about a microsecond, of which two heap
/// allocations were a tenth.
const STACK_FACES: usize = 48;

/// Face-to-face steps of the local walk before it stops where it is.
const MAX_WALK_STEPS: usize = 64;

/// Rounds of adding faces around a vertex that breaks the certificate
/// before the local query gives up to the full scan.
const MAX_CERTIFY_ROUNDS: usize = 4;

/// How far (m) the separating-axis lower bound may sit below the distance
/// found for the distance to count as exact (rounding on coordinates of a
/// few decimetres is ~1e-17 m).
const CERTIFICATE_GAP_M: f64 = 1e-12;

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
}
