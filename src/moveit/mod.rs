//! MoveIt's messages in: a cell that runs MoveIt describes its world in
//! `moveit_msgs/PlanningScene` and MotionBenchMaker publishes its problems
//! the same way.
//!
//! - [`planning_scene`]: a `PlanningScene` (YAML as `ros2 topic echo` and
//!   MotionBenchMaker write it, or JSON) → the obstacles of the request
//!   schema, every primitive and mesh posed in the robot's base frame.
//! - [`motion_plan_request`]: a `MotionPlanRequest` → the start, the goal,
//!   the scaling factors and the planning time, in the robot's joints;
//!   [`fingers`]: the finger joints of its start state pose the fingers'
//!   collision geometry; [`joint_goal`]: a joint goal's tolerances →
//!   the configuration planned to.
//! - [`plan`]: both planned ([`plan_moveit`], what `dpmp plan-moveit` and
//!   `POST /v1/moveit/plan` call): the optimise answer, a
//!   `moveit_msgs/RobotTrajectory` and an [`error_code`].
//!
//! Everything read is validated; what dPMP cannot honour is refused naming
//! the field (a cone, a frame other than the base), never dropped, and what
//! it handles more strictly than MoveIt (an allowed-collision entry between
//! the robot and a world object) is said in the warnings.

pub mod error_code;
pub mod fingers;
pub mod joint_goal;
pub mod motion_plan_request;
pub mod plan;
pub mod planning_scene;

pub use error_code::MoveItErrorCode;
pub use plan::{plan_moveit, DurationChoice, MoveItPlanOptions, MoveItPlanResponse, MoveItQuery};

pub use motion_plan_request::{read_motion_plan_request, MoveItGoal, MoveItRequest};
pub use planning_scene::{read_planning_scene, MoveItScene};
