//! The node itself: DDS subscriptions in, the plan loop, publications out.
//!
//! One task reads every subscription; each message updates the
//! [`LatestInputs`] or, for a target, queues a plan. One plan runs at a
//! time on the blocking pool (with the deadline of the target's arrival
//! plus `deadline_s`); a target arriving while one runs replaces the one
//! waiting (`superseded`). Each finished plan publishes a
//! `DiagnosticArray` (status, reason, timings) and, when `optimal`, the
//! `JointTrajectory`. A message that cannot be decoded, or is refused by a
//! check, is logged and counted; nothing stops the node but [`RunningNode::stop`].

use super::config::NodeSettings;
use super::controller::{controller, follow, Controller};
use super::convert::{
    camera_model, check_colour, check_depth, diagnostics, distortion_norm, start_configuration,
    trajectory_message,
};
use super::dds::{advertise, dds, qos, subscribe};
use super::inputs::{LatestInputs, MatchRules};
use super::msg::{
    CameraInfo, DiagnosticArray, DiagnosticStatus, Image, JointState, JointTrajectory,
    RegionOfInterest, TransformStamped,
};
use super::names::node_name;
use super::plan::{camera_pose, plan_request};
use crate::net::Model;
use crate::optim::report::{RosDuration, Status};
use crate::optim::SolveControl;
use crate::plan::{predict_and_optimize, PlanResponse};
use crate::robot::Robot;
use crate::{Error, Result};
use futures::{pin_mut, Stream, StreamExt};
use ros2_client::{Context, ContextOptions, MessageInfo, NodeOptions, Publisher, Subscription};
use serde::de::DeserializeOwned;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What the node has seen and done, for logs and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Messages decoded, every topic.
    pub received: u64,
    /// Messages that could not be decoded.
    pub undecodable: u64,
    /// Messages decoded but failing a check on receipt (encoding, size,
    /// NaN, unknown joints, camera model): kept as the newest, so a target
    /// that would use one is refused naming the field.
    pub rejected: u64,
    /// Targets refused: stale, unmatched or bad inputs.
    pub refused: u64,
    /// Targets replaced by a newer one before their plan started.
    pub superseded: u64,
    /// Plans that ran.
    pub planned: u64,
    /// Of them, `optimal`.
    pub optimal: u64,
    /// Trajectories published.
    pub published: u64,
    /// Goals sent to the controller action (`optimal` answers only).
    pub goals_sent: u64,
}

/// A node running on its own thread.
pub struct RunningNode {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<Result<Counters>>>,
}

impl RunningNode {
    /// Stop the node (a plan in flight is cancelled) and return its counts.
    pub fn stop(mut self) -> Result<Counters> {
        self.stop.store(true, Ordering::Relaxed);
        self.join()
    }

    /// Wait for the node to stop by itself (it stops only on an error).
    pub fn join(&mut self) -> Result<Counters> {
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| Error::Numerical("the ROS 2 node's thread panicked".into()))?,
            None => Ok(Counters::default()),
        }
    }
}

impl Drop for RunningNode {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.join();
    }
}

/// Start the node on a thread of its own.
pub fn spawn(settings: NodeSettings, model: Arc<Model>, robot: Arc<Robot>) -> Result<RunningNode> {
    settings.validate()?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let thread = std::thread::Builder::new()
        .name("dpmp-ros2".into())
        .spawn(move || run(settings, model, robot, flag))
        .map_err(|e| Error::Numerical(format!("cannot start the ROS 2 node's thread: {e}")))?;
    Ok(RunningNode {
        stop,
        thread: Some(thread),
    })
}

/// Run the node until `stop` is set.
pub fn run(
    settings: NodeSettings,
    model: Arc<Model>,
    robot: Arc<Robot>,
    stop: Arc<AtomicBool>,
) -> Result<Counters> {
    settings.validate()?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Error::Numerical(format!("cannot start the node's runtime: {e}")))?;
    runtime.block_on(serve(settings, model, robot, stop))
}

/// Depth of the sensor topics' history: the newest matters.
const SENSOR_HISTORY: usize = 1;
/// Depth of the target and output topics' history.
const REQUEST_HISTORY: usize = 10;

/// The node's publications.
struct Outputs {
    trajectory: Publisher<JointTrajectory>,
    diagnostics: Publisher<DiagnosticArray>,
    /// The controller action, when one is configured.
    controller: Option<Arc<Controller>>,
}

/// A target waiting for its plan.
struct Target {
    roi: RegionOfInterest,
    at: Instant,
}

/// A plan that finished.
struct PlanDone {
    target_at: Instant,
    plan_ms: f64,
    result: Result<PlanResponse>,
}

/// Everything the loop keeps between messages.
struct NodeState {
    settings: Arc<NodeSettings>,
    model: Arc<Model>,
    robot: Arc<Robot>,
    stop: Arc<AtomicBool>,
    inputs: LatestInputs,
    pending: Option<Target>,
    counters: Counters,
    bad_by_topic: std::collections::HashMap<String, u64>,
    warned_distortion: bool,
}

impl NodeState {
    /// A decoded message, or a count and a log line for one that was not.
    fn decoded<M>(
        &mut self,
        topic: &str,
        item: ros2_client::ReadResult<(M, MessageInfo)>,
    ) -> Option<M> {
        match item {
            Ok((msg, _)) => {
                self.counters.received += 1;
                Some(msg)
            }
            Err(e) => {
                self.counters.undecodable += 1;
                self.log_bad(topic, "undecodable message ignored", &format!("{e:?}"));
                None
            }
        }
    }

    /// Count and log a message that failed its check on receipt.
    fn checked(&mut self, topic: &str, check: Result<()>) {
        if let Err(e) = check {
            self.counters.rejected += 1;
            self.log_bad(topic, "bad message", &e.to_string());
        }
    }

    /// Log a bad message: the first of each topic, then every 100th (a
    /// camera sending bad frames at 30 Hz must not flood the log).
    fn log_bad(&mut self, topic: &str, what: &str, reason: &str) {
        let n = self.bad_by_topic.entry(topic.to_string()).or_insert(0);
        *n += 1;
        if *n % 100 == 1 {
            tracing::warn!(topic, count = *n, reason, "{what}");
        }
    }

    fn on_color(&mut self, msg: Image, at: Instant) {
        let check = check_colour(&msg, "color", self.settings.max_image_pixels);
        self.checked("color", check.map(|_| ()));
        self.inputs.color(msg, at);
    }

    fn on_depth(&mut self, msg: Image, at: Instant) {
        let check = check_depth(&msg, "depth", self.settings.max_image_pixels);
        self.checked("depth", check);
        self.inputs.depth(msg, at);
    }

    fn on_joint_state(&mut self, msg: JointState, at: Instant) {
        let check = start_configuration(&msg, "joint_states", self.robot.joint_names());
        self.checked("joint_states", check.map(|_| ()));
        self.inputs.joint_state(msg, at);
    }

    fn on_camera_pose(&mut self, msg: TransformStamped, at: Instant) {
        let check = camera_pose(&msg, "camera_pose");
        self.checked("camera_pose", check.map(|_| ()));
        self.inputs.camera_pose(msg, at);
    }

    fn on_camera_info(&mut self, msg: CameraInfo, at: Instant) {
        let check = camera_model(&msg, "camera_info", &self.model.config().camera_model());
        self.checked("camera_info", check.map(|_| ()));
        if !self.warned_distortion && distortion_norm(&msg) > 1e-6 {
            self.warned_distortion = true;
            tracing::warn!(
                largest = distortion_norm(&msg),
                "camera_info has distortion; the pinhole model ignores it (rectify the images)"
            );
        }
        self.inputs.camera_info(msg, at);
    }

    fn on_target(&mut self, roi: RegionOfInterest, at: Instant) {
        if self.pending.replace(Target { roi, at }).is_some() {
            self.counters.superseded += 1;
            tracing::info!("a newer target replaced the one waiting");
        }
    }

    /// Start the waiting target's plan, or refuse it (a diagnostics
    /// message says why).
    fn start_plan(&mut self, outputs: &Outputs) -> Option<tokio::task::JoinHandle<PlanDone>> {
        let target = self.pending.take()?;
        let rules = MatchRules {
            stamp_tolerance_s: self.settings.stamp_tolerance_s,
            max_age: Duration::from_secs_f64(self.settings.max_input_age_s),
        };
        let matched = match self.inputs.matched(target.at, &rules) {
            Ok(m) => m,
            Err(e) => {
                self.refuse(&e, outputs);
                return None;
            }
        };
        let (settings, model, robot) = (
            self.settings.clone(),
            self.model.clone(),
            self.robot.clone(),
        );
        let control = SolveControl {
            deadline: Some(target.at + settings.deadline()),
            cancel: Some(self.stop.clone()),
            sharing: None,
        };
        Some(tokio::task::spawn_blocking(move || {
            let started = Instant::now();
            let result = plan_request(&matched, &target.roi, &settings, &model, &robot)
                .and_then(|request| predict_and_optimize(&model, &robot, request, &control));
            PlanDone {
                target_at: target.at,
                plan_ms: started.elapsed().as_secs_f64() * 1e3,
                result,
            }
        }))
    }

    fn refuse(&mut self, e: &Error, outputs: &Outputs) {
        self.counters.refused += 1;
        tracing::warn!(reason = %e, "target refused");
        let c = self.counters;
        let values = [
            ("refused", c.refused.to_string()),
            ("received", c.received.to_string()),
            ("undecodable", c.undecodable.to_string()),
            ("rejected", c.rejected.to_string()),
        ];
        publish_diagnostics(
            outputs,
            DiagnosticStatus::ERROR,
            format!("refused: {e}"),
            &values,
        );
    }

    /// Publish what a plan gave: the trajectory when `optimal`, always the
    /// diagnostics.
    fn finish_plan(&mut self, done: PlanDone, outputs: &Outputs) {
        let response = match done.result {
            Ok(r) => r,
            Err(e) => return self.refuse(&e, outputs),
        };
        self.counters.planned += 1;
        let result = &response.result;
        let optimal = result.status == Status::Optimal;
        if optimal {
            self.counters.optimal += 1;
            let message = trajectory_message(&result.trajectory);
            // Only an `optimal` answer ever reaches the controller.
            if let Some(controller) = &outputs.controller {
                self.counters.goals_sent += 1;
                tokio::spawn(follow(controller.clone(), message.clone()));
            }
            match outputs.trajectory.publish(message) {
                Ok(()) => self.counters.published += 1,
                Err(e) => tracing::error!(error = ?e, "the trajectory could not be published"),
            }
        }
        let latency_ms = done.target_at.elapsed().as_secs_f64() * 1e3;
        let (level, message) = if optimal {
            (DiagnosticStatus::OK, "optimal".to_string())
        } else {
            let reason = result.reason.clone().unwrap_or_default();
            (
                DiagnosticStatus::WARN,
                format!(
                    "{}: {reason}; no trajectory published",
                    result.status.as_str()
                ),
            )
        };
        tracing::info!(
            status = result.status.as_str(),
            stop_reason = result.stop_reason.as_str(),
            plan_ms = done.plan_ms,
            latency_ms,
            "planned"
        );
        let values = [
            ("status", result.status.as_str().to_string()),
            ("stop_reason", result.stop_reason.as_str().to_string()),
            ("plan_ms", format!("{:.3}", done.plan_ms)),
            ("solve_ms", format!("{:.3}", result.report.solve_ms)),
            ("target_to_publish_ms", format!("{latency_ms:.3}")),
            ("mahalanobis", format!("{:.6}", result.mahalanobis)),
            ("model", response.model.clone()),
            ("published", self.counters.published.to_string()),
            ("refused", self.counters.refused.to_string()),
            ("undecodable", self.counters.undecodable.to_string()),
            ("rejected", self.counters.rejected.to_string()),
        ];
        publish_diagnostics(outputs, level, message, &values);
    }
}

fn publish_diagnostics(outputs: &Outputs, level: u8, message: String, values: &[(&str, String)]) {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    let msg = diagnostics(
        RosDuration::from_seconds(now).into(),
        level,
        message,
        values,
    );
    if let Err(e) = outputs.diagnostics.publish(msg) {
        tracing::error!(error = ?e, "diagnostics could not be published");
    }
}

/// An optional subscription's stream, or one that never yields.
fn optional_stream<'a, M: 'static + DeserializeOwned>(
    sub: Option<&'a Subscription<M>>,
) -> impl Stream<Item = ros2_client::ReadResult<(M, MessageInfo)>> + 'a {
    match sub {
        Some(s) => s.async_stream().left_stream(),
        None => futures::stream::pending().right_stream(),
    }
}

async fn serve(
    settings: NodeSettings,
    model: Arc<Model>,
    robot: Arc<Robot>,
    stop: Arc<AtomicBool>,
) -> Result<Counters> {
    let context = Context::with_options(ContextOptions::new().domain_id(settings.domain_id))
        .map_err(|e| dds("context", e))?;
    let mut node = context
        .new_node(
            node_name(&settings.namespace, &settings.node_name)?,
            NodeOptions::new().enable_rosout(true),
        )
        .map_err(|e| dds("node", e))?;
    let spinner = node.spinner().map_err(|e| dds("spinner", e))?;
    let spinning = tokio::spawn(async move {
        if let Err(e) = spinner.spin().await {
            tracing::error!(error = ?e, "the ROS 2 spinner stopped");
        }
    });
    let topics = settings.topics.clone();
    let sensors = qos(settings.qos.sensors, SENSOR_HISTORY);
    let image_type = ("sensor_msgs", "Image");
    let color = subscribe::<Image>(
        &mut node,
        &topics.color,
        "topics.color",
        image_type,
        &sensors,
    )?;
    let depth = subscribe::<Image>(
        &mut node,
        &topics.depth,
        "topics.depth",
        image_type,
        &sensors,
    )?;
    let info = subscribe::<CameraInfo>(
        &mut node,
        &topics.camera_info,
        "topics.camera_info",
        ("sensor_msgs", "CameraInfo"),
        &sensors,
    )?;
    let joints = subscribe::<JointState>(
        &mut node,
        &topics.joint_states,
        "topics.joint_states",
        ("sensor_msgs", "JointState"),
        &sensors,
    )?;
    let target = subscribe::<RegionOfInterest>(
        &mut node,
        &topics.target,
        "topics.target",
        ("sensor_msgs", "RegionOfInterest"),
        &qos(settings.qos.target, REQUEST_HISTORY),
    )?;
    let pose = match topics.camera_pose.as_str() {
        "" => None,
        name => Some(subscribe::<TransformStamped>(
            &mut node,
            name,
            "topics.camera_pose",
            ("geometry_msgs", "TransformStamped"),
            &sensors,
        )?),
    };
    let out_qos = qos(settings.qos.outputs, REQUEST_HISTORY);
    let outputs = Outputs {
        trajectory: advertise(
            &mut node,
            &topics.trajectory,
            "topics.trajectory",
            ("trajectory_msgs", "JointTrajectory"),
            &out_qos,
        )?,
        diagnostics: advertise(
            &mut node,
            &topics.diagnostics,
            "topics.diagnostics",
            ("diagnostic_msgs", "DiagnosticArray"),
            &out_qos,
        )?,
        controller: match settings.controller.action.as_str() {
            "" => None,
            name => Some(Arc::new(controller(&mut node, name)?)),
        },
    };
    tracing::info!(
        node = %settings.node_name,
        namespace = %settings.namespace,
        domain = settings.domain_id,
        "dpmp ROS 2 node up"
    );
    let mut state = NodeState {
        settings: Arc::new(settings),
        model,
        robot,
        stop: stop.clone(),
        inputs: LatestInputs::default(),
        pending: None,
        counters: Counters::default(),
        bad_by_topic: Default::default(),
        warned_distortion: false,
    };
    let (color, depth, info, joints, target) = (
        color.async_stream(),
        depth.async_stream(),
        info.async_stream(),
        joints.async_stream(),
        target.async_stream(),
    );
    let pose = optional_stream(pose.as_ref());
    pin_mut!(color, depth, info, joints, target, pose);
    let mut in_flight: Option<tokio::task::JoinHandle<PlanDone>> = None;
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    while !stop.load(Ordering::Relaxed) {
        let mut finished = None;
        let plan = async {
            match in_flight.as_mut() {
                Some(handle) => handle.await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            _ = tick.tick() => {}
            Some(item) = color.next() => {
                if let Some(m) = state.decoded("color", item) { state.on_color(m, Instant::now()) }
            }
            Some(item) = depth.next() => {
                if let Some(m) = state.decoded("depth", item) { state.on_depth(m, Instant::now()) }
            }
            Some(item) = info.next() => {
                if let Some(m) = state.decoded("camera_info", item) { state.on_camera_info(m, Instant::now()) }
            }
            Some(item) = joints.next() => {
                if let Some(m) = state.decoded("joint_states", item) { state.on_joint_state(m, Instant::now()) }
            }
            Some(item) = pose.next() => {
                if let Some(m) = state.decoded("camera_pose", item) { state.on_camera_pose(m, Instant::now()) }
            }
            Some(item) = target.next() => {
                if let Some(m) = state.decoded("target", item) { state.on_target(m, Instant::now()) }
            }
            done = plan => finished = Some(done),
        }
        if let Some(done) = finished {
            in_flight = None;
            match done {
                Ok(done) => state.finish_plan(done, &outputs),
                Err(e) => tracing::error!(error = %e, "a plan's task failed"),
            }
        }
        if in_flight.is_none() {
            in_flight = state.start_plan(&outputs);
        }
    }
    if let Some(handle) = in_flight {
        let _ = handle.await;
    }
    // Dropping the node stops its spinner; its readers go before the
    // participant (the context, dropped last).
    drop(node);
    let _ = spinning.await;
    tracing::info!(counters = ?state.counters, "dpmp ROS 2 node stopped");
    Ok(state.counters)
}
