//! Forward kinematics of every Panda link, the TCP Jacobian and IK
//! (target: FK of all links ≤ 1 µs per configuration), and a task-space
//! distribution turned into a joint-space prior (64 IK-tracked draws, what
//! a plan with a task-space model adds, or the linearised propagation).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use dpmp::robot::{IkOptions, IkTarget, Robot, PANDA_HOME};
use nalgebra::{Point3, Unit, Vector3};

fn kinematics(c: &mut Criterion) {
    let robot = Robot::panda().expect("the shipped Panda loads");
    let q = PANDA_HOME;
    c.bench_function("fk_all_links", |b| b.iter(|| robot.fk(black_box(&q))));
    c.bench_function("tcp_pose", |b| b.iter(|| robot.tcp_pose(black_box(&q))));
    c.bench_function("tcp_jacobian", |b| {
        b.iter(|| robot.tcp_jacobian(black_box(&q)))
    });
    let frames = robot.fk(&q);
    let hand = robot.link_index("panda_hand").expect("hand link");
    let point = frames.poses[hand] * Point3::new(0.0, 0.03, 0.1);
    c.bench_function("point_jacobian_hand", |b| {
        b.iter(|| robot.point_jacobian(black_box(&q), &frames, hand, &point))
    });
    let target = IkTarget {
        position: Point3::new(0.66, 0.05, 0.75),
        approach_axis: Some(Unit::new_normalize(Vector3::new(1.0, 0.0, -0.2))),
    };
    c.bench_function("ik_berry_from_home", |b| {
        b.iter(|| robot.ik(black_box(&target), &PANDA_HOME, &IkOptions::default()))
    });
}

fn task_space_prior(c: &mut Criterion) {
    use dpmp::promp::{Basis, PrompConfig};
    use dpmp::task_space::{joint_prior, task_distribution, JointPriorOptions};
    let robot = Robot::panda().expect("the shipped Panda loads");
    let basis = Basis::new(&PrompConfig::default()).expect("default basis");
    let demos: Vec<Vec<f64>> = dpmp::fixtures::demonstrations::demonstrations(
        &dpmp::fixtures::demonstrations::TYPICAL_FINAL,
        10,
        basis.n_samples(),
        3,
    )
    .iter()
    .map(|d| {
        let w = dpmp::promp::fit::fit_weights(&basis, d).expect("fit");
        w.as_slice().to_vec()
    })
    .collect();
    let refs: Vec<&[f64]> = demos.iter().map(Vec::as_slice).collect();
    let reference = robot.tcp_pose(&PANDA_HOME).rotation;
    let task = task_distribution(&basis, &robot, &refs, &reference).expect("task space");
    let options = JointPriorOptions::default();
    c.bench_function("task_space_joint_prior_64_draws", |b| {
        b.iter(|| joint_prior(&robot, &basis, &task, &PANDA_HOME, &options, &|| false))
    });
    let linearised = JointPriorOptions {
        propagation: dpmp::task_space::Propagation::Linearised,
        ..JointPriorOptions::default()
    };
    c.bench_function("task_space_joint_prior_linearised", |b| {
        b.iter(|| joint_prior(&robot, &basis, &task, &PANDA_HOME, &linearised, &|| false))
    });
}

criterion_group!(benches, kinematics, task_space_prior);
criterion_main!(benches);
