//! A stand-in robot cell on DDS: it publishes what a hand camera and a
//! robot would (colour, aligned depth, camera info, joint states) and a
//! target box, and reads the node's answers. `dpmp ros2 replay` drives a
//! node with it (no camera or robot needed), the latency figure is measured
//! with it, and the loopback test uses it.

use super::config::{NodeSettings, Reliability};
use super::dds::{advertise, dds, qos, subscribe};
use super::msg::{
    CameraInfo, DiagnosticArray, DiagnosticStatus, Header, Image, JointState, JointTrajectory,
    RegionOfInterest, Time,
};
use super::names::node_name;
use crate::perception::{CameraModel, DepthImage};
use crate::{Error, Result};
use futures::StreamExt;
use image::RgbImage;
use ros2_client::{
    Context, ContextOptions, Node, NodeOptions, Publisher, QosProfile, Subscription,
};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::time::{Duration, Instant};

/// How often [`Cell::wait_for_node`] looks at the match tables.
const DISCOVERY_POLL: Duration = Duration::from_millis(20);

/// The messages of one camera frame and robot state, with a target.
#[derive(Clone, Debug)]
pub struct Frame {
    /// `rgb8` colour image.
    pub color: Image,
    /// `16UC1` aligned depth (mm).
    pub depth: Image,
    /// The camera's intrinsics.
    pub camera_info: CameraInfo,
    /// The robot's joint state.
    pub joint_state: JointState,
    /// The target box.
    pub roi: RegionOfInterest,
}

impl Frame {
    /// A frame from rendered images: the camera's intrinsics, the robot at
    /// `start` (joints named `joint_names`), the target box `bbox` (pixels,
    /// widened to whole pixels).
    pub fn new(
        rgb: &RgbImage,
        depth: &DepthImage,
        camera: &CameraModel,
        bbox: [f64; 4],
        joint_names: &[String],
        start: &[f64],
    ) -> Result<Frame> {
        let (w, h) = (rgb.width(), rgb.height());
        if (depth.width(), depth.height()) != (w, h) {
            return Err(Error::invalid("depth", "not the colour image's size"));
        }
        let millimetres = |u: u16| (f64::from(u) * depth.scale_m() * 1e3).round() as u16;
        let i = camera.intrinsics;
        Ok(Frame {
            color: Image {
                header: Header::default(),
                height: h,
                width: w,
                encoding: "rgb8".into(),
                is_bigendian: 0,
                step: 3 * w,
                data: rgb.as_raw().clone(),
            },
            depth: Image {
                header: Header::default(),
                height: h,
                width: w,
                encoding: "16UC1".into(),
                is_bigendian: 0,
                step: 2 * w,
                data: depth
                    .units()
                    .iter()
                    .flat_map(|&u| millimetres(u).to_le_bytes())
                    .collect(),
            },
            camera_info: CameraInfo {
                width: i.width,
                height: i.height,
                distortion_model: "plumb_bob".into(),
                d: vec![0.0; 5],
                k: [i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0],
                r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                p: [
                    i.fx, 0.0, i.cx, 0.0, 0.0, i.fy, i.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
                ],
                ..CameraInfo::default()
            },
            joint_state: JointState {
                name: joint_names.to_vec(),
                position: start.to_vec(),
                ..JointState::default()
            },
            roi: roi_around(bbox),
        })
    }
}

/// The smallest whole-pixel box holding `bbox`.
pub fn roi_around(bbox: [f64; 4]) -> RegionOfInterest {
    let (x, y) = (bbox[0].floor().max(0.0), bbox[1].floor().max(0.0));
    RegionOfInterest {
        x_offset: x as u32,
        y_offset: y as u32,
        width: (bbox[2].ceil() - x).max(0.0) as u32,
        height: (bbox[3].ceil() - y).max(0.0) as u32,
        do_rectify: false,
    }
}

/// What the node answered to one target.
#[derive(Clone, Debug)]
pub struct Answer {
    /// Its diagnostics.
    pub status: DiagnosticStatus,
    /// The trajectory, when `optimal`.
    pub trajectory: Option<JointTrajectory>,
    /// Target published → diagnostics received (s).
    pub round_trip_s: f64,
}

impl Answer {
    /// A diagnostics value as a number.
    pub fn value(&self, key: &str) -> Option<f64> {
        self.status
            .values
            .iter()
            .find(|kv| kv.key == key)
            .and_then(|kv| kv.value.parse().ok())
    }
}

/// The cell: publishers of the node's inputs, subscribers of its outputs.
pub struct Cell {
    color: Publisher<Image>,
    depth: Publisher<Image>,
    info: Publisher<CameraInfo>,
    joints: Publisher<JointState>,
    target: Publisher<RegionOfInterest>,
    trajectory: Subscription<JointTrajectory>,
    diagnostics: Subscription<DiagnosticArray>,
    // Dropped after the publishers and subscriptions (declaration order).
    node: Node,
    /// The node's spinner until [`Cell::wait_for_node`] starts it.
    spinner: Option<ros2_client::Spinner>,
    /// The spinner's task once started.
    spinning: Option<tokio::task::JoinHandle<()>>,
    _context: Context,
}

/// Reliable, keep the last 10: nothing the cell sends is lost.
fn reliable() -> QosProfile {
    qos(Reliability::Reliable, 10)
}

fn publisher<M: Serialize>(node: &mut Node, name: &str, ty: (&str, &str)) -> Result<Publisher<M>> {
    advertise(node, name, name, ty, &reliable())
}

fn subscription<M: 'static + DeserializeOwned>(
    node: &mut Node,
    name: &str,
    ty: (&str, &str),
) -> Result<Subscription<M>> {
    subscribe(node, name, name, ty, &reliable())
}

impl Cell {
    /// A cell for a node with `settings` (its domain, its namespace, its
    /// topics), as a node named `cell`.
    pub fn new(settings: &NodeSettings) -> Result<Cell> {
        let context = Context::with_options(ContextOptions::new().domain_id(settings.domain_id))
            .map_err(|e| dds("context", e))?;
        let mut node = context
            .new_node(node_name(&settings.namespace, "cell")?, NodeOptions::new())
            .map_err(|e| dds("node", e))?;
        let t = &settings.topics;
        let image = ("sensor_msgs", "Image");
        let spinner = Some(node.spinner().map_err(|e| dds("spinner", e))?);
        Ok(Cell {
            spinner,
            spinning: None,
            color: publisher(&mut node, &t.color, image)?,
            depth: publisher(&mut node, &t.depth, image)?,
            info: publisher(&mut node, &t.camera_info, ("sensor_msgs", "CameraInfo"))?,
            joints: publisher(&mut node, &t.joint_states, ("sensor_msgs", "JointState"))?,
            target: publisher(&mut node, &t.target, ("sensor_msgs", "RegionOfInterest"))?,
            trajectory: subscription(
                &mut node,
                &t.trajectory,
                ("trajectory_msgs", "JointTrajectory"),
            )?,
            diagnostics: subscription(
                &mut node,
                &t.diagnostics,
                ("diagnostic_msgs", "DiagnosticArray"),
            )?,
            node,
            _context: context,
        })
    }

    /// Stop the spinner (dropping the node tells it to) and wait for it,
    /// then the rest: every DDS entity goes before its participant.
    pub async fn close(self) {
        let Cell { node, spinning, .. } = self;
        drop(node);
        if let Some(task) = spinning {
            let _ = task.await;
        }
    }

    /// The cell's ROS node (for extra publishers of its own).
    pub fn node_mut(&mut self) -> &mut Node {
        &mut self.node
    }

    /// Start the cell's spinner (it keeps the match tables this reads)
    /// and wait until the node has matched every topic both ways.
    ///
    /// The wait polls the node's match tables rather than awaiting
    /// ros2-client's `wait_for_subscription`: that future wakes on graph
    /// events sent into a channel of 8 with `try_send`, and on a busy
    /// machine a burst of discovery traffic fills it, drops the one match
    /// event the wait needs, and leaves it waiting after discovery is done.
    /// The tables themselves are updated on every match.
    pub async fn wait_for_node(&mut self, timeout: Duration) -> Result<()> {
        if let Some(spinner) = self.spinner.take() {
            self.spinning = Some(tokio::spawn(async move {
                if let Err(e) = spinner.spin().await {
                    tracing::warn!(error = ?e, "the cell's spinner stopped");
                }
            }));
        }
        let until = Instant::now() + timeout;
        loop {
            let unmatched = self.unmatched_topics();
            if unmatched.is_empty() {
                break;
            }
            if Instant::now() >= until {
                let what = format!(
                    "no dpmp node matched within {timeout:?} (unmatched: {})",
                    unmatched.join(", ")
                );
                return Err(dds("discovery", what));
            }
            tokio::time::sleep(DISCOVERY_POLL).await;
        }
        // The writers have seen the node's readers; give the readers a
        // moment to match the writers too (discovery runs both ways).
        tokio::time::sleep(Duration::from_millis(500)).await;
        Ok(())
    }

    /// The cell's topics with no matched node endpoint yet: its
    /// publishers with no reader and its subscriptions with no writer.
    fn unmatched_topics(&self) -> Vec<&'static str> {
        let node = &self.node;
        [
            ("color", self.color.get_subscription_count(node)),
            ("depth", self.depth.get_subscription_count(node)),
            ("camera_info", self.info.get_subscription_count(node)),
            ("joint_states", self.joints.get_subscription_count(node)),
            ("target", self.target.get_subscription_count(node)),
            ("trajectory", self.trajectory.get_publisher_count(node)),
            ("diagnostics", self.diagnostics.get_publisher_count(node)),
        ]
        .into_iter()
        .filter(|&(_, matched)| matched == 0)
        .map(|(topic, _)| topic)
        .collect()
    }

    /// Publish the camera info, the joint state and the colour and depth
    /// images (stamped `stamps`), then wait `settle` for the node to take
    /// them in.
    pub async fn sensors(
        &self,
        frame: &Frame,
        stamps: (Time, Time),
        settle: Duration,
    ) -> Result<()> {
        let stamped = |m: &Image, stamp: Time| Image {
            header: Header {
                stamp,
                frame_id: "camera_color_optical_frame".into(),
            },
            ..m.clone()
        };
        let failed = |e| dds("publish", e);
        self.info
            .publish(frame.camera_info.clone())
            .map_err(|e| failed(format!("{e:?}")))?;
        self.joints
            .publish(frame.joint_state.clone())
            .map_err(|e| failed(format!("{e:?}")))?;
        self.color
            .publish(stamped(&frame.color, stamps.0))
            .map_err(|e| failed(format!("{e:?}")))?;
        self.depth
            .publish(stamped(&frame.depth, stamps.1))
            .map_err(|e| failed(format!("{e:?}")))?;
        tokio::time::sleep(settle).await;
        Ok(())
    }

    /// Send a target and wait (up to `timeout`) for the diagnostics that
    /// answer it and, when `optimal`, the trajectory.
    pub async fn request(&self, roi: RegionOfInterest, timeout: Duration) -> Result<Answer> {
        let sent = Instant::now();
        self.target
            .publish(roi)
            .map_err(|e| dds("publish", format!("{e:?}")))?;
        let status = next(&self.diagnostics, timeout)
            .await?
            .status
            .into_iter()
            .next()
            .ok_or_else(|| dds("diagnostics", "an empty DiagnosticArray"))?;
        let round_trip_s = sent.elapsed().as_secs_f64();
        let trajectory = match status.level {
            DiagnosticStatus::OK => Some(next(&self.trajectory, Duration::from_secs(10)).await?),
            _ => None,
        };
        Ok(Answer {
            status,
            trajectory,
            round_trip_s,
        })
    }
}

/// The next message of `sub`, within `timeout`.
async fn next<M: 'static + DeserializeOwned>(
    sub: &Subscription<M>,
    timeout: Duration,
) -> Result<M> {
    let stream = sub.async_stream();
    futures::pin_mut!(stream);
    match tokio::time::timeout(timeout, stream.next()).await {
        Ok(Some(Ok((m, _)))) => Ok(m),
        Ok(Some(Err(e))) => Err(dds("read", e)),
        Ok(None) | Err(_) => Err(dds("read", format!("no answer within {timeout:?}"))),
    }
}
