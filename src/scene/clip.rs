//! Long obstacles cut down to the piece near one robot shape.
//!
//! parry3d's narrow phase runs in `f32` with tolerances relative to the
//! shapes' size, so a 4 cm rod 200 m long measured against a finger box
//! comes out a millimetre off, and in the wrong direction for a clearance
//! certificate. The distance only depends on the obstacle near the robot
//! shape: if a robot shape lies within `R` of its centre `c`, the closest
//! point `k` of the obstacle `K` to it (when they are within `prediction`)
//! satisfies `|k − c| ≤ R + prediction`. So `K' = K ∩ {points whose
//! axial / box coordinates lie within R + prediction of c's}` is a subset
//! of `K` that still holds `k`: the distance to `K'` is the distance to
//! `K` whenever it is below `prediction`, and `K'` meets the robot shape
//! exactly when `K` does. `K'` is short, so parry measures it to `f32`
//! precision of small coordinates.
//!
//! Capsules, cylinders and boxes longer than [`LONG_PART_M`](super::shape::LONG_PART_M) carry their
//! exact `f64` description ([`LongPart`]) for this; the cut is built per
//! query, only for them.

use super::shape::{to_glam, y_onto, LongPart, Part};
use crate::geometry::OrientedBox;
use nalgebra::{Isometry3, Translation3, Vector3};
use parry3d::shape::{Capsule, Cuboid, Cylinder, SharedShape};

/// What is left of a part near a robot shape.
pub enum Cut {
    /// The part is short: use it whole.
    Whole,
    /// The piece within reach.
    Piece(Box<Part>),
    /// Nothing of the part lies within reach: no contact below the
    /// prediction.
    Beyond,
}

/// The piece of `part` that can hold the closest point to a robot shape
/// within `reach` of `centre` (see the module docs).
pub fn near_piece(part: &Part, centre: &Vector3<f64>, reach: f64) -> Cut {
    match part.long.as_deref() {
        None => Cut::Whole,
        Some(&LongPart::Segment { flat_ends }) => segment_piece(part, centre, reach, flat_ends),
        Some(LongPart::Box(b)) => box_piece(part, b, centre, reach),
    }
}

fn segment_piece(part: &Part, centre: &Vector3<f64>, reach: f64, flat_ends: bool) -> Cut {
    let core = &part.core;
    let axis = core.b - core.a;
    let length = axis.norm();
    if length < 1e-12 {
        return Cut::Whole;
    }
    let dir = axis / length;
    // The closest point's foot on the axis lies within reach (+ radius for
    // round ends) of the centre's projection.
    let window = reach + if flat_ends { 0.0 } else { core.radius };
    let t = (centre - core.a).dot(&dir);
    let (lo, hi) = ((t - window).max(0.0), (t + window).min(length));
    if lo > hi {
        return Cut::Beyond;
    }
    let (a, b) = (core.a + dir * lo, core.a + dir * hi);
    let mid = (a + b) * 0.5;
    let mut piece = part.clone();
    piece.long = None;
    piece.core.a = a;
    piece.core.b = b;
    if flat_ends {
        piece.pose = Isometry3::from_parts(Translation3::from(mid), y_onto(&dir));
        let half = (0.5 * (hi - lo)).max(1e-9);
        piece.shape = SharedShape::new(Cylinder::new(half as f32, core.radius as f32));
    } else {
        piece.pose = Isometry3::translation(mid.x, mid.y, mid.z);
        piece.shape = SharedShape::new(Capsule::new(
            to_glam(&(a - mid)),
            to_glam(&(b - mid)),
            core.radius as f32,
        ));
    }
    Cut::Piece(Box::new(piece))
}

fn box_piece(part: &Part, b: &OrientedBox, centre: &Vector3<f64>, reach: f64) -> Cut {
    let rotation = crate::geometry::quaternion::from_xyzw(&b.rotation);
    let local = rotation.inverse() * (centre - Vector3::from(b.center));
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for i in 0..3 {
        let h = b.half_extents[i];
        lo[i] = (local[i] - reach).max(-h);
        hi[i] = (local[i] + reach).min(h);
        if lo[i] > hi[i] {
            return Cut::Beyond;
        }
    }
    let mid_local = Vector3::new(
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    );
    let half = Vector3::new(
        0.5 * (hi[0] - lo[0]),
        0.5 * (hi[1] - lo[1]),
        0.5 * (hi[2] - lo[2]),
    )
    .map(|h| h.max(1e-9));
    let mid = Vector3::from(b.center) + rotation * mid_local;
    let mut piece = part.clone();
    piece.long = None;
    piece.pose = Isometry3::from_parts(Translation3::from(mid), rotation);
    piece.shape = SharedShape::new(Cuboid::new(to_glam(&half)));
    // The broad-phase capsule of the piece: its longest axis.
    let k = (0..3)
        .max_by(|&i, &j| half[i].total_cmp(&half[j]))
        .unwrap_or(0);
    let mut e = Vector3::zeros();
    e[k] = half[k];
    let rest = (0..3)
        .filter(|&i| i != k)
        .map(|i| half[i] * half[i])
        .sum::<f64>()
        .sqrt();
    piece.core.a = mid - rotation * e;
    piece.core.b = mid + rotation * e;
    piece.core.radius = rest;
    Cut::Piece(Box::new(piece))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Capsule as Cap;
    use crate::scene::shape::compile_obstacle;
    use crate::scene::ObstacleShape;

    #[test]
    fn a_cut_capsule_is_the_same_capsule_over_the_window() {
        let a = [0.5315508003090741, 0.7862054375043886, 0.9779796581831582];
        let b = [
            0.009276127196650386,
            -0.11059967181282371,
            0.6133294672770594,
        ];
        let long = compile_obstacle(&ObstacleShape::Capsule(Cap { a, b, radius: 0.02 })).unwrap();
        let part = &long.parts[0];
        assert!(part.long.is_some());
        let centre = Vector3::new(0.25, 0.27, 0.75);
        let Cut::Piece(piece) = near_piece(part, &centre, 0.07) else {
            panic!("not cut")
        };
        let p = Vector3::new(0.2511556014807565, 0.26472517232676396, 0.7343624560163167);
        let whole = crate::scene::distance::point_distance(part, &p);
        let cut = crate::scene::distance::point_distance(&piece, &p);
        assert!((whole - cut).abs() < 1e-6, "{whole} vs {cut}");
    }
}
