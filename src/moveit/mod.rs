//! MoveIt's messages in: a cell that runs MoveIt describes its world in
//! `moveit_msgs/PlanningScene` and MotionBenchMaker publishes its problems
//! the same way.
//!
//! - [`planning_scene`]: a `PlanningScene` (YAML as `ros2 topic echo` and
//!   MotionBenchMaker write it, or JSON) → the obstacles of the request
//!   schema, every primitive and mesh posed in the robot's base frame.
//!
//! Everything read is validated; what dPMP cannot honour is refused naming
//! the field (a cone, a frame other than the base), never dropped, and what
//! it handles more strictly than MoveIt (an allowed-collision entry between
//! the robot and a world object) is said in the warnings.

pub mod motion_plan_request;
pub mod planning_scene;

pub use motion_plan_request::{read_motion_plan_request, MoveItGoal, MoveItRequest};
pub use planning_scene::{read_planning_scene, MoveItScene};
