//! Task space: the TCP's trajectory as a ProMP, the paper's second space.
//!
//! ```text
//! joint weights ──► trajectory (T x dof) ──► FK ──► poses (T x 7: x y z qx qy qz qw)
//!               ──► fit ──► task-space weights (7 x n_basis)          [poses]
//! task-space distribution ──► draws ──► IK along each from the start
//!               ──► joint trajectories ──► fit ──► joint-space prior [joint_prior]
//! ```
//!
//! A task-space trajectory has seven dimensions: the TCP position (m, base
//! frame) and its orientation as a unit quaternion `[x, y, z, w]` whose
//! sign is kept continuous along the trajectory (each sample takes the sign
//! closer to the previous one; the first takes the sign closer to a stated
//! reference, so that the demonstrations of one target and the targets of
//! one dataset agree). The seven dimensions are fitted with the same basis
//! as the joints, so a task-space weight vector has the joint-space shape
//! of a 7-joint arm and the network's heads, losses and covariance codes
//! apply unchanged ([`crate::net::Space`]).
//!
//! The optimiser works in joint space; a task-space distribution becomes a
//! joint-space prior by [`joint_prior`]: draws of the task-space trajectory
//! are tracked by damped least-squares IK from the plan's start (each
//! sample starts from the previous configuration, so the joint trajectory
//! is continuous) and the joint-space ProMP is fitted to the tracked draws.

pub mod joint_prior;
pub mod poses;

pub use joint_prior::{joint_prior, JointPriorOptions, JointPriorReport, Propagation};
pub use poses::{
    continuous_quaternions, pose_of_row, task_distribution, task_trajectory, task_weight_set,
    task_weights, TASK_DIMS, TASK_DIM_NAMES,
};
