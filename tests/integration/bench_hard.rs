//! The hard optimiser sets: `problems/hard/` (`dpmp bench make-problems
//! --set hard`, at least 200 problems) and `problems/hard-real/` (`--set
//! hard-real`, at least 100 on the paper's real annotation priors). In
//! both, each problem's prior mean is blocked by its obstacles, every
//! `feasible: true` label carries a witness that still satisfies every
//! constraint of the file as written, and the generator reproduces the
//! committed files byte for byte (every tenth hard file, every eleventh
//! real-prior one).

use dpmp::bench::hard_set::real::make_real_one;
use dpmp::bench::hard_set::{make_hard_one, HARD_CLEARANCE_M};
use dpmp::bench::problem_file::HARD_CATEGORY;
use dpmp::bench::ProblemFile;
use dpmp::optim::OptimizeRequest;
use dpmp::promp::annotation::JointAnnotation;
use dpmp::robot::Robot;

/// Targets of the paper's annotations.
const REAL_TARGETS: usize = 25;

fn load_all(set: &str) -> Vec<ProblemFile> {
    crate::common::requests::problem_set(set)
}

/// Asserts every problem's prior mean is blocked and every witness
/// verifies; returns how many are labelled feasible.
fn check_labels(robot: &Robot, problems: &[ProblemFile]) -> usize {
    let mut labelled = 0;
    for p in problems {
        assert_eq!(p.meta.category, HARD_CATEGORY, "{}", p.name);
        let request: OptimizeRequest = serde_json::from_value(p.request.clone()).unwrap();
        assert_eq!(request.task.clearance_m, HARD_CLEARANCE_M, "{}", p.name);
        let problem = request.validate(robot).unwrap();
        let at_mean = problem.evaluate(problem.prior().mean.as_slice());
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
    labelled
}

#[test]
fn every_hard_witness_verifies_and_every_prior_mean_is_blocked() {
    let robot = Robot::panda().unwrap();
    let problems = load_all("hard");
    assert!(problems.len() >= 200, "{} problems", problems.len());
    let labelled = check_labels(&robot, &problems);
    // The set is meant for success rates: most of it must be labelled.
    assert!(labelled * 10 >= problems.len() * 9, "{labelled} labelled");
}

#[test]
fn every_real_prior_witness_verifies_and_every_prior_mean_is_blocked() {
    let robot = Robot::panda().unwrap();
    let problems = load_all("hard-real");
    assert!(problems.len() >= 100, "{} problems", problems.len());
    let labelled = check_labels(&robot, &problems);
    assert!(labelled * 10 >= problems.len() * 8, "{labelled} labelled");
}

#[test]
fn the_generator_reproduces_the_committed_files() {
    let robot = Robot::panda().unwrap();
    let generator = dpmp::bench::make_problems::generator(&robot).unwrap();
    let problems = load_all("hard");
    // Every tenth file: a sample across the families, so that a change
    // that moves the generator or its long search shows here.
    for i in (0..problems.len()).step_by(10) {
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

#[test]
fn the_real_prior_generator_reproduces_the_committed_files() {
    let robot = Robot::panda().unwrap();
    let problems = load_all("hard-real");
    // Problem k < 25 is target k's, and the files carry each annotation.
    let targets: Vec<Vec<JointAnnotation>> = problems[..REAL_TARGETS]
        .iter()
        .map(|p| serde_json::from_value(p.request["prior"]["annotation"].clone()).unwrap())
        .collect();
    for i in (0..problems.len()).step_by(11) {
        let committed = &problems[i];
        let again = make_real_one(&robot, &targets, i, committed.meta.seed, true).unwrap();
        assert_eq!(
            again.to_json().unwrap(),
            committed.to_json().unwrap(),
            "{}",
            committed.name
        );
    }
}
