//! `dpmp ros2`: the planner as a native ROS 2 node (cargo feature `ros2`),
//! over the pure-Rust DDS of the `ros2-client` crate: no ROS install.
//!
//! ```text
//! sensor_msgs/Image (colour) ─┐
//! sensor_msgs/Image (depth)  ─┤ inputs: the newest of each, depth paired
//! sensor_msgs/CameraInfo     ─┤ with colour by stamp, stale ones refused
//! sensor_msgs/JointState     ─┤
//! geometry_msgs/TransformStamped (optional camera pose)
//!                             │
//! sensor_msgs/RegionOfInterest (the target) ─► plan ─► trajectory_msgs/JointTrajectory
//!                                   (crate::plan)  └─► diagnostic_msgs/DiagnosticArray
//! ```
//!
//! [`msg`] holds the message layouts (pinned by CDR tests), [`convert`]
//! turns messages into the plan's inputs and its answer into messages,
//! [`inputs`] keeps the newest inputs and matches them to a target,
//! [`plan`] builds the one [`crate::plan::PlanRequest`] `/v1/plan` would,
//! [`config`] reads the ROS-style parameters, [`names`] resolves ROS
//! names, [`dds`] makes topics, readers and writers, [`node`] runs the DDS side, [`controller`] sends `optimal`
//! trajectories to a controller action, and [`replay`] is a stand-in cell
//! that drives a node. Like the HTTP service it is a shell: the planning
//! is the library's, with the service's deadline and limits by default.

pub mod config;
pub mod controller;
pub mod convert;
pub mod dds;
pub mod inputs;
pub mod msg;
pub mod names;
pub mod node;
pub mod plan;
pub mod replay;

pub use config::NodeSettings;
pub use node::{run, spawn, Counters, RunningNode};
