//! Inverse kinematics on random reachable targets: converges below 1 mm,
//! stays within the joint limits, honours the approach axis and the
//! null-space bias.

use dpmp::robot::{IkOptions, IkTarget, Robot, PANDA_HOME};
use nalgebra::{Point3, Unit, Vector3};
use rand::{Rng, SeedableRng};

fn random_configuration(robot: &Robot, rng: &mut impl Rng) -> Vec<f64> {
    robot
        .limits()
        .iter()
        .map(|l| {
            let margin = 0.05 * (l.upper - l.lower);
            rng.gen_range(l.lower + margin..l.upper - margin)
        })
        .collect()
}

fn assert_within_limits(robot: &Robot, q: &[f64], margin: f64) {
    for (i, (x, l)) in q.iter().zip(robot.limits()).enumerate() {
        assert!(
            *x >= l.lower + margin - 1e-12 && *x <= l.upper - margin + 1e-12,
            "joint {i}: {x}"
        );
    }
}

#[test]
fn reaches_random_positions_within_limits() {
    let robot = Robot::panda().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let options = IkOptions::default();
    for case in 0..25 {
        let truth = random_configuration(&robot, &mut rng);
        let target = IkTarget {
            position: Point3::from(robot.tcp_pose(&truth).translation.vector),
            approach_axis: None,
        };
        let solution = robot.ik(&target, &PANDA_HOME, &options).unwrap();
        assert!(solution.converged, "case {case}: {solution:?}");
        let reached = robot.tcp_pose(&solution.q).translation.vector;
        assert!(
            (reached - target.position.coords).norm() < 1e-3,
            "case {case}"
        );
        assert!((reached - target.position.coords).norm() - solution.position_error_m < 1e-12);
        assert_within_limits(&robot, &solution.q, 0.0);
    }
}

#[test]
fn reaches_random_positions_with_approach_axis_and_margin() {
    let robot = Robot::panda().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let options = IkOptions {
        limit_margin_rad: 0.02,
        ..IkOptions::default()
    };
    for case in 0..15 {
        let truth = random_configuration(&robot, &mut rng);
        let pose = robot.tcp_pose(&truth);
        let target = IkTarget {
            position: Point3::from(pose.translation.vector),
            approach_axis: Some(Unit::new_normalize(pose.rotation * Vector3::z())),
        };
        let solution = robot.ik(&target, &PANDA_HOME, &options).unwrap();
        assert!(solution.converged, "case {case}: {solution:?}");
        let reached = robot.tcp_pose(&solution.q);
        assert!((reached.translation.vector - target.position.coords).norm() < 1e-3);
        let axis = reached.rotation * Vector3::z();
        let angle = axis.angle(target.approach_axis.as_ref().unwrap());
        assert!(angle < 2e-3, "case {case}: axis off by {angle}");
        assert_within_limits(&robot, &solution.q, 0.02);
    }
}

#[test]
fn berry_workspace_targets_converge_from_home_with_a_horizontal_approach() {
    let robot = Robot::panda().unwrap();
    for (x, y, z) in [(0.62, -0.2, 0.62), (0.7, 0.17, 0.84), (0.66, 0.0, 0.73)] {
        let target = IkTarget {
            position: Point3::new(x, y, z),
            approach_axis: Some(Unit::new_normalize(Vector3::new(1.0, 0.0, -0.2))),
        };
        let solution = robot
            .ik(&target, &PANDA_HOME, &IkOptions::default())
            .unwrap();
        assert!(solution.converged, "({x}, {y}, {z}): {solution:?}");
        assert!(solution.position_error_m < 1e-3);
    }
}

#[test]
fn null_space_bias_moves_the_elbow_without_moving_the_tcp() {
    let robot = Robot::panda().unwrap();
    let target = IkTarget {
        position: Point3::new(0.6, 0.0, 0.7),
        approach_axis: None,
    };
    let plain = robot
        .ik(&target, &PANDA_HOME, &IkOptions::default())
        .unwrap();
    let mut bias = plain.q.clone();
    bias[2] += 0.6;
    let options = IkOptions {
        null_space_bias: Some(bias.clone()),
        null_space_gain: 0.2,
        max_iterations: 400,
        ..IkOptions::default()
    };
    let biased = robot.ik(&target, &plain.q, &options).unwrap();
    assert!(
        biased.converged && biased.position_error_m < 1e-3,
        "{biased:?}"
    );
    // joint 3 moved towards the bias while the TCP stayed on target
    assert!(
        biased.q[2] - plain.q[2] > 0.1,
        "{} vs {}",
        biased.q[2],
        plain.q[2]
    );
}

#[test]
fn unreachable_targets_report_not_converged_and_bad_input_is_an_error() {
    let robot = Robot::panda().unwrap();
    let far = IkTarget {
        position: Point3::new(3.0, 0.0, 0.5),
        approach_axis: None,
    };
    let options = IkOptions {
        restarts: 1,
        max_iterations: 100,
        ..IkOptions::default()
    };
    let solution = robot.ik(&far, &PANDA_HOME, &options).unwrap();
    assert!(!solution.converged);
    assert!(solution.position_error_m > 1.5);
    assert_within_limits(&robot, &solution.q, 0.0);

    let nan = IkTarget {
        position: Point3::new(f64::NAN, 0.0, 0.5),
        approach_axis: None,
    };
    let e = robot.ik(&nan, &PANDA_HOME, &options).unwrap_err();
    assert_eq!(e.field(), Some("target.position[0]"));
    let e = robot.ik(&far, &PANDA_HOME[..6], &options).unwrap_err();
    assert_eq!(e.field(), Some("seed"));
    let bad = IkOptions {
        tolerance_m: -1.0,
        ..IkOptions::default()
    };
    assert_eq!(
        robot.ik(&far, &PANDA_HOME, &bad).unwrap_err().field(),
        Some("options.tolerance_m")
    );
    let huge_margin = IkOptions {
        limit_margin_rad: 2.0,
        ..IkOptions::default()
    };
    assert!(robot.ik(&far, &PANDA_HOME, &huge_margin).is_err());
}

#[test]
fn ik_is_deterministic() {
    let robot = Robot::panda().unwrap();
    let target = IkTarget {
        position: Point3::new(0.3, -0.4, 0.3),
        approach_axis: Some(Unit::new_normalize(Vector3::new(0.0, 0.0, -1.0))),
    };
    let a = robot
        .ik(&target, &PANDA_HOME, &IkOptions::default())
        .unwrap();
    let b = robot
        .ik(&target, &PANDA_HOME, &IkOptions::default())
        .unwrap();
    assert_eq!(a.q, b.q);
    assert_eq!(a.iterations, b.iterations);
}
