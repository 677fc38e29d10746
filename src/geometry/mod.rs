//! Geometry shared by the robot and the scene, below both in the module
//! graph (it depends on neither):
//!
//! - [`primitive`]: the sphere, capsule and oriented box of robot links and
//!   obstacles (one serde type each, one wire format) and their maths;
//! - [`quaternion`]: the project's `[x, y, z, w]` quaternion convention and
//!   its conversions to and from nalgebra;
//! - [`slabs`]: the k-DOP around a point set, a cheap lower bound on the
//!   distance to its convex hull;
//! - [`rounded_box`]: an oriented box grown by a radius, and a cheap lower
//!   bound on the distance between two (the scene's pre-check before its
//!   exact queries);
//! - [`segment`]: closest points and distances between segments and points
//!   (the kernel of capsule, hull and broad-phase distances);
//! - [`convex_gap`]: the closest points of a point cloud's hull and a
//!   support-map shape, in `f64` (parry3d-f64's GJK);
//! - [`random_unit`]: uniformly random directions.

pub mod convex_gap;
pub mod primitive;
pub mod quaternion;
pub mod rounded_box;
pub mod segment;
pub mod slabs;

pub use primitive::{midpoint, Capsule, OrientedBox, Primitive, Sphere};
pub use rounded_box::RoundedBox;
pub use segment::{closest_segments, point_segment_distance, segment_distance};
pub use slabs::Slabs;

use nalgebra::Vector3;
use rand::Rng;

/// A uniformly random unit vector (rejection sampling in the unit ball).
pub fn random_unit(rng: &mut impl Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}
