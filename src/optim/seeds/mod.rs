//! Where the SCP starts besides the prior mean: [`restart`]s from seeded
//! prior draws after a local minimum, and the `samples: N` projected draws of
//! [`sampling`].

pub mod restart;
pub mod sampling;
