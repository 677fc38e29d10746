//! More basis functions when the motion needs them (`optim::finer_basis`):
//! a smooth-prior request that its default basis cannot meet is answered
//! on a finer basis, certified, and equal to the same request sent with
//! that basis; requests the default basis meets, learned priors and
//! `refine_basis: false` keep their basis.

use crate::common::robot::panda;
use dpmp::optim::finer_basis::{on_answer_basis, refinable, FINER_BASES};
use dpmp::optim::{optimize, OptimizeRequest, PriorSpec, Status};
use dpmp::promp::smooth::{smooth_basis_config, smooth_basis_config_with, SMOOTH_N_BASIS};
use serde_json::json;

const READY: [f64; 7] = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];

/// A smooth-prior request from and back to the ready pose through `n`
/// waypoints that swing joint 1 between +0.3 and -0.3 rad (0.02 rad tolerance):
/// `n` bends, which a basis with too few functions cannot make.
fn swinging(n: usize) -> OptimizeRequest {
    let via: Vec<_> = (1..=n)
        .map(|k| {
            let mut q = READY;
            q[0] = if k % 2 == 1 { 0.3 } else { -0.3 };
            json!({"phase": k as f64 / (n + 1) as f64, "configuration": q, "tolerance_rad": 0.02})
        })
        .collect();
    serde_json::from_value(json!({
        "start": READY,
        "duration_s": 10.0,
        "clearance_m": 0.01,
        "via_points": via,
        "options": {"final_configuration": READY},
    }))
    .unwrap()
}

#[test]
fn a_motion_the_default_basis_cannot_bend_is_answered_on_a_finer_one() {
    let robot = panda();
    let request = swinging(9);
    assert!(refinable(&request));
    let mut kept = request.clone();
    kept.task.options.refine_basis = false;
    let on_default = optimize(&kept, &robot).unwrap();
    assert_eq!(
        on_default.status,
        Status::MaxIterations,
        "{:?}",
        on_default.reason
    );
    assert_eq!(on_default.weights.len(), 7 * SMOOTH_N_BASIS);
    assert!(on_default.promp.is_none());

    let answer = optimize(&request, &robot).unwrap();
    assert_eq!(answer.status, Status::Optimal, "{:?}", answer.reason);
    let promp = answer.promp.clone().expect("the basis of the answer");
    assert!(FINER_BASES.contains(&promp.n_basis));
    assert_eq!(promp, smooth_basis_config_with(promp.n_basis));
    assert_eq!(answer.weights.len(), 7 * promp.n_basis);
    assert!(answer
        .report
        .warnings
        .iter()
        .any(|w| w.contains("found no certified answer")));

    // Certified on its own basis: the dense and continuous checks of the
    // problem the weights belong to hold, and every waypoint is met.
    let problem = on_answer_basis(&request, &answer).validate(&robot).unwrap();
    let report = problem.evaluate(&answer.weights);
    assert!(problem.is_feasible(&report), "{report:?}");

    // The same request sent with that basis gives the same bytes (but for
    // the wall clock and the refinement's warning).
    let mut direct = request.clone();
    direct.task.promp = promp;
    let again = optimize(&direct, &robot).unwrap();
    assert!(again.promp.is_none());
    assert_eq!(again.weights, answer.weights);
    assert_eq!(again.mahalanobis.to_bits(), answer.mahalanobis.to_bits());
}

#[test]
fn a_motion_the_default_basis_meets_keeps_it() {
    let robot = panda();
    let request = swinging(5);
    let answer = optimize(&request, &robot).unwrap();
    assert_eq!(answer.status, Status::Optimal, "{:?}", answer.reason);
    assert!(answer.promp.is_none());
    assert_eq!(answer.weights.len(), 7 * SMOOTH_N_BASIS);
    let json = serde_json::to_value(&answer).unwrap();
    assert!(json.get("promp").is_none());
}

#[test]
fn learned_priors_chosen_bases_and_the_opt_out_are_not_refined() {
    let request = swinging(9);
    assert!(refinable(&request));
    let mut chosen = request.clone();
    chosen.task.promp = smooth_basis_config_with(16);
    assert!(!refinable(&chosen));
    let mut off = request.clone();
    off.task.options.refine_basis = false;
    assert!(!refinable(&off));
    let n = 7 * smooth_basis_config().n_basis;
    let mut learned = request.clone();
    learned.prior = PriorSpec::Full {
        mean: vec![0.0; n],
        cov: (0..n)
            .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
            .collect(),
    };
    assert!(!refinable(&learned));
}
