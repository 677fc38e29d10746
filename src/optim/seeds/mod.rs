//! Where the SCP starts besides the prior mean: a collision-free [`path`]
//! found in configuration space to the final configuration or a clear
//! configuration of the goal region ([`goal_pose`]), raced against the mean from the first
//! iteration when the mean is blocked ([`global`]); [`restart`]s from
//! a feasible trajectory ending at a clear goal configuration
//! ([`pinned`]), from a second planned path made feasible near itself
//! ([`near_path`]), from detours around the obstacles that block the mean and from seeded prior
//! draws after a local minimum, the draws [`screen`]ed for the closest to
//! feasible; and the `samples: N` projected draws of
//! [`sampling`].

mod condition;
mod detour;
pub mod global;
pub mod goal_pose;
mod near_path;
pub mod path;
mod pinned;
pub mod restart;
pub mod sampling;
mod screen;

#[cfg(test)]
mod test_problems {
    /// A committed real-prior hard problem (`problems/hard-real/NAME`),
    /// for the seeds' tests.
    pub(super) fn real_problem(name: &str) -> crate::optim::problem::Problem {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("problems/hard-real")
            .join(name);
        let file = crate::bench::ProblemFile::load(&path).unwrap();
        let request: crate::optim::OptimizeRequest = serde_json::from_value(file.request).unwrap();
        request
            .validate(&crate::robot::Robot::panda().unwrap())
            .unwrap()
    }
}
