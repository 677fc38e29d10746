//! Generated typical optimiser requests, as structs and as JSON bodies,
//! and the committed problem sets.

use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, OptimizeRequest, Status};
use dpmp::robot::Robot;
use serde_json::Value;

/// The shipped Panda and the typical request of `seed` with `settings`.
pub fn typical(seed: u64, settings: &ExampleSettings) -> (Robot, OptimizeRequest) {
    let robot = Robot::panda().unwrap();
    let request = typical_request(&robot, seed, settings).unwrap();
    (robot, request)
}

/// A request whose run from the prior mean ends in a local minimum and
/// that a seeded restart solves: typical problem 195 on the paper's timing
/// (free ends) without its start configuration, so that the global stage
/// (which plans from a start) does not race it first.
pub fn needs_restarts() -> (Robot, OptimizeRequest) {
    let settings = ExampleSettings {
        boundary: dpmp::optim::Boundary::Free,
        ..Default::default()
    };
    let (robot, mut request) = typical(195, &settings);
    request.task.start = None;
    (robot, request)
}

/// The typical request of `seed` with `settings` (for the Panda) as JSON.
pub fn typical_json(seed: u64, settings: &ExampleSettings) -> Value {
    serde_json::to_value(typical(seed, settings).1).unwrap()
}

/// `optimize` on a rayon pool of `threads` workers: the status and the
/// answer's deterministic JSON (every `solve_ms` 0).
pub fn answer_with_threads(
    req: &OptimizeRequest,
    robot: &Robot,
    threads: usize,
) -> (Status, String) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let resp = pool.install(|| optimize(req, robot)).unwrap();
    (resp.status, resp.deterministic_json())
}

/// Every problem file of a committed set (`problems/<set>/`), in name
/// order.
pub fn problem_set(set: &str) -> Vec<dpmp::bench::ProblemFile> {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("problems")
        .join(set);
    dpmp::bench::load_dir(&dir)
        .unwrap()
        .into_iter()
        .map(|(name, p)| p.unwrap_or_else(|e| panic!("{name}: {e}")))
        .collect()
}
