//! The node's settings ([`NodeSettings`]): its name and namespace, every
//! topic name, the QoS of the inputs and outputs, the input matching rules,
//! the deadline, and what to plan besides the messages.
//!
//! Read from a ROS 2 parameters file (`--params-file`, the layout
//! `ros2 run --ros-args --params-file` takes):
//!
//! ```yaml
//! dpmp:                      # the node's name, or /** for any node
//!   ros__parameters:
//!     topics:
//!       color: camera/color/image_raw
//!     qos:
//!       sensors: best_effort
//!     plan:
//!       world: depth
//!       task: { clearance_m: 0.02 }
//! ```
//!
//! then the command line's `--namespace`, `--node-name`, `--domain-id`
//! and `--remap from:=to` (ROS's `-r`) on top. Relative topic names
//! resolve in the node's namespace, as in ROS.

use crate::optim::report::TrajectoryFormat;
use crate::optim::{GoalApproach, Task};
use crate::plan::WorldSource;
use crate::service::ServiceConfig;
use crate::{Error, Result};
use serde::Deserialize;
use std::path::Path;
use std::time::Duration;

/// Every topic the node reads or writes (ROS names; relative ones resolve
/// in the node's namespace; an empty name turns an optional one off).
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Topics {
    /// `sensor_msgs/Image`, `rgb8` or `bgr8`.
    pub color: String,
    /// `sensor_msgs/Image` aligned to the colour image, `16UC1` (mm) or
    /// `32FC1` (m).
    pub depth: String,
    /// `sensor_msgs/CameraInfo` of the colour camera.
    pub camera_info: String,
    /// `sensor_msgs/JointState`.
    pub joint_states: String,
    /// `sensor_msgs/RegionOfInterest`: the target berry; each one plans.
    pub target: String,
    /// `geometry_msgs/TransformStamped`: the camera's optical frame in the
    /// robot's base frame; empty (the default): the hand-mounted camera
    /// at the home configuration.
    pub camera_pose: String,
    /// `trajectory_msgs/JointTrajectory` out.
    pub trajectory: String,
    /// `diagnostic_msgs/DiagnosticArray` out: one status per target.
    pub diagnostics: String,
}

impl Default for Topics {
    /// The realsense2_camera and franka_ros2 names.
    fn default() -> Self {
        Topics {
            color: "camera/color/image_raw".into(),
            depth: "camera/aligned_depth_to_color/image_raw".into(),
            camera_info: "camera/color/camera_info".into(),
            joint_states: "joint_states".into(),
            target: "dpmp/target".into(),
            camera_pose: String::new(),
            trajectory: "dpmp/trajectory".into(),
            diagnostics: "dpmp/diagnostics".into(),
        }
    }
}

/// The reliability of a group of topics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// Samples may be lost; matches every publisher (ROS's sensor-data
    /// profile).
    BestEffort,
    /// Lost samples are sent again; matches only reliable publishers.
    Reliable,
}

/// QoS of the inputs and the outputs (history depth 1 on the sensors,
/// 10 on the rest, volatile).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct QosSettings {
    /// Images, camera info, joint states, camera pose (default best
    /// effort: ROS's sensor-data profile).
    pub sensors: Reliability,
    /// The target (default reliable: each one is a request).
    pub target: Reliability,
    /// Trajectory and diagnostics (default reliable, what controllers
    /// expect).
    pub outputs: Reliability,
}

impl Default for QosSettings {
    fn default() -> Self {
        QosSettings {
            sensors: Reliability::BestEffort,
            target: Reliability::Reliable,
            outputs: Reliability::Reliable,
        }
    }
}

/// What to plan besides the messages: the `/v1/plan` fields that are not
/// images, box, camera or start.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanSettings {
    /// Whether the colour images already have the target painted.
    #[serde(default)]
    pub mask_applied: bool,
    /// `depth` (the default: the depth image's cloud is an obstacle) or
    /// `none` (only `task.obstacles`).
    #[serde(default = "depth_world")]
    pub world: WorldSource,
    /// Standoff of the pre-grasp goal (m); default: the pipeline's.
    #[serde(default)]
    pub goal_standoff_m: Option<f64>,
    /// Approach direction of the derived goal.
    #[serde(default)]
    pub goal: Option<GoalApproach>,
    /// `/v1/optimize`'s scene and constraint fields (`obstacles`,
    /// `clearance_m`, `duration_s`, `options`, ...); `start` comes from the
    /// joint states and the trajectory is written for ROS 2.
    #[serde(default)]
    pub task: Task,
}

fn depth_world() -> WorldSource {
    WorldSource::Depth
}

impl Default for PlanSettings {
    fn default() -> Self {
        PlanSettings {
            mask_applied: false,
            world: WorldSource::Depth,
            goal_standoff_m: None,
            goal: None,
            task: Task::default(),
        }
    }
}

/// The controller action the node may send `optimal` answers to.
#[derive(Clone, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerSettings {
    /// `control_msgs/action/FollowJointTrajectory` action name, e.g.
    /// `/fr3_arm_controller/follow_joint_trajectory`; empty (the default):
    /// no goal is sent.
    pub action: String,
}

/// Everything the node is configured with.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeSettings {
    /// Node name (default `dpmp`).
    pub node_name: String,
    /// Node namespace (default: the root).
    pub namespace: String,
    /// DDS domain (`ROS_DOMAIN_ID`; default 0).
    pub domain_id: u16,
    /// Topic names.
    pub topics: Topics,
    /// QoS.
    pub qos: QosSettings,
    /// Colour and depth images pair when their stamps are this close (s).
    pub stamp_tolerance_s: f64,
    /// Inputs received longer ago than this when a target arrives are
    /// stale (s).
    pub max_input_age_s: f64,
    /// Time budget of one plan from the target's arrival (s; default the
    /// HTTP service's deadline).
    pub deadline_s: f64,
    /// Largest image accepted (pixels; default the HTTP service's).
    pub max_image_pixels: u64,
    /// What to plan besides the messages.
    pub plan: PlanSettings,
    /// The controller action.
    pub controller: ControllerSettings,
}

impl Default for NodeSettings {
    /// The topics' defaults, and the HTTP service's deadline and image limit.
    fn default() -> Self {
        let service = ServiceConfig::default();
        NodeSettings {
            node_name: "dpmp".into(),
            namespace: String::new(),
            domain_id: 0,
            topics: Topics::default(),
            qos: QosSettings::default(),
            stamp_tolerance_s: 0.02,
            max_input_age_s: 1.0,
            deadline_s: service.deadline.as_secs_f64(),
            max_image_pixels: service.max_image_pixels,
            plan: PlanSettings::default(),
            controller: ControllerSettings::default(),
        }
    }
}

impl NodeSettings {
    /// Settings from a ROS 2 parameters file: the `ros__parameters` of the
    /// entry named `node_name` (or `/**`), on the defaults.
    pub fn from_params_file(path: &Path, node_name: &str) -> Result<NodeSettings> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let doc: serde_yaml::Value =
            serde_yaml::from_str(&text).map_err(|e| Error::file(path, format!("not YAML: {e}")))?;
        let entry = [node_name, &format!("/{node_name}"), "/**"]
            .iter()
            .find_map(|k| doc.get(*k))
            .ok_or_else(|| {
                Error::file(
                    path,
                    format!("no entry `{node_name}:` (or `/**:`) with `ros__parameters:`"),
                )
            })?;
        let params = entry.get("ros__parameters").ok_or_else(|| {
            Error::file(path, format!("`{node_name}:` has no `ros__parameters:`"))
        })?;
        let mut settings: NodeSettings =
            serde_path_to_error::deserialize(params.clone()).map_err(|e| {
                Error::file(path, format!("ros__parameters.{}: {}", e.path(), e.inner()))
            })?;
        if settings.node_name == NodeSettings::default().node_name {
            settings.node_name = node_name.to_string();
        }
        Ok(settings)
    }

    /// Rename a topic (`from` as a topic's setting or its current name).
    pub fn remap(&mut self, rule: &str) -> Result<()> {
        let (from, to) = rule
            .split_once(":=")
            .ok_or_else(|| Error::invalid("--remap", format!("expected from:=to, got {rule:?}")))?;
        let t = &mut self.topics;
        let slots: [(&str, &mut String); 8] = [
            ("color", &mut t.color),
            ("depth", &mut t.depth),
            ("camera_info", &mut t.camera_info),
            ("joint_states", &mut t.joint_states),
            ("target", &mut t.target),
            ("camera_pose", &mut t.camera_pose),
            ("trajectory", &mut t.trajectory),
            ("diagnostics", &mut t.diagnostics),
        ];
        let mut hit = false;
        for (key, name) in slots {
            if key == from || name.as_str() == from {
                *name = to.to_string();
                hit = true;
            }
        }
        if hit {
            Ok(())
        } else {
            Err(Error::invalid(
                "--remap",
                format!("{from:?} is neither a topic setting nor a topic name"),
            ))
        }
    }

    /// Check every setting; errors name the parameter.
    pub fn validate(&self) -> Result<()> {
        for (name, v, lo, hi) in [
            ("stamp_tolerance_s", self.stamp_tolerance_s, 0.0, 10.0),
            ("max_input_age_s", self.max_input_age_s, 1e-3, 3600.0),
            ("deadline_s", self.deadline_s, 1e-3, 600.0),
        ] {
            crate::error::ensure_in_range(name, v, lo, hi)?;
        }
        if self.max_image_pixels == 0 {
            return Err(Error::invalid("max_image_pixels", "must be positive"));
        }
        let service = ServiceConfig::default();
        let task = &self.plan.task;
        for (field, value, limit) in [
            (
                "plan.task.obstacles",
                task.obstacles.len(),
                service.max_obstacles,
            ),
            ("plan.task.samples", task.samples, service.max_samples),
            (
                "plan.task.promp.n_samples",
                task.promp.n_samples,
                service.max_trajectory_samples,
            ),
        ] {
            if value > limit {
                return Err(Error::invalid(
                    field,
                    format!("at most {limit} (the HTTP service's limit), got {value}"),
                ));
            }
        }
        if self.plan.task.start.is_some() {
            return Err(Error::invalid(
                "plan.task.start",
                "the start is the robot's joint state",
            ));
        }
        if self.plan.task.trajectory_format != TrajectoryFormat::Dpmp {
            return Err(Error::invalid(
                "plan.task.trajectory_format",
                "the node always writes trajectory_msgs/JointTrajectory",
            ));
        }
        let topics = &self.topics;
        for (name, topic) in [
            ("topics.color", &topics.color),
            ("topics.depth", &topics.depth),
            ("topics.camera_info", &topics.camera_info),
            ("topics.joint_states", &topics.joint_states),
            ("topics.target", &topics.target),
            ("topics.trajectory", &topics.trajectory),
            ("topics.diagnostics", &topics.diagnostics),
        ] {
            super::names::topic_name(topic, name)?;
        }
        if !topics.camera_pose.is_empty() {
            super::names::topic_name(&topics.camera_pose, "topics.camera_pose")?;
        }
        if !self.controller.action.is_empty() {
            super::names::topic_name(&self.controller.action, "controller.action")?;
        }
        super::names::node_name(&self.namespace, &self.node_name)?;
        Ok(())
    }

    /// The deadline as a duration.
    pub fn deadline(&self) -> Duration {
        Duration::from_secs_f64(self.deadline_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        std::io::Write::write_all(&mut f, text.as_bytes()).unwrap();
        f
    }

    #[test]
    fn a_params_file_sets_what_it_names_and_keeps_the_defaults() {
        let f = write(
            "dpmp:\n  ros__parameters:\n    topics:\n      color: /cam/rgb\n    qos:\n      sensors: reliable\n    plan:\n      task:\n        clearance_m: 0.03\n",
        );
        let s = NodeSettings::from_params_file(f.path(), "dpmp").unwrap();
        assert_eq!(s.topics.color, "/cam/rgb");
        assert_eq!(s.topics.depth, Topics::default().depth);
        assert_eq!(s.qos.sensors, Reliability::Reliable);
        assert_eq!(s.qos.outputs, Reliability::Reliable);
        assert_eq!(s.plan.task.clearance_m, 0.03);
        assert_eq!(s.plan.world, WorldSource::Depth);
        s.validate().unwrap();
        let any = write("/**:\n  ros__parameters:\n    deadline_s: 0.5\n");
        let s = NodeSettings::from_params_file(any.path(), "picker").unwrap();
        assert_eq!((s.deadline_s, s.node_name.as_str()), (0.5, "picker"));
    }

    #[test]
    fn bad_params_name_the_parameter() {
        let f = write("dpmp:\n  ros__parameters:\n    topics:\n      colour: x\n");
        let e = NodeSettings::from_params_file(f.path(), "dpmp").unwrap_err();
        assert!(e.to_string().contains("topics"), "{e}");
        let f = write("other:\n  ros__parameters: {}\n");
        assert!(NodeSettings::from_params_file(f.path(), "dpmp").is_err());
        let mut s = NodeSettings {
            deadline_s: f64::NAN,
            ..NodeSettings::default()
        };
        assert_eq!(s.validate().unwrap_err().field(), Some("deadline_s"));
        s.deadline_s = 1.0;
        s.topics.target = "bad name!".into();
        assert_eq!(s.validate().unwrap_err().field(), Some("topics.target"));
    }

    #[test]
    fn remaps_rename_by_setting_or_by_name() {
        let mut s = NodeSettings::default();
        s.remap("joint_states:=/franka/joint_states").unwrap();
        s.remap("camera/color/image_raw:=/rgb").unwrap();
        assert_eq!(s.topics.joint_states, "/franka/joint_states");
        assert_eq!(s.topics.color, "/rgb");
        assert_eq!(s.remap("nothing:=x").unwrap_err().field(), Some("--remap"));
        assert_eq!(s.remap("no_arrow").unwrap_err().field(), Some("--remap"));
    }
}
