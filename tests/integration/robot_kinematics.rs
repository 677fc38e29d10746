//! Forward kinematics and Jacobians of the robot model, checked against
//! central finite differences over random configurations.

use crate::common::robot::{at_fractions, panda};
use dpmp::robot::{Robot, PANDA_HOME};
use nalgebra::{Point3, UnitQuaternion, Vector3};
use proptest::prelude::*;

const H: f64 = 1e-6;

fn nudged(q: &[f64], i: usize, h: f64) -> Vec<f64> {
    let mut q = q.to_vec();
    q[i] += h;
    q
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The point Jacobian, and its product with a direction built without
    /// it (`point_velocity_along`, the clearance gradient's), against
    /// central differences of the point's motion.
    #[test]
    fn point_jacobian_matches_finite_differences(
        fractions in proptest::collection::vec(0.02f64..0.98, 7),
        link_pick in 0usize..11,
        offset in proptest::array::uniform3(-0.1f64..0.1),
        direction in proptest::array::uniform3(-1.0f64..1.0),
    ) {
        let robot = panda();
        let q = at_fractions(&robot, &fractions);
        let frames = robot.fk(&q);
        let link = link_pick % robot.link_names().len();
        let local = Point3::from(Vector3::from(offset));
        let point = frames.poses[link] * local;
        let jac = robot.point_jacobian(&q, &frames, link, &point);
        let u = Vector3::from(direction);
        let along = robot.point_velocity_along(&frames, link, &point, &u);
        prop_assert_eq!(along.len(), robot.dof());
        for i in 0..robot.dof() {
            let plus = robot.fk(&nudged(&q, i, H)).poses[link] * local;
            let minus = robot.fk(&nudged(&q, i, -H)).poses[link] * local;
            let fd = (plus - minus) / (2.0 * H);
            let err = (jac.column(i) - fd).norm();
            prop_assert!(err < 1e-6, "link {link} joint {i}: analytic {} fd {fd} err {err}", jac.column(i));
            let along_err = (along[i] - fd.dot(&u)).abs();
            prop_assert!(along_err < 1e-6, "link {link} joint {i}: along {} fd {}", along[i], fd.dot(&u));
        }
    }

    #[test]
    fn tcp_jacobian_matches_finite_differences(fractions in proptest::collection::vec(0.02f64..0.98, 7)) {
        let robot = panda();
        let q = at_fractions(&robot, &fractions);
        let jac = robot.tcp_jacobian(&q);
        for i in 0..robot.dof() {
            let plus = robot.tcp_pose(&nudged(&q, i, H));
            let minus = robot.tcp_pose(&nudged(&q, i, -H));
            let linear = (plus.translation.vector - minus.translation.vector) / (2.0 * H);
            let turn: UnitQuaternion<f64> = plus.rotation * minus.rotation.inverse();
            let angular = turn.scaled_axis() / (2.0 * H);
            prop_assert!((jac.fixed_view::<3, 1>(0, i) - linear).norm() < 1e-6);
            prop_assert!((jac.fixed_view::<3, 1>(3, i) - angular).norm() < 1e-6, "joint {i}");
        }
    }

    #[test]
    fn tcp_pose_equals_the_last_frame(fractions in proptest::collection::vec(0.0f64..1.0, 7)) {
        let robot = panda();
        let q = at_fractions(&robot, &fractions);
        let frames = robot.fk(&q);
        let tcp = robot.tcp_pose(&q);
        let last = frames.poses[robot.tcp_link()];
        prop_assert!((tcp.translation.vector - last.translation.vector).norm() < 1e-12);
        // the flange and the TCP are 0.1034 apart along the hand's z axis
        let hand = frames.poses[robot.link_index("panda_hand").unwrap()];
        let along = hand.rotation * Vector3::z() * 0.1034;
        prop_assert!((hand.translation.vector + along - last.translation.vector).norm() < 1e-12);
    }
}

#[test]
fn jacobian_columns_after_the_link_are_zero() {
    let robot = panda();
    let frames = robot.fk(&PANDA_HOME);
    let link3 = robot.link_index("panda_link3").unwrap();
    let p = frames.poses[link3] * Point3::new(0.05, 0.0, 0.0);
    let jac = robot.point_jacobian(&PANDA_HOME, &frames, link3, &p);
    for i in 3..7 {
        assert_eq!(jac.column(i).norm(), 0.0, "joint {i}");
    }
    assert!(jac.column(0).norm() > 0.01);
}

#[test]
fn prismatic_chain_jacobian_matches_finite_differences() {
    let xml = r#"<robot name="rp">
      <link name="base"/><link name="arm"/><link name="slide"/><link name="tip"/>
      <joint name="turn" type="revolute"><parent link="base"/><child link="arm"/>
        <origin xyz="0 0 0.2" rpy="0.3 0 0"/><axis xyz="0 1 1"/><limit lower="-2" upper="2" velocity="1"/></joint>
      <joint name="push" type="prismatic"><parent link="arm"/><child link="slide"/>
        <origin xyz="0.1 0 0" rpy="0 0.2 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.5" velocity="1"/></joint>
      <joint name="flange" type="fixed"><parent link="slide"/><child link="tip"/><origin xyz="0 0.05 0.1"/></joint>
    </robot>"#;
    let robot = Robot::from_urdf_str(xml, "base", "tip").unwrap();
    let q = [0.7, 0.2];
    let jac = robot.tcp_jacobian(&q);
    for i in 0..2 {
        let plus = robot.tcp_pose(&nudged(&q, i, H));
        let minus = robot.tcp_pose(&nudged(&q, i, -H));
        let linear = (plus.translation.vector - minus.translation.vector) / (2.0 * H);
        assert!(
            (jac.fixed_view::<3, 1>(0, i) - linear).norm() < 1e-6,
            "joint {i}"
        );
        let angular = (plus.rotation * minus.rotation.inverse()).scaled_axis() / (2.0 * H);
        assert!(
            (jac.fixed_view::<3, 1>(3, i) - angular).norm() < 1e-6,
            "joint {i}"
        );
    }
    // the prismatic joint does not rotate the tip
    assert_eq!(jac.fixed_view::<3, 1>(3, 1).norm(), 0.0);
}

#[test]
fn urdf_file_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.urdf");
    std::fs::write(&path, "<robot name='x'><link name='a'/>").unwrap();
    let err = Robot::from_urdf_file(&path, "a", "a").unwrap_err();
    assert!(err.to_string().contains("broken.urdf"), "{err}");
    let missing = Robot::from_urdf_file(&dir.path().join("none.urdf"), "a", "b").unwrap_err();
    assert!(missing.to_string().contains("none.urdf"));
}
