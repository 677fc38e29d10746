//! The compiled serial chain: for every step from one link to the next, the
//! fixed joint origin followed by the joint's motion.

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// How a joint moves its child link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// No motion.
    Fixed,
    /// Rotation about `axis` (joint frame) by the joint value `q[dof]`.
    Revolute {
        /// Unit axis in the joint frame.
        axis: Unit<Vector3<f64>>,
        /// Index of the joint value.
        dof: usize,
    },
    /// Translation along `axis` (joint frame) by the joint value `q[dof]`.
    Prismatic {
        /// Unit axis in the joint frame.
        axis: Unit<Vector3<f64>>,
        /// Index of the joint value.
        dof: usize,
    },
}

/// One step of the chain: the parent link frame, times `origin`, times the
/// motion, is the child link frame (the URDF convention).
#[derive(Clone, Debug)]
pub struct ChainStep {
    /// URDF joint name.
    pub joint: String,
    /// Joint origin in the parent link frame.
    pub origin: Isometry3<f64>,
    /// The joint's motion.
    pub motion: Motion,
}

impl ChainStep {
    /// The child link pose given the parent link pose and the joint values.
    #[inline]
    pub fn child_pose(&self, parent: &Isometry3<f64>, q: &[f64]) -> Isometry3<f64> {
        let at_origin = parent * self.origin;
        match self.motion {
            Motion::Fixed => at_origin,
            Motion::Revolute { axis, dof } => {
                let rotation = UnitQuaternion::from_axis_angle(&axis, q[dof]);
                Isometry3::from_parts(at_origin.translation, at_origin.rotation * rotation)
            }
            Motion::Prismatic { axis, dof } => {
                at_origin * Translation3::from(axis.into_inner() * q[dof])
            }
        }
    }
}

/// URDF roll-pitch-yaw (fixed axes x, y, z) and translation as an isometry.
pub fn isometry_from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}
