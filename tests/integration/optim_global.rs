//! The global stage: a motion whose prior mean collides with a wall races a
//! run from a collision-free path found in configuration space; the
//! answer is `optimal`, clear of the wall against the meshes at 10,000
//! phases, and the same bytes on one or two threads.

use crate::common::requests::answer_with_threads;
use dpmp::optim::{optimize, OptimizeRequest, Status};
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

#[test]
fn a_colliding_mean_races_a_planned_path_and_the_answer_clears_the_meshes() {
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
        answer
            .report
            .warnings
            .iter()
            .any(|w| w.contains("collision-free path in configuration space")),
        "the path must have raced: {:?}",
        answer.report.warnings
    );
    // The certificate against an independent dense scan of the meshes.
    let scene = Scene::new(req.task.obstacles.clone()).unwrap();
    let basis = Basis::new(&req.task.promp).unwrap();
    let warp = req.task.time_warp();
    let nb = req.task.promp.n_basis;
    let wm = DMatrix::from_fn(nb, 7, |i, j| answer.weights[j * nb + i]);
    let n = 10_000;
    let worst = (0..=n)
        .map(|k| {
            let s = warp.at(k as f64 / n as f64)[0];
            let q: Vec<f64> = (wm.transpose() * basis.row_at(s)).iter().copied().collect();
            scene.min_clearance(&robot, &robot.fk(&q)).unwrap().distance
        })
        .fold(f64::INFINITY, f64::min);
    let certified = answer.report.continuous_clearance_m.unwrap();
    assert!(certified >= 0.01 - 1e-9, "certified {certified}");
    assert!(
        worst >= certified - 1e-9,
        "dense {worst} < certified {certified}"
    );
    // Same bytes whatever the thread count.
    let (_, reference) = answer_with_threads(&req, &robot, 1);
    assert_eq!(answer_with_threads(&req, &robot, 2).1, reference);
}
