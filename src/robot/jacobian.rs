//! Jacobians: of any point rigidly attached to a link, and of the TCP.

use super::chain::Motion;
use super::{Frames, Robot};
use nalgebra::{DVector, Matrix3xX, Matrix6xX, Point3, Vector3};

impl Robot {
    /// `d(point)/dq` (3 x dof) for `point` (base frame, at the configuration
    /// of `frames`) rigidly attached to link `link`. Columns of joints that do
    /// not move `link` (those after it) are zero.
    pub fn point_jacobian(
        &self,
        q: &[f64],
        frames: &Frames,
        link: usize,
        point: &Point3<f64>,
    ) -> Matrix3xX<f64> {
        debug_assert_eq!(q.len(), self.dof());
        let mut jac = Matrix3xX::zeros(self.dof());
        for (dof, step) in self.joints_moving(link) {
            jac.set_column(dof, &self.joint_velocity_column(frames, step, point));
        }
        jac
    }

    /// `J(point)ᵀ u` (one entry per joint) for `point` (base frame) rigidly
    /// attached to link `link` and a direction `u`: how fast the point moves
    /// along `u` per unit speed of each joint, without building the
    /// Jacobian ([`Robot::point_jacobian`]'s columns dotted with `u`).
    pub fn point_velocity_along(
        &self,
        frames: &Frames,
        link: usize,
        point: &Point3<f64>,
        u: &Vector3<f64>,
    ) -> DVector<f64> {
        let mut out = DVector::zeros(self.dof());
        for (dof, step) in self.joints_moving(link) {
            out[dof] = self.joint_velocity_column(frames, step, point).dot(u);
        }
        out
    }

    /// `(joint index, chain step)` of every joint that moves link `link`
    /// (those before it in the chain).
    fn joints_moving(&self, link: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.dof_step
            .iter()
            .copied()
            .enumerate()
            .take_while(move |&(_, step)| step < link)
    }

    /// Geometric Jacobian of the TCP (6 x dof): rows 0..3 the linear
    /// velocity of the TCP origin, rows 3..6 the angular velocity.
    pub fn tcp_jacobian(&self, q: &[f64]) -> Matrix6xX<f64> {
        let frames = self.fk(q);
        let tip = self.tcp_link();
        let origin = Point3::from(frames.poses[tip].translation.vector);
        let linear = self.point_jacobian(q, &frames, tip, &origin);
        let mut jac = Matrix6xX::zeros(self.dof());
        jac.fixed_rows_mut::<3>(0).copy_from(&linear);
        for (dof, &step) in self.dof_step.iter().enumerate() {
            if let Motion::Revolute { axis, .. } = self.steps[step].motion {
                let w = frames.poses[step + 1].rotation * axis.into_inner();
                jac.fixed_view_mut::<3, 1>(3, dof).copy_from(&w);
            }
        }
        jac
    }

    /// Velocity of `point` per unit speed of the joint of chain step `step`.
    fn joint_velocity_column(
        &self,
        frames: &Frames,
        step: usize,
        point: &Point3<f64>,
    ) -> Vector3<f64> {
        let frame = &frames.poses[step + 1];
        match self.steps[step].motion {
            Motion::Revolute { axis, .. } => {
                let w = frame.rotation * axis.into_inner();
                w.cross(&(point.coords - frame.translation.vector))
            }
            Motion::Prismatic { axis, .. } => frame.rotation * axis.into_inner(),
            Motion::Fixed => Vector3::zeros(),
        }
    }
}
