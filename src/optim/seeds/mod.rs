//! Where the SCP starts besides the prior mean: [`restart`]s from detours
//! around the obstacles that block the mean and from seeded prior draws
//! after a local minimum, and the `samples: N` projected draws of
//! [`sampling`].

mod detour;
pub mod restart;
pub mod sampling;
