//! MoveIt queries planned: `dpmp plan-moveit` and `POST /v1/moveit/plan`
//! give the same answer, the error codes follow what the diagnosis and the
//! solver found, bad input is refused naming the field, and `duration:
//! auto` picks the shortest duration (within 10 %) that keeps the rate
//! limits.

use crate::common::cli::{arg, dpmp, stderr};
use crate::common::http::{
    assert_valid, client, code, field, openapi, post_json, start, test_config, without_timing,
};
use crate::common::robot::panda;
use dpmp::moveit::{
    plan_moveit, DurationChoice, MoveItPlanOptions, MoveItPlanResponse, MoveItQuery,
};
use dpmp::optim::auto_duration::{time_scale_to_limits, AUTO_DURATION_STEP};
use dpmp::optim::problem::linear::RATE_BUFFER;
use dpmp::optim::tolerances::OPTIMALITY_TOLERANCE;
use dpmp::optim::SolveControl;
use serde_json::{json, Value};

const READY: [f64; 7] = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
const GOAL: [f64; 7] = [0.5, -0.3, 0.2, -2.0, 0.1, 1.8, 0.6];

/// A table under the arm and a ball beside it, with `extra` objects.
fn scene(extra: &[Value]) -> Value {
    let mut objects = vec![
        json!({
            "id": "table", "header": {"frame_id": "panda_link0"}, "operation": 0,
            "primitives": [{"type": 1, "dimensions": [1.0, 1.2, 0.02]}],
            "primitive_poses": [{"position": {"x": 0.5, "y": 0.0, "z": -0.05},
                                 "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}]
        }),
        json!({
            "id": "ball", "header": {"frame_id": "panda_link0"}, "operation": 0,
            "primitives": [{"type": 2, "dimensions": [0.05]}],
            "primitive_poses": [{"position": {"x": -0.3, "y": 0.6, "z": 0.9},
                                 "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}]
        }),
    ];
    objects.extend(extra.iter().cloned());
    json!({"name": "test", "is_diff": false, "world": {"collision_objects": objects}})
}

/// A request from `start` to the joint goal `goal` (MoveIt's nine joints:
/// the fingers are in the start state).
fn request(start: &[f64], goal: &[f64], planning_time: f64) -> Value {
    let names: Vec<String> = (1..=7).map(|k| format!("panda_joint{k}")).collect();
    let mut state_names = names.clone();
    state_names.extend(["panda_finger_joint1".into(), "panda_finger_joint2".into()]);
    let mut positions = start.to_vec();
    positions.extend([0.035, 0.035]);
    let constraints: Vec<Value> = names
        .iter()
        .zip(goal)
        .map(|(n, q)| json!({"joint_name": n, "position": q, "tolerance_above": 0.001, "tolerance_below": 0.001, "weight": 1.0}))
        .collect();
    json!({
        "group_name": "panda_arm",
        "start_state": {"joint_state": {"name": state_names, "position": positions}},
        "goal_constraints": [{"joint_constraints": constraints}],
        "max_velocity_scaling_factor": 0.0,
        "max_acceleration_scaling_factor": 0.0,
        "allowed_planning_time": planning_time,
    })
}

fn body(scene: &Value, request: &Value) -> String {
    json!({"planning_scene": scene, "motion_plan_request": request}).to_string()
}

/// The answer without its wall-clock fields.
fn deterministic(mut answer: Value) -> Value {
    answer["moveit"]["planning_time"] = json!(0);
    without_timing(answer)
}

/// A sphere of `radius` on the TCP of `q`.
fn ball_on_tcp(id: &str, q: &[f64], radius: f64) -> Value {
    let p = panda().tcp_pose(q).translation.vector;
    json!({
        "id": id, "header": {"frame_id": "panda_link0"},
        "primitives": [{"type": "sphere", "dimensions": [radius]}],
        "primitive_poses": [{"position": [p.x, p.y, p.z]}]
    })
}

/// `request` in `scene` planned with the defaults, in the library.
fn plan(scene: &Value, request: &Value) -> MoveItPlanResponse {
    plan_with(scene, request, &MoveItPlanOptions::default())
}

fn plan_with(scene: &Value, request: &Value, options: &MoveItPlanOptions) -> MoveItPlanResponse {
    let robot = panda();
    let query = MoveItQuery::read(&scene.to_string(), &request.to_string(), &robot).unwrap();
    plan_moveit(&query, options, &robot, &SolveControl::default()).unwrap()
}

#[test]
fn the_cli_and_the_service_give_the_same_answer_from_yaml_and_json() {
    let blocked = scene(&[ball_on_tcp("on start", &READY, 0.04)]);
    let (scene, request) = (scene(&[]), request(&READY, &GOAL, 30.0));
    let dir = tempfile::tempdir().unwrap();
    // The CLI reads YAML, as `ros2 topic echo` writes it.
    let scene_file = dir.path().join("scene.yaml");
    let request_file = dir.path().join("request.yaml");
    std::fs::write(&scene_file, serde_yaml::to_string(&scene).unwrap()).unwrap();
    std::fs::write(&request_file, serde_yaml::to_string(&request).unwrap()).unwrap();
    let out = dpmp(&[
        "plan-moveit",
        "--scene",
        arg(&scene_file),
        "--request",
        arg(&request_file),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let from_cli: Value = serde_json::from_slice(&out.stdout).unwrap();
    let server = start(test_config());
    let (status, from_http) = post_json(
        &client(),
        &server.url("/v1/moveit/plan"),
        body(&scene, &request),
    );
    assert_eq!(status, 200, "{from_http}");
    assert_eq!(from_http["status"], "optimal", "{from_http}");
    assert_valid(&openapi(), "post", "/v1/moveit/plan", 200, &from_http);
    // A refused start answers 200 with MoveIt's code, in the schema too.
    let (status, refused) = post_json(
        &client(),
        &server.url("/v1/moveit/plan"),
        body(&blocked, &request),
    );
    assert_eq!(status, 200, "{refused}");
    assert_eq!(
        refused["moveit"]["error_code_name"],
        "START_STATE_IN_COLLISION"
    );
    assert_valid(&openapi(), "post", "/v1/moveit/plan", 200, &refused);
    assert_eq!(from_http["moveit"]["error_code"]["val"], 1);
    assert_eq!(from_http["moveit"]["error_code_name"], "SUCCESS");
    let points = from_http["moveit"]["trajectory"]["joint_trajectory"]["points"]
        .as_array()
        .unwrap();
    assert_eq!(points.len(), 150);
    let last = points[149]["positions"].as_array().unwrap();
    for (q, g) in last.iter().zip(GOAL) {
        assert!((q.as_f64().unwrap() - g).abs() < 1e-6);
    }
    // The finger joints of the start state pose the fingers: nothing to
    // warn about within their limits.
    assert_eq!(from_http["moveit"]["warnings"], json!([]));
    assert_eq!(
        serde_json::to_string(&deterministic(from_cli)).unwrap(),
        serde_json::to_string(&deterministic(from_http)).unwrap()
    );
}

#[test]
fn error_codes_follow_the_diagnosis_and_the_solver() {
    let blocked_start = scene(&[ball_on_tcp("on start", &READY, 0.04)]);
    let answer = plan(&blocked_start, &request(&READY, &GOAL, 30.0));
    assert_eq!(answer.moveit.error_code_name, "START_STATE_IN_COLLISION");
    assert_eq!(answer.moveit.error_code.val, -10);
    assert!(answer.moveit.trajectory.joint_trajectory.points.is_empty());
    assert!(answer.result.reason.unwrap().contains("on start"));
    let blocked_goal = scene(&[ball_on_tcp("on goal", &GOAL, 0.04)]);
    let answer = plan(&blocked_goal, &request(&READY, &GOAL, 30.0));
    assert_eq!(answer.moveit.error_code_name, "GOAL_IN_COLLISION");
    assert_eq!(answer.moveit.error_code.val, -12);
    // A planning time too short to verify even the prior mean.
    let answer = plan(&scene(&[]), &request(&READY, &GOAL, 1e-6));
    assert_eq!(answer.moveit.error_code_name, "TIMED_OUT");
    assert_eq!(answer.result.stop_reason, dpmp::optim::StopReason::Deadline);
}

/// `request` with both finger joints of its start state at `opening` (m).
fn with_fingers(mut request: Value, opening: f64) -> Value {
    let positions = &mut request["start_state"]["joint_state"]["position"];
    positions[7] = json!(opening);
    positions[8] = json!(opening);
    request
}

#[test]
fn the_start_states_finger_joints_pose_the_fingers() {
    let robot = panda();
    // A 2 cm ball on the goal's TCP, between the fingertips: 1.8 cm from
    // the open fingers' inner faces, crushed by closed ones.
    let world = scene(&[ball_on_tcp("berry", &GOAL, 0.02)]);
    let goal_code = |opening: f64| {
        let answer = plan(&world, &with_fingers(request(&READY, &GOAL, 30.0), opening));
        (answer.moveit.error_code_name, answer.moveit.warnings)
    };
    for opening in [0.04, 0.03] {
        let (code, _) = goal_code(opening);
        assert_ne!(code, "GOAL_IN_COLLISION", "fingers at {opening} m");
    }
    for opening in [0.0, 0.01] {
        let (code, _) = goal_code(opening);
        assert_eq!(code, "GOAL_IN_COLLISION", "fingers at {opening} m");
    }
    // Beyond franka's 0.04 m the fingers stay at 0.04, with a warning.
    let (code, warnings) = goal_code(0.065);
    assert_ne!(code, "GOAL_IN_COLLISION");
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("0.065 is outside its limits")),
        "{warnings:?}"
    );
    // The independent check: the ball's distance to the finger shapes
    // moved by hand (the loaded shapes shifted along the finger's y axis)
    // at the goal, against the planner's own verdict above.
    let frames = robot.fk(&GOAL);
    let ball = robot.tcp_pose(&GOAL).translation.vector;
    let nearest_finger = |opening: f64| {
        let mut best = f64::INFINITY;
        for side in robot.side_links() {
            let shift = (opening - side.offset_along(&nalgebra::Vector3::y()))
                * (side.pose.rotation * nalgebra::Vector3::y());
            let link_pose = frames.poses[side.chain_link];
            let local = link_pose.inverse() * nalgebra::Point3::from(ball) - shift;
            for &s in &side.shapes {
                let d = robot.collision_shapes()[s]
                    .geometry
                    .signed_distance(&[local.x, local.y, local.z]);
                best = best.min(d);
            }
        }
        best - 0.02
    };
    assert!(nearest_finger(0.04) > 0.015, "{}", nearest_finger(0.04));
    assert!(nearest_finger(0.0) < 0.0, "{}", nearest_finger(0.0));
}

/// `request` with every goal joint's tolerances at `tolerance` (rad).
fn with_goal_tolerance(mut request: Value, tolerance: f64) -> Value {
    for c in request["goal_constraints"][0]["joint_constraints"]
        .as_array_mut()
        .unwrap()
    {
        c["tolerance_above"] = json!(tolerance);
        c["tolerance_below"] = json!(tolerance);
    }
    request
}

#[test]
fn a_goal_with_tolerances_ends_clear_within_them() {
    // A 6 cm ball on the goal's TCP: the constraints' positions themselves
    // are in collision.
    let world = scene(&[ball_on_tcp("berry", &GOAL, 0.06)]);
    let tight = plan(
        &world,
        &with_goal_tolerance(request(&READY, &GOAL, 30.0), 0.001),
    );
    assert_eq!(tight.moveit.error_code_name, "GOAL_IN_COLLISION");
    let tolerance = 0.3;
    let loose = plan(
        &world,
        &with_goal_tolerance(request(&READY, &GOAL, 30.0), tolerance),
    );
    assert_ne!(loose.moveit.error_code_name, "GOAL_IN_COLLISION");
    let end = loose
        .result
        .trajectory
        .points
        .last()
        .unwrap()
        .positions
        .clone();
    for (q, g) in end.iter().zip(GOAL) {
        assert!((q - g).abs() <= tolerance + 1e-6, "{q} vs {g}");
    }
    // Its end keeps the clearance (measured to the meshes' hulls).
    let robot = panda();
    let read = MoveItQuery::read(
        &world.to_string(),
        &request(&READY, &GOAL, 1.0).to_string(),
        &robot,
    );
    let scene = dpmp::scene::Scene::new(read.unwrap().scene.obstacles).unwrap();
    let clearance = scene.min_clearance(&robot, &robot.fk(&end)).unwrap();
    assert!(clearance.distance >= 0.005 - 1e-6, "{}", clearance.distance);
    assert!(
        loose
            .moveit
            .warnings
            .iter()
            .any(|w| w.contains("within the joint constraints' tolerances")),
        "{:?}",
        loose.moveit.warnings
    );
}

#[test]
fn bad_queries_are_refused_naming_the_field() {
    let server = start(test_config());
    let url = server.url("/v1/moveit/plan");
    let c = client();
    let good_scene = scene(&[]);
    let good_request = request(&READY, &GOAL, 30.0);
    let mut outside = GOAL;
    outside[3] = 0.5;
    let mut unknown_joint = good_request.clone();
    unknown_joint["goal_constraints"][0]["joint_constraints"][2]["joint_name"] = json!("elbow");
    let mut negative_tolerance = good_request.clone();
    negative_tolerance["goal_constraints"][0]["joint_constraints"][5]["tolerance_below"] =
        json!(-0.1);
    let torus = scene(&[json!({
        "id": "t", "primitives": [{"type": "torus", "dimensions": [0.1]}],
        "primitive_poses": [{"position": [0.5, 0, 0.5]}]
    })]);
    let skewed = scene(&[json!({
        "id": "q", "primitives": [{"type": 1, "dimensions": [0.1, 0.1, 0.1]}],
        "primitive_poses": [{"position": [0.5, 0, 0.5], "orientation": {"x": 0, "y": 0, "z": 0, "w": 2}}]
    })]);
    let cases: Vec<(String, &str, &str)> = vec![
        (
            body(&good_scene, &request(&READY, &outside, 30.0)),
            "motion_plan_request.goal_constraints[0].joint_constraints[3].position",
            "INVALID_GOAL_CONSTRAINTS",
        ),
        (
            body(&good_scene, &unknown_joint),
            "motion_plan_request.goal_constraints[0].joint_constraints[2].joint_name",
            "elbow",
        ),
        (
            body(&good_scene, &negative_tolerance),
            "motion_plan_request.goal_constraints[0].joint_constraints[5].tolerance_below",
            "-0.1",
        ),
        (
            body(&torus, &good_request),
            "planning_scene.world.collision_objects[2].primitives[0].type",
            "torus",
        ),
        (
            body(&skewed, &good_request),
            "planning_scene.world.collision_objects[2].primitive_poses[0].orientation",
            "unit",
        ),
        (
            json!({"planning_scene": good_scene}).to_string(),
            "motion_plan_request",
            "required",
        ),
        (
            json!({"planning_scene": good_scene, "motion_plan_request": good_request, "duration_s": "soon"}).to_string(),
            "duration_s",
            "auto",
        ),
        (
            json!({"planning_scene": good_scene, "motion_plan_request": good_request, "speed": 1}).to_string(),
            "speed",
            "unknown field",
        ),
    ];
    for (text, expected_field, words) in cases {
        let (status, answer) = post_json(&c, &url, text);
        assert_eq!(status, 422, "{answer}");
        assert_eq!(code(&answer), "invalid_input", "{answer}");
        assert_eq!(field(&answer), Some(expected_field), "{answer}");
        assert!(answer.to_string().contains(words), "{answer}");
    }
    // The CLI: exit 2, the field in the message.
    let dir = tempfile::tempdir().unwrap();
    let scene_file = dir.path().join("scene.json");
    let request_file = dir.path().join("request.json");
    std::fs::write(&scene_file, torus.to_string()).unwrap();
    std::fs::write(&request_file, good_request.to_string()).unwrap();
    let out = dpmp(&[
        "plan-moveit",
        "--scene",
        arg(&scene_file),
        "--request",
        arg(&request_file),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("primitives[0].type"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn auto_duration_is_the_shortest_within_ten_percent_that_keeps_the_rate_limits() {
    for (velocity_scaling, goal) in [
        (0.0, GOAL),
        (0.5, GOAL),
        (0.0, [-0.4, 0.2, -0.3, -1.5, -0.2, 2.2, 1.2]),
    ] {
        let mut request = request(&READY, &goal, 30.0);
        request["max_velocity_scaling_factor"] = json!(velocity_scaling);
        let answer = plan(&scene(&[]), &request);
        let result = &answer.result;
        assert_eq!(
            result.status,
            dpmp::optim::Status::Optimal,
            "{:?}",
            result.reason
        );
        // Within the limits at the chosen duration ...
        let k = time_scale_to_limits(result);
        assert!(k <= 1.0 + 1e-6, "rate ratio scale {k}");
        // ... and a duration 10 % shorter breaks one on the same path
        // (velocity ratios scale with 1/T, acceleration 1/T², jerk 1/T³).
        assert!(
            k * AUTO_DURATION_STEP > 1.0,
            "k {k} at {} s",
            result.duration_s
        );
        let last = &result.trajectory.points.last().unwrap().time_from_start;
        assert!((last - result.duration_s).abs() < 1e-9);
    }
}

/// `duration: auto` retimes the exploring answer instead of searching
/// again. In free space (a convex QP) and past a ball on the mean path
/// (the run from the mean at either duration reaches the same side) that
/// answer is at least as close to the prior as a direct solve at the
/// chosen duration (the direct solve's rate rows keep `RATE_BUFFER` inside
/// the limits that the verification checks, so its feasible set lies
/// within the retimed answer's), and no farther than that buffer moves it,
/// each within the solver's optimality tolerance.
#[test]
fn the_retimed_answer_is_the_direct_solves_at_its_duration() {
    let middle: Vec<f64> = READY
        .iter()
        .zip(&GOAL)
        .map(|(a, b)| 0.5 * (a + b))
        .collect();
    let blocked = scene(&[ball_on_tcp("on the way", &middle, 0.03)]);
    for (velocity_scaling, goal, world) in [
        (0.0, GOAL, scene(&[])),
        (0.5, GOAL, scene(&[])),
        (0.0, [-0.4, 0.2, -0.3, -1.5, -0.2, 2.2, 1.2], scene(&[])),
        (0.0, GOAL, blocked.clone()),
        (0.5, GOAL, blocked),
    ] {
        let mut request = request(&READY, &goal, 30.0);
        request["max_velocity_scaling_factor"] = json!(velocity_scaling);
        let auto = plan(&world, &request).result;
        let fixed = MoveItPlanOptions {
            duration_s: DurationChoice::Seconds(auto.duration_s),
            ..MoveItPlanOptions::default()
        };
        let direct = plan_with(&world, &request, &fixed).result;
        assert_eq!(auto.status, dpmp::optim::Status::Optimal);
        assert_eq!(direct.status, dpmp::optim::Status::Optimal);
        let gap = direct.mahalanobis - auto.mahalanobis;
        // Each run stops within the optimality tolerance of its optimum.
        let slack = OPTIMALITY_TOLERANCE * (1.0 + direct.mahalanobis);
        assert!(
            (-slack..=slack + 2.0 * RATE_BUFFER * (1.0 + direct.mahalanobis)).contains(&gap),
            "Mahalanobis {} retimed vs {} direct at {} s",
            auto.mahalanobis,
            direct.mahalanobis,
            auto.duration_s
        );
        let step = auto
            .weights
            .iter()
            .zip(&direct.weights)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(step <= 1e-2, "weights differ by {step} rad");
    }
}
