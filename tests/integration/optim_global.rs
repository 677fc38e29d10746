//! The global stage: a motion whose prior mean collides (with a wall, or
//! at a position goal with a berry beside the target) races a run from a
//! collision-free path found in configuration space; the answer is
//! `optimal`, clear of the obstacles against the meshes at 10,000 phases,
//! and the same bytes on one or two threads.

use crate::common::requests::answer_with_threads;
use dpmp::optim::{optimize, OptimizeRequest, OptimizeResponse, Status, FEASIBILITY_TOLERANCE};
use dpmp::promp::Basis;
use dpmp::robot::Robot;
use dpmp::scene::Scene;
use nalgebra::DMatrix;
use serde_json::json;

/// A swing of joint 1 from -1 to +1 rad in the ready pose, across a wall
/// 75 cm tall in front of the robot (`x` from 0.25 to 0.85 m, in the
/// plane `y = 0`): the smoothest motion (the smooth prior's mean) passes
/// the hand through it.
fn swing_across_a_wall() -> OptimizeRequest {
    let ready = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let mut start = ready;
    start[0] = -1.0;
    let mut end = ready;
    end[0] = 1.0;
    serde_json::from_value(json!({
        "start": start,
        "options": {"final_configuration": end},
        "boundary": "rest",
        "duration_s": 4.0,
        "clearance_m": 0.01,
        "obstacles": [{
            "type": "box", "id": "wall",
            "center": [0.55, 0.0, 0.375],
            "half_extents": [0.3, 0.01, 0.375],
            "rotation": [0.0, 0.0, 0.0, 1.0]
        }],
    }))
    .unwrap()
}

/// The smooth prior's mean swings the hand through the wall, but its run
/// leaves the wall within its head start: the planner is abandoned and
/// that run goes on alone to the certified answer.
#[test]
fn a_mean_that_leaves_the_wall_within_its_head_start_needs_no_race() {
    let robot = Robot::panda().unwrap();
    let req = swing_across_a_wall();
    let problem = req.validate(&robot).unwrap();
    let mean = problem.prior().mean.as_slice().to_vec();
    let at_mean = problem.evaluate(&mean);
    assert!(
        at_mean.min_clearance_m.unwrap() < 0.0,
        "the mean must collide: {at_mean:?}"
    );
    let answer = optimize(&req, &robot).unwrap();
    assert_eq!(answer.status, Status::Optimal, "{:?}", answer.reason);
    assert!(
        !answer
            .report
            .warnings
            .iter()
            .any(|w| w.contains("collision-free path in configuration space")),
        "no path should have raced: {:?}",
        answer.report.warnings
    );
    assert_certified_against_a_dense_scan(&req, &robot, &answer);
    // Same bytes whatever the thread count.
    let (_, reference) = answer_with_threads(&req, &robot, 1);
    assert_eq!(answer_with_threads(&req, &robot, 2).1, reference);
}

/// The trajectory of `weights` at `s` (phase after the time warp).
fn configuration_at(req: &OptimizeRequest, basis: &Basis, weights: &[f64], s: f64) -> Vec<f64> {
    let nb = req.task.promp.n_basis;
    let wm = DMatrix::from_fn(nb, weights.len() / nb, |i, j| weights[j * nb + i]);
    (wm.transpose() * basis.row_at(s)).iter().copied().collect()
}

/// The answer's certified clearance is at least the clearance asked and at
/// most an independent scan of the meshes at 10,000 phases.
fn assert_certified_against_a_dense_scan(
    req: &OptimizeRequest,
    robot: &Robot,
    answer: &OptimizeResponse,
) {
    let weights = &answer.weights;
    let answer_clearance = req.task.clearance_m;
    let scene = Scene::new(req.task.obstacles.clone()).unwrap();
    let basis = Basis::new(&req.task.promp).unwrap();
    let warp = req.task.time_warp();
    let n = 10_000;
    let worst = (0..=n)
        .map(|k| {
            let q = configuration_at(req, &basis, weights, warp.at(k as f64 / n as f64)[0]);
            scene.min_clearance(robot, &robot.fk(&q)).unwrap().distance
        })
        .fold(f64::INFINITY, f64::min);
    let certified = answer.report.continuous_clearance_m.unwrap();
    assert!(
        certified >= answer_clearance - FEASIBILITY_TOLERANCE,
        "certified {certified}"
    );
    assert!(
        worst >= certified - 1e-9,
        "dense {worst} < certified {certified}"
    );
}

/// A real annotation prior (target 14 of the paper's) with an unripe berry
/// beside its path that its mean's final pose touches: the goal is a
/// position, so the planner aims at a clear configuration of the goal
/// region.
fn real_prior_with_a_berry_at_the_hand() -> OptimizeRequest {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("problems/hard-real/real-089.json");
    let file = dpmp::bench::ProblemFile::load(&path).unwrap();
    serde_json::from_value(file.request).unwrap()
}

#[test]
fn a_position_goal_blocked_at_the_mean_pose_is_reached_from_a_clear_goal_configuration() {
    let robot = Robot::panda().unwrap();
    let req = real_prior_with_a_berry_at_the_hand();
    let problem = req.validate(&robot).unwrap();
    let mean = problem.prior().mean.as_slice().to_vec();
    let at_mean = problem.evaluate(&mean);
    assert!(at_mean.min_clearance_m.unwrap() < 0.0, "{at_mean:?}");
    let answer = optimize(&req, &robot).unwrap();
    assert_eq!(answer.status, Status::Optimal, "{:?}", answer.reason);
    assert!(
        answer
            .report
            .warnings
            .iter()
            .any(|w| w.contains("collision-free path in configuration space")),
        "{:?}",
        answer.report.warnings
    );
    assert_certified_against_a_dense_scan(&req, &robot, &answer);
    // The goal, by forward kinematics of the final configuration.
    let basis = Basis::new(&req.task.promp).unwrap();
    let end = configuration_at(&req, &basis, &answer.weights, 1.0);
    let goal = req.task.goal.as_ref().unwrap();
    let reached = robot.tcp_pose(&end).translation.vector;
    let miss = (reached - nalgebra::Vector3::from(goal.position)).norm();
    assert!(miss <= goal.tolerance_m + 1e-9, "{miss}");
    let (_, reference) = answer_with_threads(&req, &robot, 1);
    assert_eq!(answer_with_threads(&req, &robot, 2).1, reference);
}
