//! The fast, conservative geometry of a mesh link: the convex hull of its
//! collision mesh.
//!
//! Why a hull: every triangle of a mesh lies in the convex hull of the
//! mesh's vertices (a triangle is the convex hull of its three vertices, and
//! those are among the hull's points), so the hull contains the whole mesh
//! surface by convexity, with no sampling argument. Franka's collision meshes
//! are themselves simplified hulls (no vertex lies more than 1 mm outside any
//! face plane), so the hull gives away at most about 1 mm of clearance,
//! where fitted capsules gave away centimetres at the flat faces.
//!
//! Numerics: parry3d computes in `f32`. The hull is built from the vertices
//! relative to their centroid (coordinates of a few decimetres, rounding
//! about 2e-8 m), its containment of every mesh vertex is re-checked in
//! `f64` against the hull's face planes at load, and the measured excess
//! plus [`ROUNDING_ALLOWANCE_M`] becomes the hull's
//! [`ConvexHull::allowance`]: every distance reported against the hull is
//! reduced by it, so the reported clearance never exceeds the distance to
//! the mesh. The distances themselves are computed in `f64`
//! ([`super::hull_query`]), not by parry3d's GJK on the hull's point cloud.

use super::hull_topology::HullTopology;
use super::mesh::TriangleMesh;
use crate::geometry::convex_gap::Polytope;
use crate::geometry::slabs::cube_directions;
use crate::geometry::{point_segment_distance, Slabs};
use nalgebra::{Point3, Vector3};
use parry3d::shape::ConvexPolyhedron;
use std::sync::Arc;

/// Base allowance (m) subtracted from every distance to a hull, on top of
/// the hull's measured `f32` rounding: it covers the `f32` arithmetic left
/// in the queries (parry3d's closest points on the hull's triangles and
/// the obstacles' `f32` support points), which stays below 1e-6 m.
pub const ROUNDING_ALLOWANCE_M: f64 = 1e-5;

/// A convex hull in its link's frame, with what the clearance queries need:
/// the parry3d shape, a bounding capsule for the broad phase, and the
/// allowance that keeps reported distances conservative.
#[derive(Clone, Debug)]
pub struct ConvexHull(Arc<HullData>);

/// The data of a [`ConvexHull`], shared between clones.
#[derive(Debug)]
struct HullData {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    frame: nalgebra::Isometry3<f64>,
    shape: Arc<ConvexPolyhedron>,
    bound: ([f64; 3], [f64; 3], f64),
    allowance: f64,
    source: Option<Arc<TriangleMesh>>,
    /// Outward unit normal and offset of every face (`n·x ≤ d` inside).
    planes: Vec<(Vector3<f64>, f64)>,
    /// Centroid and radius of a ball around every face (pruning).
    face_balls: Vec<(Vector3<f64>, f64)>,
    /// Face adjacency for the local query (shared by moved copies).
    topology: Arc<HullTopology>,
    /// The k-DOP around the vertices: a cheap lower bound on distances.
    slabs: Slabs,
}

impl PartialEq for ConvexHull {
    fn eq(&self, other: &Self) -> bool {
        self.0.vertices == other.0.vertices && self.0.faces == other.0.faces
    }
}

impl serde::Serialize for ConvexHull {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("ConvexHull", 3)?;
        st.serialize_field("vertices", &self.0.vertices)?;
        st.serialize_field("faces", &self.0.faces)?;
        st.serialize_field("allowance_m", &self.0.allowance)?;
        st.end()
    }
}

impl ConvexHull {
    /// The convex hull of `mesh`'s vertices. Errors when the vertices are
    /// coplanar or collinear (no solid to collide with).
    pub fn of_mesh(mesh: &TriangleMesh) -> Result<ConvexHull, String> {
        let hull = ConvexHull::of_points(&mesh.vertices())?;
        let mut data = Arc::try_unwrap(hull.0).map_err(|_| "hull shared")?;
        data.source = Some(Arc::new(mesh.clone()));
        Ok(ConvexHull(Arc::new(data)))
    }

    /// The convex hull of `points` (at least four, not coplanar).
    pub fn of_points(points: &[[f64; 3]]) -> Result<ConvexHull, String> {
        let n = points.len().max(1) as f64;
        let centre = [0, 1, 2].map(|i| points.iter().map(|p| p[i]).sum::<f64>() / n);
        let local: Vec<parry3d::math::Vector> = points
            .iter()
            .map(|p| {
                parry3d::math::Vector::new(
                    (p[0] - centre[0]) as f32,
                    (p[1] - centre[1]) as f32,
                    (p[2] - centre[2]) as f32,
                )
            })
            .collect();
        let (hull_points, mut faces) =
            parry3d::transformation::try_convex_hull(&local).map_err(|e| {
                format!(
                    "no convex hull of its {} vertices ({e:?}): the mesh must be a solid, not flat",
                    points.len()
                )
            })?;
        let vertices: Vec<[f64; 3]> = hull_points
            .iter()
            .map(|v| {
                [
                    v.x as f64 + centre[0],
                    v.y as f64 + centre[1],
                    v.z as f64 + centre[2],
                ]
            })
            .collect();
        // Largest faces first: they separate most obstacles, so the queries'
        // early exit ([`ConvexHull::segment_contact_within`]) comes sooner.
        sort_faces_by_area(&vertices, &mut faces);
        let volume = enclosed_volume(&vertices, &faces);
        if volume.abs() < 1e-12 {
            return Err(format!(
                "its {} vertices span no volume ({volume:e} m³): the mesh must be a solid, not flat",
                points.len()
            ));
        }
        let shape = ConvexPolyhedron::from_convex_mesh(hull_points, &faces)
            .ok_or("parry3d rejected the convex hull of the mesh")?;
        let planes = face_planes(&vertices, &faces);
        let slabs = hull_slabs(&vertices, &planes).ok_or("the hull's vertices are not finite")?;
        let mut hull = HullData {
            slabs,
            bound: bounding_capsule(&vertices),
            vertices,
            faces,
            frame: nalgebra::Isometry3::translation(centre[0], centre[1], centre[2]),
            shape: Arc::new(shape),
            allowance: ROUNDING_ALLOWANCE_M,
            source: None,
            planes,
            face_balls: Vec::new(),
            topology: Arc::default(),
        };
        hull.face_balls = face_balls(&hull.vertices, &hull.faces);
        let normals: Vec<Vector3<f64>> = hull.planes.iter().map(|(n, _)| *n).collect();
        hull.topology = Arc::new(HullTopology::new(
            hull.vertices.len(),
            &hull.faces,
            &normals,
        ));
        let excess = points
            .iter()
            .map(|p| max_plane_distance(&hull.planes, p))
            .fold(0.0, f64::max);
        hull.allowance += excess;
        Ok(ConvexHull(Arc::new(hull)))
    }

    /// The mesh the hull was built from (link frame), when it came from one.
    pub fn source(&self) -> Option<&TriangleMesh> {
        self.0.source.as_deref()
    }

    /// Hull vertices (link frame).
    pub fn vertices(&self) -> &[[f64; 3]] {
        &self.0.vertices
    }

    /// Hull triangles, indices into [`ConvexHull::vertices`], outward.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.0.faces
    }

    /// The parry3d shape, in its own frame ([`ConvexHull::frame`]).
    pub fn shape(&self) -> &Arc<ConvexPolyhedron> {
        &self.0.shape
    }

    /// Pose of the parry shape's frame in the link frame.
    pub fn frame(&self) -> &nalgebra::Isometry3<f64> {
        &self.0.frame
    }

    /// A capsule `(a, b, radius)` containing the hull (link frame).
    pub fn bound(&self) -> ([f64; 3], [f64; 3], f64) {
        self.0.bound
    }

    /// Distance (m) subtracted from every distance measured against the
    /// hull: [`ROUNDING_ALLOWANCE_M`] plus how far, in `f64`, any point the hull
    /// was built from lies outside its face planes (parry's `f32` rounding).
    pub fn allowance(&self) -> f64 {
        self.0.allowance
    }

    /// Farthest distance from `origin` to the hull (at a vertex, by
    /// convexity), plus the allowance.
    pub fn reach_from(&self, origin: &[f64; 3]) -> f64 {
        self.0
            .vertices
            .iter()
            .map(|v| dist(v, origin))
            .fold(0.0, f64::max)
            + self.0.allowance
    }

    /// The same hull moved by the rigid motion `pose` (the parry shape is
    /// shared, only its frame moves).
    pub fn transformed(&self, pose: &nalgebra::Isometry3<f64>) -> ConvexHull {
        let map = |p: &[f64; 3]| -> [f64; 3] { (pose * Point3::from(*p)).coords.into() };
        let (a, b, r) = self.0.bound;
        ConvexHull(Arc::new(HullData {
            vertices: self.0.vertices.iter().map(map).collect(),
            faces: self.0.faces.clone(),
            frame: pose * self.0.frame,
            shape: self.0.shape.clone(),
            bound: (map(&a), map(&b), r),
            allowance: self.0.allowance,
            source: self.0.source.as_ref().map(|m| Arc::new(m.mapped(map))),
            planes: self
                .0
                .planes
                .iter()
                .map(|(n, d)| {
                    let n2 = pose.rotation * n;
                    (n2, d + n2.dot(&pose.translation.vector))
                })
                .collect(),
            face_balls: self
                .0
                .face_balls
                .iter()
                .map(|(c, r)| ((pose * Point3::from(*c)).coords, *r))
                .collect(),
            topology: self.0.topology.clone(),
            slabs: self.0.slabs.placed(pose),
        }))
    }

    /// The k-DOP around the hull (link frame): its gaps are lower bounds on
    /// the distance to the hull (before the allowance).
    pub fn slabs(&self) -> &Slabs {
        &self.0.slabs
    }

    /// Which faces touch which (for the local query).
    pub fn topology(&self) -> &HullTopology {
        &self.0.topology
    }

    /// The hull as a polytope whose support points climb its skeleton
    /// (for [`crate::geometry::convex_gap::hull_shape_gap`]).
    pub fn polytope(&self) -> Polytope<'_> {
        Polytope {
            points: self.vertices(),
            skeleton: Some(self.topology()),
        }
    }

    /// A ball `(centre, radius)` around every face, in face order.
    pub fn face_balls(&self) -> &[(Vector3<f64>, f64)] {
        &self.0.face_balls
    }

    /// Outward unit normal and offset `(n, d)` of every face, in the order
    /// of [`ConvexHull::faces`] (`n·x ≤ d` inside).
    pub fn planes(&self) -> &[(Vector3<f64>, f64)] {
        &self.0.planes
    }

    /// Largest signed distance from `p` to the hull's face planes: ≤ 0
    /// exactly when `p` is inside; equal to the signed distance when
    /// inside.
    pub fn plane_distance(&self, p: &[f64; 3]) -> f64 {
        max_plane_distance(&self.0.planes, p)
    }

    /// Exact signed distance from `p` to the hull surface in `f64`
    /// (negative inside).
    pub fn signed_distance(&self, p: &[f64; 3]) -> f64 {
        let inside = self.plane_distance(p);
        if inside <= 0.0 {
            return inside;
        }
        self.0
            .faces
            .iter()
            .map(|f| point_triangle_distance(p, &f.map(|i| self.0.vertices[i as usize])))
            .fold(f64::INFINITY, f64::min)
    }

    /// The hull's surface as a triangle mesh (link frame).
    pub fn surface(&self) -> TriangleMesh {
        TriangleMesh {
            triangles: self
                .0
                .faces
                .iter()
                .map(|f| f.map(|i| self.0.vertices[i as usize]))
                .collect(),
        }
    }
}

/// Face normals of the largest faces (faces are sorted by area) that
/// join the cube's directions in a hull's k-DOP: the bound is exact for a
/// point facing one of them. 40 of them take the median gap of a point
/// within 5 cm of a Panda hull from 4.6 mm short (the cube's 26 alone) to
/// 0.1 mm, the 90th percentile from 16 to 3.6 mm.
const SLAB_FACES: usize = 40;

/// The k-DOP of a hull: its [`SLAB_FACES`] largest faces' normals and the
/// cube's directions.
fn hull_slabs(vertices: &[[f64; 3]], planes: &[(Vector3<f64>, f64)]) -> Option<Slabs> {
    let mut directions: Vec<Vector3<f64>> =
        planes.iter().take(SLAB_FACES).map(|(n, _)| *n).collect();
    directions.extend(cube_directions());
    Slabs::around(vertices, &directions)
}

fn max_plane_distance(planes: &[(Vector3<f64>, f64)], p: &[f64; 3]) -> f64 {
    let p = Vector3::from(*p);
    planes
        .iter()
        .map(|(n, d)| n.dot(&p) - d)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Outward unit normal and offset of every non-degenerate face.
fn face_planes(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<(Vector3<f64>, f64)> {
    faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| Vector3::from(vertices[i as usize]));
            // A degenerate face gets a plane no point is ever outside of.
            match (b - a).cross(&(c - a)).try_normalize(1e-15) {
                Some(n) => (n, n.dot(&a)),
                None => (Vector3::zeros(), f64::INFINITY),
            }
        })
        .collect()
}

/// Order `faces` by decreasing area (stable: ties keep parry's order).
fn sort_faces_by_area(vertices: &[[f64; 3]], faces: &mut [[u32; 3]]) {
    let area = |f: &[u32; 3]| {
        let [a, b, c] = f.map(|i| Vector3::from(vertices[i as usize]));
        (b - a).cross(&(c - a)).norm()
    };
    faces.sort_by(|x, y| area(y).total_cmp(&area(x)));
}

/// Centroid of every face and the largest distance from it to a corner.
fn face_balls(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<(Vector3<f64>, f64)> {
    faces
        .iter()
        .map(|f| {
            let corners = f.map(|i| Vector3::from(vertices[i as usize]));
            let c = (corners[0] + corners[1] + corners[2]) / 3.0;
            let r = corners.iter().map(|v| (v - c).norm()).fold(0.0, f64::max);
            (c, r * (1.0 + 1e-12))
        })
        .collect()
}

/// Volume enclosed by a closed triangle surface (divergence theorem).
fn enclosed_volume(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> f64 {
    faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| Vector3::from(vertices[i as usize]));
            a.dot(&b.cross(&c)) / 6.0
        })
        .sum()
}

/// A capsule containing `points`: segment along their principal axis over
/// the extent of their projections, radius the largest distance to it.
fn bounding_capsule(points: &[[f64; 3]]) -> ([f64; 3], [f64; 3], f64) {
    let n = points.len().max(1) as f64;
    let c = points
        .iter()
        .map(|p| Vector3::from(*p))
        .sum::<Vector3<f64>>()
        / n;
    let mut cov = nalgebra::Matrix3::zeros();
    for p in points {
        let d = Vector3::from(*p) - c;
        cov += d * d.transpose();
    }
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let u: Vector3<f64> = eig.eigenvectors.column(k).into();
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            let t = u.dot(&(Vector3::from(*p) - c));
            (lo.min(t), hi.max(t))
        });
    let (a, b) = (c + u * lo, c + u * hi);
    let radius = points
        .iter()
        .map(|p| point_segment_distance(&Vector3::from(*p), &a, &b))
        .fold(0.0, f64::max);
    (a.into(), b.into(), radius * (1.0 + 1e-9) + 1e-9)
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (Vector3::from(*a) - Vector3::from(*b)).norm()
}

/// Exact `f64` distance from `p` to the triangle `t` (closest point by
/// Voronoi regions, Ericson's "Real-Time Collision Detection" §5.1.5).
pub fn point_triangle_distance(p: &[f64; 3], t: &[[f64; 3]; 3]) -> f64 {
    let p = Vector3::from(*p);
    let [a, b, c] = t.map(Vector3::from);
    (p - closest_on_triangle(&p, &a, &b, &c)).norm()
}

pub(crate) fn closest_on_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> Vector3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < 1e-300 {
        // Degenerate (zero-area) triangle: nearest of its edges.
        return [(*a, *b), (*b, *c), (*c, *a)]
            .into_iter()
            .map(|(s, e)| {
                let d = e - s;
                let t = if d.norm_squared() > 0.0 {
                    ((p - s).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                s + d * t
            })
            .min_by(|x, y| (p - x).norm().total_cmp(&(p - y).norm()))
            .unwrap_or(*a);
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

impl TriangleMesh {
    /// Exact `f64` distance from `p` to the nearest triangle.
    pub fn distance_to_point(&self, p: &[f64; 3]) -> f64 {
        self.triangles
            .iter()
            .map(|t| point_triangle_distance(p, t))
            .fold(f64::INFINITY, f64::min)
    }
}

/// How tightly a hull wraps its mesh.
#[derive(Clone, Debug, serde::Serialize, PartialEq)]
pub struct Tightness {
    /// Largest distance (m) of a mesh vertex outside the hull's face planes
    /// (≤ 0: every triangle is inside, exactly, by convexity).
    pub containment_excess_m: f64,
    /// Points sampled on the hull surface.
    pub samples: usize,
    /// Mean distance (m) from the hull surface to the mesh: clearance given
    /// away on average.
    pub mean_gap_m: f64,
    /// Median of the same.
    pub median_gap_m: f64,
    /// Largest of the same.
    pub max_gap_m: f64,
}

/// Containment and tightness of `hull` around `mesh`: the exact containment
/// test over the mesh vertices, and the gap sampled on the hull surface at
/// `spacing` (m).
pub fn tightness(hull: &ConvexHull, mesh: &TriangleMesh, spacing: f64) -> Tightness {
    let containment_excess_m = mesh
        .vertices()
        .iter()
        .map(|v| hull.plane_distance(v))
        .fold(f64::NEG_INFINITY, f64::max);
    let mut gaps: Vec<f64> = hull
        .surface()
        .surface_samples(spacing)
        .iter()
        .map(|p| mesh.distance_to_point(p) + hull.allowance())
        .collect();
    gaps.sort_by(f64::total_cmp);
    let n = gaps.len().max(1);
    Tightness {
        containment_excess_m,
        samples: gaps.len(),
        mean_gap_m: gaps.iter().sum::<f64>() / n as f64,
        median_gap_m: gaps.get(gaps.len() / 2).copied().unwrap_or(0.0),
        max_gap_m: gaps.last().copied().unwrap_or(0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(h: f64) -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        for x in [-h, h] {
            for y in [-h, h] {
                for z in [-h, h] {
                    v.push([x + 1.0, y, z]);
                }
            }
        }
        v
    }

    #[test]
    fn hull_of_a_cube_has_exact_signed_distances() {
        let hull = ConvexHull::of_points(&cube(0.1)).unwrap();
        assert_eq!(hull.vertices().len(), 8);
        assert_eq!(hull.faces().len(), 12);
        assert!((hull.signed_distance(&[1.0, 0.0, 0.0]) + 0.1).abs() < 1e-7);
        assert!((hull.signed_distance(&[1.3, 0.0, 0.0]) - 0.2).abs() < 1e-7);
        let corner = hull.signed_distance(&[1.2, 0.2, 0.2]);
        assert!((corner - 0.1 * 3f64.sqrt()).abs() < 1e-7, "{corner}");
        assert!(
            hull.allowance() >= ROUNDING_ALLOWANCE_M
                && hull.allowance() < ROUNDING_ALLOWANCE_M + 1e-7
        );
        let (a, b, r) = hull.bound();
        for v in cube(0.1) {
            let d = point_segment_distance(&Vector3::from(v), &a.into(), &b.into());
            assert!(d <= r, "{d} > {r}");
        }
        assert!((hull.reach_from(&[1.0, 0.0, 0.0]) - 0.1 * 3f64.sqrt()).abs() < 2e-5);
    }

    #[test]
    fn flat_points_have_no_hull() {
        let e =
            ConvexHull::of_points(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
                .unwrap_err();
        assert!(e.contains("flat"), "{e}");
    }

    #[test]
    fn point_triangle_distance_matches_the_regions() {
        let t = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!((point_triangle_distance(&[0.2, 0.2, 0.5], &t) - 0.5).abs() < 1e-15);
        assert!((point_triangle_distance(&[-1.0, -1.0, 0.0], &t) - 2f64.sqrt()).abs() < 1e-15);
        assert!((point_triangle_distance(&[0.5, -2.0, 0.0], &t) - 2.0).abs() < 1e-15);
        let d = point_triangle_distance(&[1.0, 1.0, 0.0], &t);
        assert!((d - 0.5f64.sqrt()).abs() < 1e-15, "{d}");
    }

    #[test]
    fn a_cube_wraps_its_own_mesh_with_no_gap_but_the_allowance() {
        let hull = ConvexHull::of_points(&cube(0.05)).unwrap();
        let t = tightness(&hull, &hull.surface(), 0.01);
        assert!(t.containment_excess_m <= 1e-7, "{t:?}");
        assert!(t.max_gap_m <= hull.allowance() + 1e-7, "{t:?}");
        assert!(t.samples > 100);
    }
}
