//! Geometry shared by the robot and the scene, below both in the module
//! graph (it depends on neither):
//!
//! - [`quaternion`]: the project's `[x, y, z, w]` quaternion convention and
//!   its conversions to and from nalgebra;
//! - [`segment`]: closest points and distances between segments and points
//!   (the kernel of capsule, hull and broad-phase distances).

pub mod quaternion;
pub mod segment;

pub use segment::{closest_segments, point_segment_distance, segment_distance};
