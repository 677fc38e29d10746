//! Where the SCP starts besides the prior mean: a collision-free [`path`]
//! found in configuration space to the final configuration or a clear
//! configuration of the goal region ([`goal_pose`]), raced against the mean from the first
//! iteration when the mean is blocked ([`global`]); [`restart`]s from
//! detours around the obstacles that block the mean and from seeded prior
//! draws after a local minimum; and the `samples: N` projected draws of
//! [`sampling`].

mod detour;
pub mod global;
pub mod goal_pose;
pub mod path;
pub mod restart;
pub mod sampling;
