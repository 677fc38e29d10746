//! The hard optimiser set (`problems/hard/`, `dpmp bench make-problems
//! --set hard`): at least 200 problems, each one's prior mean blocked by its
//! intruders, every `feasible: true` label carrying a witness that still
//! satisfies every constraint of the file as written, and the generator
//! reproducing the committed files byte for byte.

use dpmp::bench::hard_set::{make_hard_one, HARD_CLEARANCE_M};
use dpmp::bench::problem_file::HARD_CATEGORY;
use dpmp::bench::{load_dir, ProblemFile};
use dpmp::optim::OptimizeRequest;
use dpmp::robot::Robot;
use std::path::PathBuf;

fn hard_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("problems/hard")
}

fn load_all() -> Vec<ProblemFile> {
    load_dir(&hard_dir())
        .unwrap()
        .into_iter()
        .map(|(name, p)| p.unwrap_or_else(|e| panic!("{name}: {e}")))
        .collect()
}

#[test]
fn every_hard_witness_verifies_and_every_prior_mean_is_blocked() {
    let robot = Robot::panda().unwrap();
    let problems = load_all();
    assert!(problems.len() >= 200, "{} problems", problems.len());
    let mut labelled = 0;
    for p in &problems {
        assert_eq!(p.meta.category, HARD_CATEGORY, "{}", p.name);
        let request: OptimizeRequest = serde_json::from_value(p.request.clone()).unwrap();
        assert_eq!(request.task.clearance_m, HARD_CLEARANCE_M, "{}", p.name);
        let problem = request.validate(&robot).unwrap();
        let mean = problem.prior().mean.as_slice().to_vec();
        let at_mean = problem.evaluate(&mean);
        assert!(
            at_mean.min_clearance_m.unwrap() < HARD_CLEARANCE_M,
            "{}: the prior mean is not blocked",
            p.name
        );
        match (p.expect.feasible, &p.expect.witness) {
            (Some(true), Some(w)) => {
                labelled += 1;
                let report = problem.evaluate(w);
                assert!(
                    problem.is_feasible(&report),
                    "{}: the witness no longer verifies: {report:?}",
                    p.name
                );
            }
            (None, None) => {}
            other => panic!("{}: label {other:?}", p.name),
        }
    }
    // The set is meant for success rates: most of it must be labelled.
    assert!(labelled * 10 >= problems.len() * 9, "{labelled} labelled");
}

#[test]
fn the_generator_reproduces_the_committed_files() {
    let robot = Robot::panda().unwrap();
    let generator = dpmp::bench::make_problems::generator(&robot).unwrap();
    let problems = load_all();
    for i in [0, 1, 5] {
        let committed = &problems[i];
        let again = make_hard_one(&generator, i, committed.meta.seed, true).unwrap();
        assert_eq!(
            again.to_json().unwrap(),
            committed.to_json().unwrap(),
            "{}",
            committed.name
        );
    }
}
