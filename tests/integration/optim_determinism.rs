//! Same request, same bytes (apart from the wall-clock `solve_ms`): across
//! repeated runs and across 1 and 2 rayon worker threads, with the
//! restarts (which run in parallel) included.

use crate::common::requests::{answer_with_threads, needs_restarts};
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::Status;
use dpmp::robot::Robot;

#[test]
fn parallel_restarts_give_the_same_bytes_on_one_or_two_threads() {
    let (robot, req) = needs_restarts();
    let (status, reference) = answer_with_threads(&req, &robot, 1);
    assert_eq!(status, Status::Optimal);
    assert!(reference.contains("restart"), "the restarts must have run");
    for threads in [2, 2, 1, 2] {
        let (_, again) = answer_with_threads(&req, &robot, threads);
        assert_eq!(again, reference, "{threads} threads");
    }
}

#[test]
fn a_hundred_runs_give_the_same_bytes() {
    let robot = Robot::panda().unwrap();
    let req = typical_request(&robot, 5, &ExampleSettings::default()).unwrap();
    let (status, reference) = answer_with_threads(&req, &robot, 2);
    assert_eq!(status, Status::Optimal);
    for run in 0..100 {
        let threads = 1 + run % 2;
        let (_, again) = answer_with_threads(&req, &robot, threads);
        assert_eq!(again, reference, "run {run} on {threads} threads");
    }
}

/// A solve that shares the machine (every core busy: its loops run on one
/// thread) answers with the same bytes as one that has it to itself, the
/// restarts' race included; and the switch follows the running count.
#[test]
fn a_solve_sharing_the_cores_gives_the_same_bytes_as_one_alone() {
    use dpmp::optim::{optimize_with, Sharing, SolveControl};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    let (robot, req) = needs_restarts();
    let running = Arc::new(AtomicUsize::new(2));
    let shared = SolveControl {
        sharing: Some(Sharing {
            running: running.clone(),
            cores: 2,
        }),
        ..Default::default()
    };
    assert!(!shared.parallel());
    let alone = optimize_with(&req, &robot, &SolveControl::default()).unwrap();
    let sharing = optimize_with(&req, &robot, &shared).unwrap();
    assert_eq!(alone.status, Status::Optimal);
    let reference = alone.deterministic_json();
    assert!(reference.contains("restart"), "the restarts must have run");
    assert_eq!(sharing.deterministic_json(), reference);
    running.store(1, Ordering::Relaxed);
    assert!(shared.parallel(), "a core is idle again");
}
