//! The scene: obstacles around the robot and signed-distance queries
//! between them and the robot's collision primitives.
//!
//! - [`obstacle`]: the serde types of the request schema and validation;
//! - [`shape`]: obstacles and robot primitives as parry3d shapes;
//! - [`broadphase`]: axis-aligned bounds and their gaps;
//! - [`distance`]: one pair's signed distance, witness points and normal;
//! - [`clearance`]: minimum clearance, pairs within an activation distance,
//!   and the clearance gradient with respect to the joint angles;
//! - [`compiled`]: the [`Scene`] itself.

pub mod broadphase;
pub mod clearance;
pub mod compiled;
pub mod distance;
pub mod obstacle;
pub mod shape;

pub use clearance::Clearance;
pub use compiled::Scene;
pub use obstacle::{Obstacle, ObstacleShape, SceneFile};
