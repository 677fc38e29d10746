//! Forward kinematics: the pose of every chain link in the base frame.

use super::Robot;
use nalgebra::{DMatrix, Isometry3, Vector3};

/// Poses of every link of [`Robot::link_names`] in the base frame.
#[derive(Clone, Debug)]
pub struct Frames {
    /// One pose per entry of `robot.link_names()`.
    pub poses: Vec<Isometry3<f64>>,
}

impl Robot {
    /// Poses of every link for the joint values `q` (`q.len() == dof`;
    /// callers validate first with [`Robot::validate_configuration`]).
    pub fn fk(&self, q: &[f64]) -> Frames {
        debug_assert_eq!(q.len(), self.dof());
        let mut poses = Vec::with_capacity(self.steps.len() + 1);
        let mut current = Isometry3::identity();
        poses.push(current);
        for step in &self.steps {
            current = step.child_pose(&current, q);
            poses.push(current);
        }
        Frames { poses }
    }

    /// Pose of the tip link (the TCP) for the joint values `q`.
    pub fn tcp_pose(&self, q: &[f64]) -> Isometry3<f64> {
        debug_assert_eq!(q.len(), self.dof());
        self.steps.iter().fold(Isometry3::identity(), |pose, step| {
            step.child_pose(&pose, q)
        })
    }

    /// TCP positions along a `T x dof` trajectory (one row per sample).
    pub fn tcp_path(&self, q: &DMatrix<f64>) -> Vec<Vector3<f64>> {
        (0..q.nrows())
            .map(|t| {
                let row: Vec<f64> = q.row(t).iter().cloned().collect();
                self.tcp_pose(&row).translation.vector
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::super::PANDA_HOME;
    use super::*;
    use nalgebra::{Point3, Vector3};

    #[test]
    fn panda_at_zero_matches_hand_computation() {
        let robot = Robot::panda().unwrap();
        let frames = robot.fk(&[0.0; 7]);
        // At q = 0 the arm is straight up: z = 0.333 + 0.316 + 0.384, the
        // forearm offset 0.0825 is undone by -0.0825, joint 7 sits 0.088
        // forward, and the flange (0.107) and TCP (0.1034) point down.
        let expect = [
            ("panda_link1", [0.0, 0.0, 0.333]),
            ("panda_link2", [0.0, 0.0, 0.333]),
            ("panda_link3", [0.0, 0.0, 0.649]),
            ("panda_link4", [0.0825, 0.0, 0.649]),
            ("panda_link5", [0.0, 0.0, 1.033]),
            ("panda_link6", [0.0, 0.0, 1.033]),
            ("panda_link7", [0.088, 0.0, 1.033]),
            ("panda_link8", [0.088, 0.0, 0.926]),
            ("panda_hand", [0.088, 0.0, 0.926]),
            ("panda_tcp", [0.088, 0.0, 0.8226]),
        ];
        for (name, p) in expect {
            let got = frames.poses[robot.link_index(name).unwrap()]
                .translation
                .vector;
            assert!((got - Vector3::from(p)).norm() < 1e-12, "{name}: {got}");
        }
        let tcp = frames.poses[robot.tcp_link()];
        assert!((tcp.rotation * Vector3::z() - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert!((tcp.rotation * Vector3::x() - Vector3::new(s, s, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn panda_home_matches_the_reference() {
        let robot = Robot::panda().unwrap();
        let tcp = robot.tcp_pose(&PANDA_HOME);
        let p = tcp.translation.vector;
        assert!(
            (p - Vector3::new(0.380, -0.062, 0.708)).norm() < 1.5e-3,
            "{p}"
        );
        let axis = tcp.rotation * Vector3::z();
        assert!(
            (axis - Vector3::new(0.97, -0.06, -0.22)).norm() < 0.01,
            "{axis}"
        );
        let frames = robot.fk(&PANDA_HOME);
        let last = frames.poses[robot.tcp_link()];
        assert!((last.translation.vector - p).norm() < 1e-12);
        assert!(last.rotation.angle_to(&tcp.rotation) < 1e-12);
        let origin = last * Point3::origin();
        assert!((origin.coords - p).norm() < 1e-12);
    }
}
