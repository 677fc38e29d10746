//! The ROS 2 messages the node reads and writes, written field for field
//! from their interface definitions (`.msg` files; Humble and Jazzy agree
//! for every one here). Serde's field order is the wire order: the CDR
//! encoding (XCDR1, what ROS 2's DDS middlewares use) writes the fields in
//! declaration order with natural alignment, sequences and strings with a
//! `uint32` length first, fixed arrays (`float64[9]`) without one.
//! `tests/integration/ros2_cdr.rs` pins every layout against bytes written
//! by hand from the definitions.

use crate::optim::report::RosDuration;
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/Time` (and, same layout, `Duration`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds beyond them, `0..1e9`.
    pub nanosec: u32,
}

impl Time {
    /// The time in seconds.
    pub fn seconds(&self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }
}

impl From<RosDuration> for Time {
    /// The optimiser's ROS-shaped duration (`time_from_start`) as a message.
    fn from(d: RosDuration) -> Time {
        Time {
            sec: d.sec,
            nanosec: d.nanosec,
        }
    }
}

/// `builtin_interfaces/Duration`: the layout of [`Time`].
pub type Duration = Time;

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// `sensor_msgs/Image`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Stamp and optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`rgb8`, `bgr8`, `16UC1`, `32FC1`, ...).
    pub encoding: String,
    /// 1 when the pixel words are big-endian.
    pub is_bigendian: u8,
    /// Row length in bytes.
    pub step: u32,
    /// `step * height` bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/RegionOfInterest`: the target berry's box.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Leftmost pixel column.
    pub x_offset: u32,
    /// Topmost pixel row.
    pub y_offset: u32,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Whether the box is in the rectified image.
    pub do_rectify: bool,
}

/// `sensor_msgs/CameraInfo`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Stamp and optical frame.
    pub header: Header,
    /// Image rows.
    pub height: u32,
    /// Image columns.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, ...
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major: `[fx 0 cx; 0 fy cy; 0 0 1]`.
    pub k: [f64; 9],
    /// Rectification rotation.
    pub r: [f64; 9],
    /// Projection matrix (3 x 4).
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// Region of interest of the sensor.
    pub roi: RegionOfInterest,
}

/// `sensor_msgs/JointState`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp.
    pub header: Header,
    /// Joint names, matched to the robot's by name.
    pub name: Vec<String>,
    /// Positions (rad), one per name.
    pub position: Vec<f64>,
    /// Velocities (rad/s), empty or one per name.
    pub velocity: Vec<f64>,
    /// Efforts, empty or one per name.
    pub effort: Vec<f64>,
}

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `geometry_msgs/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation (m).
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`: the pose of `child_frame_id` in
/// `header.frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The frame posed.
    pub child_frame_id: String,
    /// The pose.
    pub transform: Transform,
}

/// `trajectory_msgs/JointTrajectoryPoint`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectoryPoint {
    /// Positions (rad).
    pub positions: Vec<f64>,
    /// Velocities (rad/s).
    pub velocities: Vec<f64>,
    /// Accelerations (rad/s²).
    pub accelerations: Vec<f64>,
    /// Efforts (empty).
    pub effort: Vec<f64>,
    /// Time from the start of the motion.
    pub time_from_start: Duration,
}

/// `trajectory_msgs/JointTrajectory`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectory {
    /// A zero stamp: "start when received" for ROS 2 controllers.
    pub header: Header,
    /// Joint names, base to tip.
    pub joint_names: Vec<String>,
    /// The points.
    pub points: Vec<JointTrajectoryPoint>,
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// [`DiagnosticStatus::OK`], `WARN`, `ERROR` or `STALE`.
    pub level: u8,
    /// What is reported on (`dpmp: plan`).
    pub name: String,
    /// One line for people.
    pub message: String,
    /// The hardware (empty).
    pub hardware_id: String,
    /// The figures.
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    /// Level: all is well (an `optimal` plan).
    pub const OK: u8 = 0;
    /// Level: an answer that is not `optimal`.
    pub const WARN: u8 = 1;
    /// Level: inputs refused or the plan failed.
    pub const ERROR: u8 = 2;
}

/// `diagnostic_msgs/DiagnosticArray`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// One status per reported item.
    pub status: Vec<DiagnosticStatus>,
}

/// `geometry_msgs/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity.
    pub linear: Vector3,
    /// Angular velocity.
    pub angular: Vector3,
}

/// `trajectory_msgs/MultiDOFJointTrajectoryPoint`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiDofJointTrajectoryPoint {
    /// Poses.
    pub transforms: Vec<Transform>,
    /// Velocities.
    pub velocities: Vec<Twist>,
    /// Accelerations.
    pub accelerations: Vec<Twist>,
    /// Time from the start of the motion.
    pub time_from_start: Duration,
}

/// `trajectory_msgs/MultiDOFJointTrajectory` (empty in dPMP's goals).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiDofJointTrajectory {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Points.
    pub points: Vec<MultiDofJointTrajectoryPoint>,
}

/// `control_msgs/JointTolerance` (0: the controller's default).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTolerance {
    /// Joint name.
    pub name: String,
    /// Position tolerance.
    pub position: f64,
    /// Velocity tolerance.
    pub velocity: f64,
    /// Acceleration tolerance.
    pub acceleration: f64,
}

/// `control_msgs/JointComponentTolerance`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointComponentTolerance {
    /// Joint name.
    pub joint_name: String,
    /// Which component (`X_AXIS = 1`, ...).
    pub component: u16,
    /// Position tolerance.
    pub position: f64,
    /// Velocity tolerance.
    pub velocity: f64,
    /// Acceleration tolerance.
    pub acceleration: f64,
}

/// `control_msgs/action/FollowJointTrajectory`'s goal.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FollowJointTrajectoryGoal {
    /// The trajectory to follow: the published one.
    pub trajectory: JointTrajectory,
    /// Empty.
    pub multi_dof_trajectory: MultiDofJointTrajectory,
    /// Empty: the controller's defaults.
    pub path_tolerance: Vec<JointTolerance>,
    /// Empty.
    pub component_path_tolerance: Vec<JointComponentTolerance>,
    /// Empty: the controller's defaults.
    pub goal_tolerance: Vec<JointTolerance>,
    /// Empty.
    pub component_goal_tolerance: Vec<JointComponentTolerance>,
    /// Zero: the controller's default.
    pub goal_time_tolerance: Duration,
}

/// `control_msgs/action/FollowJointTrajectory`'s result.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FollowJointTrajectoryResult {
    /// 0 on success; negative codes for the failures.
    pub error_code: i32,
    /// Why, for people.
    pub error_string: String,
}

/// `control_msgs/action/FollowJointTrajectory`'s feedback.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FollowJointTrajectoryFeedback {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Where the joints should be.
    pub desired: JointTrajectoryPoint,
    /// Where they are.
    pub actual: JointTrajectoryPoint,
    /// The difference.
    pub error: JointTrajectoryPoint,
    /// Multi-DOF joint names.
    pub multi_dof_joint_names: Vec<String>,
    /// Multi-DOF desired.
    pub multi_dof_desired: MultiDofJointTrajectoryPoint,
    /// Multi-DOF actual.
    pub multi_dof_actual: MultiDofJointTrajectoryPoint,
    /// Multi-DOF error.
    pub multi_dof_error: MultiDofJointTrajectoryPoint,
}

impl ros2_client::Message for FollowJointTrajectoryGoal {}
impl ros2_client::Message for FollowJointTrajectoryResult {}
impl ros2_client::Message for FollowJointTrajectoryFeedback {}
