//! The ROS 2 node on loopback (feature `ros2`): a stand-in cell
//! ([`dpmp::ros2::replay::Cell`]) publishes a generated dataset record as
//! ROS 2 messages (colour, aligned depth, camera info, joint state, target
//! box); the dPMP node answers with a `JointTrajectory` equal to
//! `/v1/plan`'s for the same inputs (1e-9) within the plan's time budget.
//! Malformed messages (wrong encoding, undecodable bytes, NaN and unknown
//! joints, a size mismatch, unpaired stamps) are refused with a
//! diagnostics message naming the field, and the node goes on to plan the
//! next good target the same way.
//!
//! Both nodes run in this process on a DDS domain of their own (RustDDS:
//! UDP on loopback, no ROS install).

use crate::common::http::{client, post_json, start_with_default_model};
use base64::Engine as _;
use dpmp::net::Model;
use dpmp::optim::report::RosDuration;
use dpmp::robot::Robot;
use dpmp::ros2::config::Reliability;
use dpmp::ros2::msg::{
    DiagnosticStatus, FollowJointTrajectoryFeedback, FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult, JointTrajectory, Time,
};
use dpmp::ros2::replay::{Cell, Frame};
use dpmp::ros2::NodeSettings;
use dpmp::synth::dataset::TargetRecord;
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use ros2_client::action::{ActionServerQosPolicies, SendGoalResponse};
use ros2_client::{ActionTypeName, MessageTypeName, Name, Publisher, ServiceMapping};
use serde_json::{json, Value};
use std::sync::Arc;
use std::time::Duration;

/// The plan's time budget in this test (debug build, loaded machine).
const DEADLINE_S: f64 = 60.0;

/// Time for the node to take in what the cell published.
const SETTLE: Duration = Duration::from_millis(300);

/// A domain of this test run's own, away from ROS's default 0; one per
/// test (`test` 0, 1 or 2), as they run at once. Domains 1-100 keep every
/// RTPS port (`7400 + 250 d + …`) below Linux's ephemeral range (32768 and
/// up), where another socket of the busy test process could hold one.
fn domain(test: u16) -> u16 {
    1 + 3 * (std::process::id() % 33) as u16 + test
}

/// How long the cells wait for DDS discovery: generous, because the whole
/// suite shares two cores while these tests run.
const DISCOVERY: Duration = Duration::from_secs(90);

/// How far past its timeout a failed discovery wait may return (one poll,
/// scheduling on a loaded machine).
const DISCOVERY_SLACK: Duration = Duration::from_secs(10);

/// The test side's runtime (one thread: the cell's loop).
fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// A generated plant: its record, its images as messages and as PNGs.
struct Scene {
    record: TargetRecord,
    frame: Frame,
    png: Vec<u8>,
    depth_png: Vec<u8>,
}

/// A start a little off home, with the joints in reverse order and a
/// gripper finger among them.
fn off_home(robot: &Robot) -> Vec<f64> {
    robot
        .home()
        .iter()
        .enumerate()
        .map(|(i, q)| q + 0.01 * (i as f64 - 3.0))
        .collect()
}

fn scene(robot: &Robot, model: &Model) -> Scene {
    let generator = Generator::new(SynthSettings::new(1, 1), robot.clone()).unwrap();
    let out = generator.config(21, 0).unwrap();
    let depth = out.depths[0].clone().unwrap();
    let record = out.records[0].clone();
    let start = off_home(robot);
    let mut frame = Frame::new(
        &out.images[0],
        &depth,
        &model.config().camera_model(),
        record.bbox,
        robot.joint_names(),
        &start,
    )
    .unwrap();
    let js = &mut frame.joint_state;
    js.name.reverse();
    js.position.reverse();
    js.name.push("panda_finger_joint1".into());
    js.position.push(0.04);
    let mut png = Vec::new();
    image::DynamicImage::ImageRgb8(out.images[0].clone())
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    Scene {
        record,
        frame,
        png,
        depth_png: depth.encode_png().unwrap(),
    }
}

fn settings(record: &TargetRecord) -> NodeSettings {
    let mut s = NodeSettings {
        namespace: "picker".into(),
        domain_id: domain(0),
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
    let b64 = |b: &[u8]| base64::engine::general_purpose::STANDARD.encode(b);
    let r = scene.frame.roi;
    let body = json!({
        "image_base64": b64(&scene.png),
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

/// Colour and depth stamped `half_seconds` / 2 s apart from 0 (each its own).
fn stamps(color: i32, depth: i32) -> (Time, Time) {
    let t = |h: i32| RosDuration::from_seconds(0.5 * f64::from(h)).into();
    (t(color), t(depth))
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
    let model = Model::shipped().unwrap();
    let robot = Robot::panda().unwrap();
    let scene = scene(&robot, &model);
    let settings = settings(&scene.record);
    let node = dpmp::ros2::spawn(
        settings.clone(),
        Arc::new(model.clone()),
        Arc::new(robot.clone()),
    )
    .unwrap();
    let http = http_plan(&scene, &model, &off_home(&robot));
    assert_eq!(http["status"], "optimal", "{}", http["reason"]);
    let timeout = Duration::from_secs_f64(DEADLINE_S + 30.0);
    runtime().block_on(async {
        let mut cell = Cell::new(&settings).unwrap();
        // One byte on the colour topic: not an Image.
        let image = MessageTypeName::new("sensor_msgs", "Image");
        let qos = ros2_client::QosProfile::subscription_default()
            .reliability_reliable(ros2_client::qos::WhenFull::DEFAULT);
        let garbage_topic = cell
            .node_mut()
            .create_topic(&Name::parse(&settings.topics.color).unwrap(), image, &qos)
            .unwrap();
        let garbage: Publisher<u8> = cell
            .node_mut()
            .create_publisher(&garbage_topic, None)
            .unwrap();
        cell.wait_for_node(DISCOVERY).await.unwrap();
        let good = &scene.frame;

        // A good target: the trajectory /v1/plan gives, in the budget.
        cell.sensors(good, stamps(2, 2), SETTLE).await.unwrap();
        let answer = cell.request(good.roi, timeout).await.unwrap();
        assert_eq!(answer.status.level, DiagnosticStatus::OK, "{answer:?}");
        assert!(answer.round_trip_s <= DEADLINE_S, "{answer:?}");
        assert_same_trajectory(answer.trajectory.as_ref().unwrap(), &http);
        assert!(answer.value("plan_ms").unwrap() > 0.0);
        assert!(answer.value("target_to_publish_ms").unwrap() >= answer.value("plan_ms").unwrap());

        // Bad messages: each refused, naming what was wrong.
        let with = |f: &dyn Fn(&mut Frame)| {
            let mut frame = good.clone();
            f(&mut frame);
            frame
        };
        let cases = [
            (
                with(&|f| f.color.encoding = "mono8".into()),
                "color.encoding",
            ),
            (with(&|f| f.depth.data.truncate(100)), "depth.data"),
            (
                with(&|f| f.joint_state.position[2] = f64::NAN),
                "joint_states.position",
            ),
            (
                with(&|f| f.joint_state.name[0] = "elbow".into()),
                "joint_states.name",
            ),
        ];
        for (i, (frame, field)) in cases.iter().enumerate() {
            let t = 4 + 2 * i as i32;
            cell.sensors(frame, stamps(t, t), SETTLE).await.unwrap();
            let answer = cell.request(frame.roi, timeout).await.unwrap();
            assert_eq!(answer.status.level, DiagnosticStatus::ERROR, "{answer:?}");
            assert!(answer.status.message.contains(field), "{field}: {answer:?}");
            assert!(answer.trajectory.is_none());
        }
        // A depth image 0.5 s away from the colour one does not pair.
        cell.sensors(good, stamps(20, 21), SETTLE).await.unwrap();
        let answer = cell.request(good.roi, timeout).await.unwrap();
        assert_eq!(answer.status.level, DiagnosticStatus::ERROR, "{answer:?}");
        assert!(
            answer.status.message.contains("no depth image within"),
            "{answer:?}"
        );
        garbage.publish(7).unwrap();
        tokio::time::sleep(SETTLE).await;

        // The node goes on: the good target plans the same trajectory.
        cell.sensors(good, stamps(30, 30), SETTLE).await.unwrap();
        let answer = cell.request(good.roi, timeout).await.unwrap();
        assert_eq!(answer.status.level, DiagnosticStatus::OK, "{answer:?}");
        assert_same_trajectory(answer.trajectory.as_ref().unwrap(), &http);
        drop(garbage);
        cell.close().await;
    });
    let counters = node.stop().unwrap();
    assert_eq!(counters.undecodable, 1, "{counters:?}");
    // The four bad messages, each counted as it arrived.
    assert_eq!(counters.rejected, 4, "{counters:?}");
    assert_eq!(counters.refused, 5, "{counters:?}");
    assert_eq!(
        (counters.planned, counters.optimal, counters.published),
        (2, 2, 2),
        "{counters:?}"
    );
}

/// The controller's action in the action test.
const ACTION: &str = "/fr3_arm_controller/follow_joint_trajectory";

type Server = ros2_client::ActionServer<
    FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult,
    FollowJointTrajectoryFeedback,
>;

/// A stand-in `FollowJointTrajectory` server on the cell's node.
fn controller(cell: &mut Cell) -> Server {
    let qos = ros2_client::QosProfile::subscription_default()
        .reliability_reliable(ros2_client::qos::WhenFull::DEFAULT)
        .history(ros2_client::qos::History::KeepLast { depth: 10 });
    let policies = ActionServerQosPolicies {
        goal_service: qos.clone(),
        result_service: qos.clone(),
        cancel_service: qos.clone(),
        feedback_publisher: qos.clone(),
        status_publisher: qos,
    };
    cell.node_mut()
        .create_action_server(
            ServiceMapping::Enhanced,
            &Name::parse(ACTION).unwrap(),
            &ActionTypeName::new("control_msgs", "FollowJointTrajectory"),
            policies,
        )
        .unwrap()
}

/// The next goal the server receives within `wait`, accepted.
async fn next_goal(server: &Server, wait: Duration) -> Option<FollowJointTrajectoryGoal> {
    let until = std::time::Instant::now() + wait;
    while std::time::Instant::now() < until {
        if let Ok(Some((id, request))) = server.receive_goal() {
            let accepted = SendGoalResponse {
                accepted: true,
                stamp: ros2_client::builtin_interfaces::Time::now(),
            };
            server.send_goal_response(id, accepted).unwrap();
            return Some(request.goal);
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    None
}

#[test]
fn only_optimal_answers_reach_the_controller_action() {
    let model = Model::shipped().unwrap();
    let robot = Robot::panda().unwrap();
    let scene = scene(&robot, &model);
    // Two nodes in two namespaces, one controller: `picker` plans in
    // time, `hasty` has a 1 ms budget (its answers are not `optimal`).
    let node_settings = |namespace: &str, deadline_s: f64| {
        let mut s = NodeSettings {
            namespace: namespace.into(),
            domain_id: domain(1),
            deadline_s,
            max_input_age_s: 30.0,
            ..NodeSettings::default()
        };
        s.qos.sensors = Reliability::Reliable;
        s.plan.mask_applied = true;
        s.controller.action = ACTION.into();
        s
    };
    let (picker, hasty) = (
        node_settings("picker", DEADLINE_S),
        node_settings("hasty", 1e-3),
    );
    let (model, robot) = (Arc::new(model), Arc::new(robot));
    let nodes = [&picker, &hasty]
        .map(|s| dpmp::ros2::spawn(s.clone(), model.clone(), robot.clone()).unwrap());
    let timeout = Duration::from_secs_f64(DEADLINE_S + 30.0);
    runtime().block_on(async {
        let mut hasty_cell = Cell::new(&hasty).unwrap();
        let mut cell = Cell::new(&picker).unwrap();
        let server = controller(&mut cell);
        cell.wait_for_node(DISCOVERY).await.unwrap();
        hasty_cell.wait_for_node(DISCOVERY).await.unwrap();
        let frame = &scene.frame;

        hasty_cell
            .sensors(frame, stamps(2, 2), SETTLE)
            .await
            .unwrap();
        let answer = hasty_cell.request(frame.roi, timeout).await.unwrap();
        assert_eq!(answer.status.level, DiagnosticStatus::WARN, "{answer:?}");
        assert!(answer.trajectory.is_none());
        assert!(next_goal(&server, Duration::from_secs(2)).await.is_none());

        cell.sensors(frame, stamps(2, 2), SETTLE).await.unwrap();
        let answer = cell.request(frame.roi, timeout).await.unwrap();
        assert_eq!(answer.status.level, DiagnosticStatus::OK, "{answer:?}");
        let goal = next_goal(&server, Duration::from_secs(20)).await.unwrap();
        assert_eq!(Some(&goal.trajectory), answer.trajectory.as_ref());
        assert!(goal.path_tolerance.is_empty() && goal.multi_dof_trajectory.points.is_empty());
        drop(server);
        cell.close().await;
        hasty_cell.close().await;
    });
    let [picker, hasty] = nodes.map(|n| n.stop().unwrap());
    assert_eq!((picker.goals_sent, picker.optimal), (1, 1), "{picker:?}");
    assert_eq!(
        (hasty.goals_sent, hasty.optimal, hasty.planned),
        (0, 0, 1),
        "{hasty:?}"
    );
}

#[test]
fn a_cell_with_no_node_gives_up_in_time_naming_every_unmatched_topic() {
    let settings = NodeSettings {
        domain_id: domain(2),
        ..NodeSettings::default()
    };
    let wait = Duration::from_millis(300);
    let started = std::time::Instant::now();
    let err = runtime().block_on(async {
        let mut cell = Cell::new(&settings).unwrap();
        let err = cell.wait_for_node(wait).await.unwrap_err();
        cell.close().await;
        err
    });
    let waited = started.elapsed();
    assert!(
        waited >= wait && waited < wait + DISCOVERY_SLACK,
        "{waited:?}"
    );
    let message = err.to_string();
    for topic in [
        "color",
        "depth",
        "camera_info",
        "joint_states",
        "target",
        "trajectory",
        "diagnostics",
    ] {
        assert!(message.contains(topic), "{topic} missing from {message}");
    }
}
