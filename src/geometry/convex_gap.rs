//! The closest points of two convex sets given by their support maps, in
//! `f64`: parry3d-f64's GJK between a point cloud's convex hull (a robot
//! link's hull vertices) and any parry3d (`f32`) support-map shape (an
//! obstacle's box, cylinder or convex polyhedron).
//!
//! Why `f64`, and why the vertex cloud: parry3d's `f32` GJK on the Panda's
//! hull vertices (dense clouds of near-coplanar points) was measured to err
//! by up to a centimetre, so the robot's hulls were queried as triangle
//! meshes instead, one separating-axis test per triangle near the part:
//! 85 % of a MotionBenchMaker box plan's run time. GJK in `f64` on the
//! vertices converges to the distance between the two convex sets, to the
//! `f32` rounding of the part's support points (a few ulps of its size).
//! A caller that must never overstate a distance (the clearance) takes
//! only the direction from here and bounds the distance along it itself.

use nalgebra::{Isometry3, Vector3};
use parry3d_f64::math::{Pose, Rot3, Vector};
use parry3d_f64::query::details::closest_points_support_map_support_map;
use parry3d_f64::query::ClosestPoints;
use parry3d_f64::shape::SupportMap;
use std::cell::Cell;

/// How two convex sets stand relative to each other.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConvexGap {
    /// Further apart than the limit asked.
    Beyond,
    /// Apart by less than the limit: the closest point of each set (the
    /// frame of the caller's poses).
    Within {
        /// Closest point on the point cloud's hull.
        on_hull: Vector3<f64>,
        /// Closest point on the shape.
        on_shape: Vector3<f64>,
    },
    /// Touching or overlapping.
    Overlapping,
}

/// A convex polytope's skeleton: the vertices sharing an edge with each
/// vertex, and where to start climbing towards a direction.
pub trait Skeleton {
    /// The vertices sharing an edge with vertex `i`.
    fn neighbours(&self, i: usize) -> &[u32];

    /// A vertex near the support point along `dir` (any length), where a
    /// climb towards `dir` starts.
    fn start_towards(&self, dir: &Vector3<f64>) -> usize;
}

/// A convex polytope as its vertices and, optionally, its skeleton. With
/// the skeleton the support point is found by climbing it (a linear
/// function on a convex polytope has no local maximum but the global one):
/// the first from the skeleton's start towards the direction, each next
/// from the last support point found; without it, by scanning every vertex.
#[derive(Clone, Copy)]
pub struct Polytope<'a> {
    /// The vertices.
    pub points: &'a [[f64; 3]],
    /// The skeleton, if known.
    pub skeleton: Option<&'a dyn Skeleton>,
}

/// The convex hull `hull` (its frame placed by `hull_pose`) against
/// `shape` (placed by `shape_pose`), when closer than `limit`.
pub fn hull_shape_gap(
    hull: Polytope<'_>,
    hull_pose: &Isometry3<f64>,
    shape: &dyn parry3d::shape::SupportMap,
    shape_pose: &Isometry3<f64>,
    limit: f64,
) -> ConvexGap {
    if hull.points.is_empty() {
        return ConvexGap::Beyond;
    }
    let relative = hull_pose.inverse() * shape_pose;
    let near = closest_points_support_map_support_map(
        &pose_f64(&relative),
        &Support {
            hull,
            last: Cell::new(None),
        },
        &ShapeF32(shape),
        limit.max(0.0),
    );
    match near {
        ClosestPoints::Disjoint => ConvexGap::Beyond,
        ClosestPoints::Intersecting => ConvexGap::Overlapping,
        ClosestPoints::WithinMargin(a, b) => ConvexGap::Within {
            on_hull: (hull_pose * nalgebra::Point3::new(a.x, a.y, a.z)).coords,
            on_shape: (shape_pose * nalgebra::Point3::new(b.x, b.y, b.z)).coords,
        },
    }
}

/// A polytope's support map, climbing from the last support point (GJK
/// asks along directions that turn little between steps).
struct Support<'a> {
    hull: Polytope<'a>,
    last: Cell<Option<usize>>,
}

impl SupportMap for Support<'_> {
    fn local_support_point(&self, dir: Vector) -> Vector {
        let points = self.hull.points;
        let along = |i: usize| points[i][0] * dir.x + points[i][1] * dir.y + points[i][2] * dir.z;
        let best = match self.hull.skeleton {
            Some(skeleton) => {
                let from = self
                    .last
                    .get()
                    .unwrap_or_else(|| skeleton.start_towards(&Vector3::new(dir.x, dir.y, dir.z)));
                let mut at = from.min(points.len() - 1);
                let mut top = along(at);
                loop {
                    let from = at;
                    for &j in skeleton.neighbours(from) {
                        let v = along(j as usize);
                        if v > top {
                            (at, top) = (j as usize, v);
                        }
                    }
                    if at == from {
                        break at;
                    }
                }
            }
            None => (0..points.len())
                .max_by(|&a, &b| along(a).total_cmp(&along(b)))
                .unwrap_or(0),
        };
        self.last.set(Some(best));
        let p = points[best];
        Vector::new(p[0], p[1], p[2])
    }
}

/// A parry3d `f32` shape's support map seen in `f64`.
struct ShapeF32<'a>(&'a dyn parry3d::shape::SupportMap);

impl SupportMap for ShapeF32<'_> {
    fn local_support_point(&self, dir: Vector) -> Vector {
        let d = parry3d::math::Vector::new(dir.x as f32, dir.y as f32, dir.z as f32);
        let p = self.0.local_support_point(d);
        Vector::new(p.x as f64, p.y as f64, p.z as f64)
    }
}

/// A nalgebra pose as parry3d-f64's.
fn pose_f64(pose: &Isometry3<f64>) -> Pose {
    let t = pose.translation.vector;
    let q = pose.rotation;
    Pose::from_parts(
        Vector::new(t.x, t.y, t.z),
        Rot3::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use parry3d::shape::Cuboid;

    fn cloud(points: &[[f64; 3]]) -> Polytope<'_> {
        Polytope {
            points,
            skeleton: None,
        }
    }

    fn cube_points(half: f64) -> Vec<[f64; 3]> {
        let mut p = Vec::new();
        for x in [-half, half] {
            for y in [-half, half] {
                for z in [-half, half] {
                    p.push([x, y, z]);
                }
            }
        }
        p
    }

    /// Two axis-aligned unit boxes 0.3 m apart along x: the gap is the
    /// closed form, and the witnesses lie on the facing faces.
    #[test]
    fn boxes_apart_along_an_axis_give_the_closed_form() {
        let points = cube_points(0.1);
        let cuboid = Cuboid::new(parry3d::math::Vector::new(0.2, 0.2, 0.2));
        let hull_pose = Isometry3::from_parts(
            Translation3::new(0.5, -0.2, 0.1),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 0.9),
        );
        let offset = hull_pose.rotation * Vector3::new(0.1 + 0.3 + 0.2, 0.0, 0.0);
        let shape_pose = Isometry3::from_parts(
            Translation3::from(hull_pose.translation.vector + offset),
            hull_pose.rotation,
        );
        let ConvexGap::Within { on_hull, on_shape } =
            hull_shape_gap(cloud(&points), &hull_pose, &cuboid, &shape_pose, 1.0)
        else {
            panic!("the boxes are 0.3 m apart");
        };
        assert!(((on_shape - on_hull).norm() - 0.3).abs() < 1e-6);
        let local = hull_pose.inverse() * nalgebra::Point3::from(on_hull);
        assert!((local.x - 0.1).abs() < 1e-9, "{local}");
        assert_eq!(
            hull_shape_gap(cloud(&points), &hull_pose, &cuboid, &shape_pose, 0.29),
            ConvexGap::Beyond
        );
        let touching = Isometry3::from_parts(
            Translation3::from(hull_pose.translation.vector + offset * 0.4),
            hull_pose.rotation,
        );
        assert_eq!(
            hull_shape_gap(cloud(&points), &hull_pose, &cuboid, &touching, 1.0),
            ConvexGap::Overlapping
        );
    }
}
