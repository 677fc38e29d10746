//! Where the SCP starts besides the prior mean: a collision-free [`path`]
//! found in configuration space, raced against the mean from the first
//! iteration when the mean is blocked ([`global`]); [`restart`]s from
//! detours around the obstacles that block the mean and from seeded prior
//! draws after a local minimum; and the `samples: N` projected draws of
//! [`sampling`].

mod detour;
pub mod global;
pub mod path;
pub mod restart;
pub mod sampling;
