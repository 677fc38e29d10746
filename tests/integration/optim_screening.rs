//! A run whose trajectory dipped between its optimisation phases screens
//! later converged iterates by dense verification before Clarabel
//! certifies them, and keeps that verification for the answer when
//! certification leaves the point where it is. The answer's report must
//! then be its own weights' report: every figure equal to a fresh dense
//! verification of the returned weights, which verifies.

use dpmp::bench::ProblemFile;
use dpmp::optim::{OptimizeRequest, SolveControl, Status};
use dpmp::robot::Robot;

fn problem_file(set: &str, name: &str) -> ProblemFile {
    crate::common::requests::problem_set(set)
        .into_iter()
        .find(|p| p.name.starts_with(name))
        .unwrap_or_else(|| panic!("{set}/{name} missing"))
}

#[test]
fn an_answer_after_added_phases_reports_its_own_verification() {
    let robot = Robot::panda().unwrap();
    // Runs that add phases (dense verification flagged dips between the
    // phases), then screen their next converged iterate: on the generator's
    // priors and on the paper's real ones; certification leaves the screened
    // point in place in the first two (the screen's verification is the
    // answer's) and moves it in the third (verified again).
    let cases = [
        ("hard", "hard-011", true),
        ("hard-real", "real-004", true),
        ("hard", "hard-000", false),
    ];
    for (set, name, kept) in cases {
        let file = problem_file(set, name);
        let request: OptimizeRequest = serde_json::from_value(file.request.clone()).unwrap();
        let problem = request.validate(&robot).unwrap();
        let answer = problem.solve(&SolveControl::default()).unwrap();
        assert_eq!(
            answer.status,
            Status::Optimal,
            "{name}: {:?}",
            answer.reason
        );
        assert!(
            answer.stats.added_phases > 0,
            "{name}: no phases added, the case does not exercise the screen"
        );
        let (screened, kept_its_own) = answer.stats.screens;
        assert!(screened > 0, "{name}: not screened");
        assert_eq!(kept_its_own > 0, kept, "{name}: {:?}", answer.stats.screens);
        let fresh = problem.evaluate(&answer.weights);
        assert!(problem.is_feasible(&fresh), "{name}: {fresh:?}");
        let got = &answer.report;
        assert_eq!(got.min_clearance_m, fresh.min_clearance_m, "{name}");
        assert_eq!(
            got.continuous_clearance_m, fresh.continuous_clearance_m,
            "{name}"
        );
        assert_eq!(got.closest, fresh.closest, "{name}");
        assert_eq!(got.max_velocity_ratio, fresh.max_velocity_ratio, "{name}");
        assert_eq!(
            got.max_acceleration_ratio, fresh.max_acceleration_ratio,
            "{name}"
        );
        assert_eq!(got.max_jerk_ratio, fresh.max_jerk_ratio, "{name}");
        assert_eq!(got.goal_error_m, fresh.goal_error_m, "{name}");
        assert_eq!(got.verified_samples, fresh.verified_samples, "{name}");
    }
}
