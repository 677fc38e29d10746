//! Signed distance between one robot primitive and one obstacle part, with
//! witness points and normal, from parry3d's `query::contact` (GJK when
//! apart, EPA when penetrating).

use super::clip::{near_piece, Cut};
use super::contact::PairContact;
use super::round_contact::round_contact;
use super::shape::{from_glam, parry_pose_relative, to_glam, LocalShape, Part, RobotPart};
use crate::geometry::convex_gap::{hull_shape_gap, ConvexGap};
use crate::geometry::RoundedBox;
use crate::robot::hull::ConvexHull;
use nalgebra::{Isometry3, Point3, Vector3};

/// Signed distance between `robot` and `part` when below `prediction` (m);
/// `None` when they are further apart. A long part is first cut to the
/// piece near the robot shape ([`super::clip`]). The robot part's allowance is
/// subtracted (its witness point moves out along the normal by as much), so
/// the distance is a lower bound on the distance to the real link. Both shapes are placed relative to
/// the robot primitive's origin so that parry's `f32` arithmetic only sees
/// small coordinates.
pub fn pair_contact(robot: &RobotPart, part: &Part, prediction: f64) -> Option<PairContact> {
    if boxes_rule_out(robot, part, prediction) {
        return None;
    }
    let piece;
    let part = match part.long {
        None => part,
        Some(_) => {
            let (centre, radius) = robot.bounding_ball();
            let reach = radius + prediction.max(0.0) + robot.allowance();
            match near_piece(part, &centre, reach) {
                Cut::Whole => part,
                Cut::Beyond => return None,
                Cut::Piece(p) => {
                    piece = *p;
                    &piece
                }
            }
        }
    };
    if let RobotPart::Convex(hull, link_pose, _) = robot {
        return hull_contact(hull, link_pose, part, prediction);
    }
    if let RobotPart::Primitive(shape, pose) = robot {
        if part.shape.as_ball().is_some() || part.shape.as_capsule().is_some() {
            if let Some(decided) = round_contact(shape, pose, &part.core, prediction) {
                return decided;
            }
        }
    }
    let (shape, pose) = robot.shape_and_pose();
    let origin = pose.translation.vector;
    let pos1 = parry_pose_relative(pose, &origin);
    let pos2 = parry_pose_relative(&part.pose, &origin);
    let contact = parry3d::query::contact(
        &pos1,
        shape,
        &pos2,
        part.shape.as_ref(),
        (prediction + robot.allowance()).max(0.0) as f32,
    )
    .ok()??;
    let normal = (-from_glam(contact.normal1))
        .try_normalize(1e-12)
        .unwrap_or_else(Vector3::z);
    let (normal, distance) = match robot {
        RobotPart::Primitive(shape, pose) => {
            primitive_separation(shape, pose, part, normal).unwrap_or((normal, contact.dist as f64))
        }
        RobotPart::Convex(..) => (normal, contact.dist as f64),
    };
    if distance >= prediction {
        return None;
    }
    Some(PairContact {
        distance,
        point_robot: from_glam(contact.point1) + origin,
        point_obstacle: from_glam(contact.point2) + origin,
        normal,
    })
}

/// A robot primitive against a part that is not round: the largest
/// separation `min_{y ∈ part} u·y − max_{x ∈ robot} u·x` over parry's
/// direction, the boxes' face normals and their edge cross products, with
/// the normal from the part towards the robot. Every separation is a lower
/// bound on the signed distance (the distance is their maximum over all
/// directions), so the answer never exceeds it, where parry's `f32` GJK
/// was measured half a millimetre above it for a box against a finger box.
/// `None` when the part has no support map.
fn primitive_separation(
    shape: &LocalShape,
    pose: &Isometry3<f64>,
    part: &Part,
    parry_normal: Vector3<f64>,
) -> Option<(Vector3<f64>, f64)> {
    let part_min = part_support_min(part)?;
    let centre = pose.translation.vector;
    let robot_axes: Vec<Vector3<f64>> = match shape {
        LocalShape::Cuboid(_) => (0..3)
            .map(|i| pose.rotation * Vector3::ith(i, 1.0))
            .collect(),
        _ => Vec::new(),
    };
    let robot_max = |u: &Vector3<f64>| -> f64 {
        match shape {
            LocalShape::Ball(b) => centre.dot(u) + b.radius as f64,
            LocalShape::Capsule(c) => {
                let a = (pose * Point3::from(from_glam(c.segment.a))).coords;
                let b = (pose * Point3::from(from_glam(c.segment.b))).coords;
                a.dot(u).max(b.dot(u)) + c.radius as f64
            }
            LocalShape::Cuboid(c) => {
                let h = from_glam(c.half_extents);
                centre.dot(u)
                    + (0..3)
                        .map(|i| h[i] * robot_axes[i].dot(u).abs())
                        .sum::<f64>()
            }
        }
    };
    let part_axes: Vec<Vector3<f64>> = match part.shape.as_cuboid() {
        Some(_) => (0..3)
            .map(|i| part.pose.rotation * Vector3::ith(i, 1.0))
            .collect(),
        None => Vec::new(),
    };
    let mut candidates = vec![-parry_normal];
    for axis in robot_axes.iter().chain(&part_axes) {
        candidates.extend([*axis, -axis]);
    }
    for r in &robot_axes {
        for q in &part_axes {
            if let Some(u) = r.cross(q).try_normalize(1e-9) {
                candidates.extend([u, -u]);
            }
        }
    }
    // The part's support points come from parry in `f32` about its own
    // origin: rounding of at most a few ulps of its size.
    let core = &part.core;
    let size = 0.5 * (core.b - core.a).norm() + core.radius;
    let rounding = F32_SUPPORT_ROUNDING * size + 1e-12;
    candidates
        .into_iter()
        .map(|u| (-u, part_min(&u) - robot_max(&u) - rounding))
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// Relative bound on the `f32` rounding of a part's support point (four
/// ulps of single precision).
const F32_SUPPORT_ROUNDING: f64 = 4.0 * f32::EPSILON as f64;

/// `u ↦ min_{y ∈ part} u·y` (base frame) from the part's support map.
fn part_support_min(part: &Part) -> Option<impl Fn(&Vector3<f64>) -> f64 + '_> {
    let support = part.shape.as_support_map()?;
    let origin = part.pose.translation.vector;
    let part_pose = parry_pose_relative(&part.pose, &origin);
    Some(move |u: &Vector3<f64>| {
        let s = from_glam(support.support_point(&part_pose, to_glam(&-u))) + origin;
        u.dot(&s)
    })
}

/// A mesh link's hull against an obstacle part, never above the distance
/// to the mesh: balls and capsules (berries, stems) by the exact `f64`
/// hull query ([`ConvexHull::segment_contact`]); other parts by a
/// separating-axis lower bound along the best of the direction between
/// the closest points of the hull's vertices and the part (parry3d-f64's
/// GJK, [`hull_shape_gap`]) and the hull's face normals. The hull's
/// allowance is subtracted in both cases.
fn hull_contact(
    hull: &ConvexHull,
    link_pose: &Isometry3<f64>,
    part: &Part,
    prediction: f64,
) -> Option<PairContact> {
    let allowance = hull.allowance();
    if part.shape.as_ball().is_some() || part.shape.as_capsule().is_some() {
        let to_link = link_pose.inverse();
        let a = (to_link * Point3::from(part.core.a)).coords;
        let b = (to_link * Point3::from(part.core.b)).coords;
        let limit = prediction + part.core.radius + allowance;
        let c = hull.segment_contact_within(&a, &b, limit)?;
        let distance = c.distance - part.core.radius - allowance;
        if distance >= prediction {
            return None;
        }
        let normal = link_pose.rotation * c.normal;
        return Some(PairContact {
            distance,
            point_robot: (link_pose * Point3::from(c.point_hull)).coords - normal * allowance,
            point_obstacle: (link_pose * Point3::from(c.point_segment)).coords
                + normal * part.core.radius,
            normal,
        });
    }
    // GJK on the two convex sets: apart beyond the limit only with a
    // separating axis (the support points along it), and a part inside the
    // hull overlaps it, so no containment check is needed.
    let limit = (prediction + allowance).max(0.0);
    let near = match part.shape.as_support_map() {
        Some(shape) => hull_shape_gap(hull.polytope(), link_pose, shape, &part.pose, limit),
        None => ConvexGap::Overlapping,
    };
    let (guess, witnesses) = match near {
        ConvexGap::Beyond => return None,
        ConvexGap::Within { on_hull, on_shape } => (
            (on_hull - on_shape).try_normalize(1e-12),
            Some((on_hull, on_shape)),
        ),
        ConvexGap::Overlapping => (None, None),
    };
    // GJK's direction between two apart convex sets is the distance's own
    // (the separation along it is within 1e-7 m of the distance: the
    // face normals cannot beat it); the face normals bound an overlap.
    let (normal, separation) = match (guess, witnesses) {
        (Some(normal), Some(_)) => (normal, separation_along(hull, link_pose, part, &normal)),
        _ => best_separating_axis(hull, link_pose, part, guess.unwrap_or_else(Vector3::z)),
    };
    let distance = separation - allowance;
    if distance >= prediction {
        return None;
    }
    let (point_robot, point_obstacle) = witnesses.unwrap_or_else(|| {
        let c = part.core.a;
        (c + normal * separation, c)
    });
    Some(PairContact {
        distance,
        point_robot: point_robot - normal * allowance,
        point_obstacle,
        normal,
    })
}

/// Whether a cheap lower bound puts `part` (a box or a cylinder, by its
/// bounding box) at least `prediction` from `robot`: the hull's k-DOP and
/// bounding capsule, or the primitive's rounded box, against the part's
/// box ([`RoundedBox`]), less the robot part's allowance. Most pairs the
/// broad phase keeps near a long board or a box are settled here, before
/// the exact query.
fn boxes_rule_out(robot: &RobotPart, part: &Part, prediction: f64) -> bool {
    let Some(part_box) = part_box(part) else {
        return false;
    };
    let gap = match robot {
        RobotPart::Convex(hull, link_pose, _) => {
            let local = part_box.transformed(&link_pose.inverse());
            let (a, b, r) = hull.bound();
            let capsule = RoundedBox::capsule(&Vector3::from(a), &Vector3::from(b), r);
            hull.slabs()
                .rounded_box_gap(&local)
                .max(capsule.gap(&local))
        }
        RobotPart::Primitive(shape, pose) => primitive_box(shape, pose).gap(&part_box),
    } - robot.allowance();
    gap >= prediction && gap > 0.0
}

/// The box around a box or cylinder part (base frame; parry's `f32`
/// extents rounded outwards); `None` for other shapes.
fn part_box(part: &Part) -> Option<RoundedBox> {
    let half = if let Some(c) = part.shape.as_cuboid() {
        from_glam(c.half_extents)
    } else if let Some(c) = part.shape.as_cylinder() {
        let (r, h) = (c.radius as f64, c.half_height as f64);
        Vector3::new(r, h, r)
    } else {
        return None;
    };
    Some(RoundedBox::placed(&part.pose, outward(half)))
}

/// A robot primitive as a rounded box (base frame).
fn primitive_box(shape: &LocalShape, pose: &Isometry3<f64>) -> RoundedBox {
    let (half, radius) = match shape {
        LocalShape::Ball(b) => (Vector3::zeros(), b.radius as f64),
        LocalShape::Capsule(c) => (from_glam(c.segment.b).abs(), c.radius as f64),
        LocalShape::Cuboid(c) => (from_glam(c.half_extents), 0.0),
    };
    RoundedBox {
        radius: outward(Vector3::repeat(radius)).x,
        ..RoundedBox::placed(pose, outward(half))
    }
}

/// `f32` extents grown past their rounding.
fn outward(v: Vector3<f64>) -> Vector3<f64> {
    v * (1.0 + 1e-6) + Vector3::repeat(1e-9)
}

/// The separation `min_{y ∈ part} u·y − max_{x ∈ hull} u·x` along
/// `u = -normal` (`normal` pointing from the part towards the hull): a
/// lower bound on the signed distance; −∞ for a part without a support map.
fn separation_along(
    hull: &ConvexHull,
    link_pose: &Isometry3<f64>,
    part: &Part,
    normal: &Vector3<f64>,
) -> f64 {
    match part_support_min(part) {
        Some(part_min) => part_min(&-normal) - hull_max(hull, link_pose, &-normal),
        None => f64::NEG_INFINITY,
    }
}

/// `max_{x ∈ hull} u·x` (base frame) over the hull's vertices.
fn hull_max(hull: &ConvexHull, link_pose: &Isometry3<f64>, u: &Vector3<f64>) -> f64 {
    let local = link_pose.rotation.inverse() * u;
    let top = hull
        .vertices()
        .iter()
        .map(|v| local.dot(&Vector3::from(*v)))
        .fold(f64::NEG_INFINITY, f64::max);
    top + u.dot(&link_pose.translation.vector)
}

/// The largest separation (see [`separation_along`]) over the candidate
/// axes `u` pointing from the hull to the part (`-guess` and the hull's
/// outward face normals), with the normal from the part towards the hull
/// (`-u`). Every such separation is a lower bound on the signed distance
/// (which is their maximum over all directions).
fn best_separating_axis(
    hull: &ConvexHull,
    link_pose: &Isometry3<f64>,
    part: &Part,
    guess: Vector3<f64>,
) -> (Vector3<f64>, f64) {
    let Some(part_min) = part_support_min(part) else {
        return (guess, f64::NEG_INFINITY);
    };
    let mut best = (guess, separation_along(hull, link_pose, part, &guess));
    for (n, d) in hull.planes() {
        if d.is_infinite() {
            continue;
        }
        let u = link_pose.rotation * n;
        let sep = part_min(&u) - (d + u.dot(&link_pose.translation.vector));
        if sep > best.1 {
            best = (-u, sep);
        }
    }
    best
}

/// Distance from `p` to the part (0 inside).
pub fn point_distance(part: &Part, p: &Vector3<f64>) -> f64 {
    let origin = part.pose.translation.vector;
    let pose = parry_pose_relative(&part.pose, &origin);
    part.shape
        .distance_to_point(&pose, super::shape::to_glam(&(p - origin)), true) as f64
}

/// Signed distance from `p` to the part's surface (negative inside).
pub fn point_signed_distance(part: &Part, p: &Vector3<f64>) -> f64 {
    let origin = part.pose.translation.vector;
    let pose = parry_pose_relative(&part.pose, &origin);
    part.shape
        .distance_to_point(&pose, super::shape::to_glam(&(p - origin)), false) as f64
}
