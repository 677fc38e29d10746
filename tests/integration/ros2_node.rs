//! The ROS 2 node on loopback (feature `ros2`): a test node publishes a
//! generated dataset record as ROS 2 messages (colour, aligned depth,
//! camera info, joint state, target box); the dPMP node answers with a
//! `JointTrajectory` equal to `/v1/plan`'s for the same inputs (1e-9)
//! within the plan's time budget. Malformed messages (wrong encoding,
//! undecodable bytes, NaN and unknown joints, a size mismatch) are refused
//! with a diagnostics message naming the field, and the node goes on to
//! plan the next good target the same way.
//!
//! Both nodes run in this process on their own DDS domain (RustDDS:
//! UDP on loopback, no ROS install).

use crate::common::http::{client, post_json, start_with_default_model};
use base64::Engine as _;
use dpmp::net::Model;
use dpmp::optim::report::RosDuration;
use dpmp::robot::Robot;
use dpmp::ros2::config::Reliability;
use dpmp::ros2::msg::{
    CameraInfo, DiagnosticArray, DiagnosticStatus, Header, Image, JointState, JointTrajectory,
    RegionOfInterest, Time,
};
use dpmp::ros2::NodeSettings;
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use futures::StreamExt;
use ros2_client::qos::{History, WhenFull};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    QosProfile, Subscription,
};
use serde::Serialize;
use serde_json::{json, Value};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The plan's time budget in this test (debug build, loaded machine).
const DEADLINE_S: f64 = 60.0;

/// A domain of this test's own, away from ROS's default 0.
fn domain() -> u16 {
    100 + (std::process::id() % 100) as u16
}

fn reliable() -> QosProfile {
    QosProfile::subscription_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .history(History::KeepLast { depth: 10 })
}

/// A generated plant: colour, aligned depth (mm) and the record.
struct Scene {
    color: Image,
    depth: Image,
    roi: RegionOfInterest,
    record: dpmp::synth::dataset::TargetRecord,
    rgb: image::RgbImage,
    depth_png: Vec<u8>,
}

fn scene() -> Scene {
    let generator = Generator::new(SynthSettings::new(1, 1), Robot::panda().unwrap()).unwrap();
    let out = generator.config(21, 0).unwrap();
    let rgb = out.images[0].clone();
    let depth = out.depths[0].clone().unwrap();
    assert_eq!(depth.scale_m(), 0.001);
    let (w, h) = (rgb.width(), rgb.height());
    let record = out.records[0].clone();
    let b = record.bbox;
    let roi = RegionOfInterest {
        x_offset: b[0].floor() as u32,
        y_offset: b[1].floor() as u32,
        width: (b[2].ceil() - b[0].floor()) as u32,
        height: (b[3].ceil() - b[1].floor()) as u32,
        do_rectify: false,
    };
    Scene {
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
            data: depth.units().iter().flat_map(|u| u.to_le_bytes()).collect(),
        },
        roi,
        record,
        rgb,
        depth_png: depth.encode_png().unwrap(),
    }
}

fn camera_info(model: &Model) -> CameraInfo {
    let i = model.config().camera_model().intrinsics;
    CameraInfo {
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
    }
}

/// A start a little off home, with the gripper's fingers and the joints
/// in another order than the robot's.
fn joint_state(robot: &Robot) -> (JointState, Vec<f64>) {
    let start: Vec<f64> = robot
        .home()
        .iter()
        .enumerate()
        .map(|(i, q)| q + 0.01 * (i as f64 - 3.0))
        .collect();
    let mut name: Vec<String> = robot.joint_names().iter().rev().cloned().collect();
    let mut position: Vec<f64> = start.iter().rev().copied().collect();
    name.push("panda_finger_joint1".into());
    position.push(0.04);
    (
        JointState {
            name,
            position,
            ..JointState::default()
        },
        start,
    )
}

/// The test node: the camera, the robot and the picker.
struct Cell {
    node: Node,
    color: Publisher<Image>,
    depth: Publisher<Image>,
    info: Publisher<CameraInfo>,
    joints: Publisher<JointState>,
    target: Publisher<RegionOfInterest>,
    trajectory: Subscription<JointTrajectory>,
    diagnostics: Subscription<DiagnosticArray>,
    /// One byte, on the colour topic: not an Image.
    garbage: Publisher<u8>,
    _context: Context,
}

fn topic(node: &Node, name: &str, ty: (&str, &str)) -> ros2_client::dds::rustdds::Topic {
    node.create_topic(
        &Name::parse(name).unwrap(),
        MessageTypeName::new(ty.0, ty.1),
        &reliable(),
    )
    .unwrap()
}

fn publisher<M: Serialize>(node: &mut Node, name: &str, ty: (&str, &str)) -> Publisher<M> {
    let t = topic(node, name, ty);
    node.create_publisher(&t, None).unwrap()
}

impl Cell {
    fn new(t: &dpmp::ros2::config::Topics) -> Cell {
        let context = Context::with_options(ContextOptions::new().domain_id(domain())).unwrap();
        let mut node = context
            .new_node(NodeName::new("/", "cell").unwrap(), NodeOptions::new())
            .unwrap();
        let image = ("sensor_msgs", "Image");
        let color = publisher(&mut node, &t.color, image);
        let depth = publisher(&mut node, &t.depth, image);
        let info = publisher(&mut node, &t.camera_info, ("sensor_msgs", "CameraInfo"));
        let joints = publisher(&mut node, &t.joint_states, ("sensor_msgs", "JointState"));
        let target = publisher(&mut node, &t.target, ("sensor_msgs", "RegionOfInterest"));
        let tt = topic(&node, &t.trajectory, ("trajectory_msgs", "JointTrajectory"));
        let trajectory = node.create_subscription(&tt, None).unwrap();
        let dt = topic(
            &node,
            &t.diagnostics,
            ("diagnostic_msgs", "DiagnosticArray"),
        );
        let diagnostics = node.create_subscription(&dt, None).unwrap();
        let garbage = publisher(&mut node, &t.color, image);
        Cell {
            node,
            color,
            depth,
            info,
            joints,
            target,
            trajectory,
            diagnostics,
            garbage,
            _context: context,
        }
    }

    /// Wait until the dPMP node has matched every topic.
    async fn wait_for_the_node(&self) {
        let all = async {
            self.color.wait_for_subscription(&self.node).await;
            self.depth.wait_for_subscription(&self.node).await;
            self.info.wait_for_subscription(&self.node).await;
            self.joints.wait_for_subscription(&self.node).await;
            self.target.wait_for_subscription(&self.node).await;
            self.trajectory.wait_for_publisher(&self.node).await;
            self.diagnostics.wait_for_publisher(&self.node).await;
        };
        tokio::time::timeout(Duration::from_secs(30), all)
            .await
            .expect("the dPMP node matched the cell's topics within 30 s");
        // The writers have matched the node's readers; give the readers the
        // same moment to match the writers (discovery runs both ways).
        tokio::time::sleep(Duration::from_millis(1500)).await;
    }

    /// Publish a colour and depth pair with one stamp, the camera info and
    /// the joint state; give the node a moment to take them in.
    async fn sensors(
        &self,
        color: &Image,
        depth: &Image,
        info: &CameraInfo,
        joints: &JointState,
        stamp: i32,
    ) {
        self.sensors_at(color, depth, info, joints, (stamp, stamp))
            .await
    }

    /// [`Cell::sensors`] with a stamp for the colour and one for the depth
    /// (half seconds).
    async fn sensors_at(
        &self,
        color: &Image,
        depth: &Image,
        info: &CameraInfo,
        joints: &JointState,
        stamps: (i32, i32),
    ) {
        let stamped = |m: &Image, half_seconds: i32| Image {
            header: Header {
                stamp: RosDuration::from_seconds(0.5 * f64::from(half_seconds)).into(),
                frame_id: "camera_color_optical_frame".into(),
            },
            ..m.clone()
        };
        self.info.publish(info.clone()).unwrap();
        self.joints.publish(joints.clone()).unwrap();
        self.color.publish(stamped(color, stamps.0)).unwrap();
        self.depth.publish(stamped(depth, stamps.1)).unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
    }

    /// Send the target; the diagnostics that answer it and, when the plan
    /// was `optimal`, the trajectory; with the time to the diagnostics.
    async fn plan(
        &self,
        roi: RegionOfInterest,
    ) -> (DiagnosticStatus, Option<JointTrajectory>, f64) {
        let sent = Instant::now();
        self.target.publish(roi).unwrap();
        let diagnostics = self.diagnostics.async_stream();
        futures::pin_mut!(diagnostics);
        let (status, _) = tokio::time::timeout(
            Duration::from_secs_f64(DEADLINE_S + 30.0),
            diagnostics.next(),
        )
        .await
        .expect("diagnostics within the deadline")
        .unwrap()
        .unwrap();
        let elapsed = sent.elapsed().as_secs_f64();
        let status = status.status.into_iter().next().unwrap();
        let trajectory = if status.level == DiagnosticStatus::OK {
            let trajectories = self.trajectory.async_stream();
            futures::pin_mut!(trajectories);
            let (t, _) = tokio::time::timeout(Duration::from_secs(10), trajectories.next())
                .await
                .expect("the trajectory with its diagnostics")
                .unwrap()
                .unwrap();
            Some(t)
        } else {
            None
        };
        (status, trajectory, elapsed)
    }
}

fn settings(record: &dpmp::synth::dataset::TargetRecord) -> NodeSettings {
    let mut s = NodeSettings {
        namespace: "picker".into(),
        domain_id: domain(),
        deadline_s: DEADLINE_S,
        max_input_age_s: 30.0,
        ..NodeSettings::default()
    };
    s.qos.sensors = Reliability::Reliable;
    s.plan.mask_applied = true;
    s.plan.task = serde_json::from_value(json!({
        "obstacles": record.scene.obstacles(),
        "clearance_m": 0.02,
    }))
    .unwrap();
    // Absolute names for the cell's side, as a launch file would remap.
    for (from, to) in [
        ("color", "/cam/color/image_raw"),
        ("depth", "/cam/aligned_depth_to_color/image_raw"),
        ("camera_info", "/cam/color/camera_info"),
        ("joint_states", "/joint_states"),
        ("target", "/picker/target"),
        ("trajectory", "/picker/trajectory"),
        ("diagnostics", "/picker/diagnostics"),
    ] {
        s.remap(&format!("{from}:={to}")).unwrap();
    }
    s
}

/// `/v1/plan`'s answer for the same inputs as JSON (PNG colour, the depth
/// PNG in mm, the camera info's intrinsics, the joint state's start).
fn http_plan(scene: &Scene, model: &Model, start: &[f64]) -> Value {
    let server = start_with_default_model();
    let mut png = Vec::new();
    image::DynamicImage::ImageRgb8(scene.rgb.clone())
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let b64 = |b: &[u8]| base64::engine::general_purpose::STANDARD.encode(b);
    let r = scene.roi;
    let body = json!({
        "image_base64": b64(&png),
        "depth_base64": b64(&scene.depth_png),
        "target_box": [r.x_offset, r.y_offset, r.x_offset + r.width, r.y_offset + r.height],
        "mask_applied": true,
        "world": "depth",
        "camera": model.config().camera_model(),
        "start": start,
        "obstacles": scene.record.scene.obstacles(),
        "clearance_m": 0.02,
        "trajectory_format": "ros2",
    });
    let (s, answer) = post_json(&client(), &server.url("/v1/plan"), body.to_string());
    assert_eq!(s, 200, "{answer}");
    answer
}

fn assert_same_trajectory(t: &JointTrajectory, http: &Value) {
    let h = &http["trajectory"];
    assert_eq!(
        t.joint_names,
        serde_json::from_value::<Vec<String>>(h["joint_names"].clone()).unwrap()
    );
    let points = h["points"].as_array().unwrap();
    assert_eq!(t.points.len(), points.len());
    let mut worst = 0.0f64;
    for (p, q) in t.points.iter().zip(points) {
        for (key, ours) in [
            ("positions", &p.positions),
            ("velocities", &p.velocities),
            ("accelerations", &p.accelerations),
        ] {
            let theirs: Vec<f64> = serde_json::from_value(q[key].clone()).unwrap();
            assert_eq!(ours.len(), theirs.len(), "{key}");
            for (a, b) in ours.iter().zip(&theirs) {
                worst = worst.max((a - b).abs());
            }
        }
        let time: Time = serde_json::from_value(q["time_from_start"].clone()).unwrap();
        assert_eq!(p.time_from_start, time);
    }
    assert!(worst <= 1e-9, "node vs /v1/plan differ by {worst}");
}

#[test]
fn the_node_plans_what_v1_plan_plans_and_survives_bad_messages() {
    let _ = tracing_subscriber::fmt()
        .with_test_writer()
        .with_env_filter("dpmp=info")
        .try_init();
    let scene = scene();
    let model = Model::shipped().unwrap();
    let robot = Robot::panda().unwrap();
    let settings = settings(&scene.record);
    let topics = settings.topics.clone();
    let node =
        dpmp::ros2::spawn(settings, Arc::new(model.clone()), Arc::new(robot.clone())).unwrap();
    let http = http_plan(&scene, &model, &joint_state(&robot).1);
    assert_eq!(http["status"], "optimal", "{}", http["reason"]);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let cell = Cell::new(&topics);
        cell.wait_for_the_node().await;
        let info = camera_info(&model);
        let (joints, _) = joint_state(&robot);

        // A good target: the trajectory /v1/plan gives, in the budget.
        cell.sensors(&scene.color, &scene.depth, &info, &joints, 1)
            .await;
        let (status, trajectory, seconds) = cell.plan(scene.roi).await;
        assert_eq!(status.level, DiagnosticStatus::OK, "{status:?}");
        assert!(seconds <= DEADLINE_S, "{seconds} s");
        assert_same_trajectory(&trajectory.unwrap(), &http);
        let plan_ms = status.values.iter().find(|kv| kv.key == "plan_ms").unwrap();
        assert!(plan_ms.value.parse::<f64>().unwrap() > 0.0);

        // Bad messages: each refused, naming what was wrong.
        let mono = Image {
            encoding: "mono8".into(),
            ..scene.color.clone()
        };
        let mut short = scene.depth.clone();
        short.data.truncate(short.data.len() / 2);
        let mut nan = joints.clone();
        nan.position[2] = f64::NAN;
        let mut unknown = joints.clone();
        unknown.name[0] = "elbow".into();
        for (stamp, color, depth, joints, field) in [
            (2, &mono, &scene.depth, &joints, "color.encoding"),
            (3, &scene.color, &short, &joints, "depth.data"),
            (4, &scene.color, &scene.depth, &nan, "joint_states.position"),
            (5, &scene.color, &scene.depth, &unknown, "joint_states.name"),
        ] {
            cell.sensors(color, depth, &info, joints, stamp).await;
            let (status, trajectory, _) = cell.plan(scene.roi).await;
            assert_eq!(status.level, DiagnosticStatus::ERROR, "{status:?}");
            assert!(
                status.message.contains(field),
                "{field}: {}",
                status.message
            );
            assert!(trajectory.is_none());
        }
        // A depth image 0.5 s away from the colour one does not pair.
        cell.sensors_at(&scene.color, &scene.depth, &info, &joints, (6, 7))
            .await;
        let (status, _, _) = cell.plan(scene.roi).await;
        assert_eq!(status.level, DiagnosticStatus::ERROR, "{status:?}");
        assert!(
            status.message.contains("no depth image within"),
            "{}",
            status.message
        );
        // Bytes that are no Image at all on the colour topic.
        cell.garbage.publish(7).unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;

        // The node goes on: the good target plans the same trajectory.
        cell.sensors(&scene.color, &scene.depth, &info, &joints, 8)
            .await;
        let (status, trajectory, _) = cell.plan(scene.roi).await;
        assert_eq!(status.level, DiagnosticStatus::OK, "{status:?}");
        assert_same_trajectory(&trajectory.unwrap(), &http);
    });
    let counters = node.stop().unwrap();
    assert_eq!(counters.undecodable, 1, "{counters:?}");
    assert_eq!(counters.refused, 5, "{counters:?}");
    assert_eq!(
        (counters.planned, counters.optimal, counters.published),
        (2, 2, 2),
        "{counters:?}"
    );
}
