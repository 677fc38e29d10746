//! The scene: obstacles around the robot and signed-distance queries
//! between them and the robot's collision primitives.
//!
//! - [`obstacle`]: the serde types of the request schema and validation;
//! - [`shape`]: obstacles and robot primitives as parry3d shapes;
//! - [`broadphase`]: axis-aligned bounds and their gaps;
//! - [`part_tree`]: a box tree over the parts of a many-part obstacle (a
//!   point cloud), so queries cost what is near the robot;
//! - [`contact`]: [`contact::PairContact`], one pair's answer;
//! - [`distance`]: one pair's signed distance, witness points and normal
//!   ([`round_contact`]: the closed forms for round shapes);
//! - [`clearance`]: minimum clearance, pairs within an activation distance,
//!   and the clearance gradient with respect to the joint angles;
//! - [`compiled`]: the [`Scene`] itself.

pub mod broadphase;
pub mod clearance;
pub mod clip;
pub mod compiled;
pub mod contact;
pub mod distance;
pub mod obstacle;
pub mod obstacle_read;
pub mod part_tree;
pub mod round_contact;
pub mod shape;

pub use clearance::Clearance;
pub use compiled::Scene;
pub use obstacle::{BerryShape, Obstacle, ObstacleShape, SceneFile};

#[cfg(test)]
mod tests {
    fn assert_send_sync<T: Send + Sync>() {}

    #[test]
    fn robot_and_scene_can_be_shared_across_threads() {
        assert_send_sync::<super::Scene>();
        assert_send_sync::<crate::robot::Robot>();
        let scene = super::Scene::empty();
        let copy = std::thread::spawn(move || scene.is_empty()).join().unwrap();
        assert!(copy);
    }
}
