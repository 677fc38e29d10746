//! The prior without demonstrations: with no obstacles the answer is the
//! closed-form smoothest motion (conditioning on the start and the final
//! configuration), and the answer's Mahalanobis distance is its integrated
//! squared acceleration, measured by finite differences.

use crate::common::robot::{at_fractions, panda};
use crate::common::scene::sphere;
use dpmp::optim::problem::phases::TimeWarp;
use dpmp::optim::{optimize, OptimizeRequest, PriorSpec, Status, StopReason};
use dpmp::promp::smooth::{smooth_basis_config, SmoothnessPrior};
use dpmp::promp::Basis;
use nalgebra::{DMatrix, DVector};
use serde_json::json;

/// A request without a prior from `start` to `end` over `duration_s`.
fn smooth_request(start: &[f64], end: &[f64], boundary: &str, duration_s: f64) -> OptimizeRequest {
    serde_json::from_value(json!({
        "start": start,
        "options": {"final_configuration": end},
        "boundary": boundary,
        "duration_s": duration_s,
        "clearance_m": 0.01,
    }))
    .unwrap()
}

/// `argmin wᵀ R w` subject to `A w = b`, by eliminating the equalities:
/// `w = A⁺ b + N y` with `N` the null space of `A` (eigenvectors of `AᵀA`
/// with eigenvalue 0) and `y = -(Nᵀ R N)⁻¹ Nᵀ R A⁺ b`.
fn constrained_minimum(r: &DMatrix<f64>, a: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let particular = a.clone().pseudo_inverse(1e-12).unwrap() * b;
    let eig = (a.transpose() * a).symmetric_eigen();
    let top = eig.eigenvalues.amax();
    let null: Vec<DVector<f64>> = (0..a.ncols())
        .filter(|&k| eig.eigenvalues[k] < 1e-10 * top)
        .map(|k| eig.eigenvectors.column(k).into_owned())
        .collect();
    let n = DMatrix::from_columns(&null);
    let y = -(n.transpose() * r * &n).try_inverse().unwrap() * n.transpose() * r * &particular;
    particular + n * y
}

/// The end-condition rows of one joint (rest, when asked, is the time
/// warp's) and their values.
fn conditions(basis: &Basis, start: f64, end: f64) -> (DMatrix<f64>, DVector<f64>) {
    let rows = [basis.row_at(0.0), basis.row_at(1.0)];
    let a = DMatrix::from_fn(2, basis.n_basis(), |i, k| rows[i][k]);
    (a, DVector::from_vec(vec![start, end]))
}

#[test]
fn with_no_obstacles_the_answer_is_the_closed_form_smoothest_motion() {
    let robot = panda();
    let config = smooth_basis_config();
    let basis = Basis::new(&config).unwrap();
    let nb = config.n_basis;
    let pairs = [
        ([0.5; 7], [0.5, 0.6, 0.4, 0.55, 0.5, 0.45, 0.6]),
        (
            [0.3, 0.4, 0.5, 0.6, 0.5, 0.4, 0.3],
            [0.6, 0.5, 0.4, 0.5, 0.6, 0.5, 0.4],
        ),
        (
            [0.45, 0.35, 0.5, 0.7, 0.5, 0.5, 0.5],
            [0.55, 0.6, 0.45, 0.5, 0.4, 0.6, 0.3],
        ),
    ];
    for boundary in ["rest", "free"] {
        for (from, to) in &pairs {
            let start = at_fractions(&robot, from);
            let end = at_fractions(&robot, to);
            let req = smooth_request(&start, &end, boundary, 6.0);
            let warp = req.task.time_warp();
            let gram = SmoothnessPrior::new(&config, &|tau| warp.at(tau))
                .unwrap()
                .acceleration_gram()
                .clone();
            assert!(matches!(req.prior, PriorSpec::Smooth));
            assert_eq!(req.task.promp, config);
            let answer = optimize(&req, &robot).unwrap();
            assert_eq!(answer.status, Status::Optimal, "{:?}", answer.reason);
            assert_eq!(answer.stop_reason, StopReason::Converged);
            for j in 0..7 {
                let (a, b) = conditions(&basis, start[j], end[j]);
                let expected = constrained_minimum(&gram, &a, &b);
                let got = DVector::from_column_slice(&answer.weights[j * nb..(j + 1) * nb]);
                let error = (&got - &expected).amax();
                assert!(error < 1e-8, "{boundary} joint {j}: {error:e}");
            }
        }
    }
}

/// `∫₀ᵀ |q̈(t)|² dt` of joint-major `weights` timed by `warp`, by central
/// second differences of `q(τ) = ψ(s(τ))ᵀ w` on `n` intervals (trapezoid
/// rule).
fn integrated_squared_acceleration(
    basis: &Basis,
    warp: TimeWarp,
    weights: &[f64],
    duration: f64,
    n: usize,
) -> f64 {
    let nb = basis.n_basis();
    let dt = duration / n as f64;
    let q: Vec<Vec<f64>> = (0..=n)
        .map(|k| {
            let row = basis.row_at(warp.at(k as f64 / n as f64)[0]);
            (0..weights.len() / nb)
                .map(|j| row.dot(&DVector::from_column_slice(&weights[j * nb..(j + 1) * nb])))
                .collect()
        })
        .collect();
    let acc2 = |k: usize| -> f64 {
        (0..q[k].len())
            .map(|j| ((q[k + 1][j] - 2.0 * q[k][j] + q[k - 1][j]) / (dt * dt)).powi(2))
            .sum()
    };
    // The ends by linear extrapolation of the squared acceleration.
    let inner: Vec<f64> = (1..n).map(acc2).collect();
    let first = 2.0 * inner[0] - inner[1];
    let last = 2.0 * inner[n - 2] - inner[n - 3];
    dt * (0.5 * first + inner.iter().sum::<f64>() + 0.5 * last)
}

#[test]
fn its_mahalanobis_distance_is_the_integrated_squared_acceleration() {
    // A sphere on the path of the smoothest motion pushes the answer off
    // it; the distance that remains is the extra squared acceleration.
    let robot = panda();
    let start = at_fractions(&robot, &[0.35, 0.55, 0.5, 0.7, 0.5, 0.5, 0.5]);
    let end = at_fractions(&robot, &[0.65, 0.55, 0.5, 0.7, 0.5, 0.5, 0.5]);
    let duration = 5.0;
    let free = smooth_request(&start, &end, "rest", duration);
    let problem = free.validate(&robot).unwrap();
    let mean = problem.prior().mean.as_slice().to_vec();
    let mid = problem.trajectory(&mean).points[75].positions.clone();
    let tcp = robot.tcp_pose(&mid).translation.vector;
    let mut req = free.clone();
    req.task
        .obstacles
        .push(sphere("in the way", [tcp.x, tcp.y, tcp.z], 0.03));
    let answer = optimize(&req, &robot).unwrap();
    assert_eq!(answer.status, Status::Optimal, "{:?}", answer.reason);
    assert!(answer.mahalanobis > 0.05, "{}", answer.mahalanobis);
    let basis = Basis::new(&req.task.promp).unwrap();
    let warp = req.task.time_warp();
    let scale = SmoothnessPrior::new(&req.task.promp, &|tau| warp.at(tau))
        .unwrap()
        .scale();
    let cost = |w: &[f64]| integrated_squared_acceleration(&basis, warp, w, duration, 20_000);
    let extra = cost(&answer.weights) - cost(&mean);
    // Mahalanobis² = s ∫₀¹ |q''(z)|² dz = s T³ ∫₀ᵀ |q̈(t)|² dt, relative
    // to the mean.
    let expected = scale * duration.powi(3) * extra;
    let got = answer.mahalanobis.powi(2);
    assert!(
        (got - expected).abs() < 1e-3 * expected,
        "Mahalanobis² {got} vs s T³ ∫|q̈|² {expected}"
    );
}

#[test]
fn a_smooth_prior_needs_a_start_and_names_a_bad_prior() {
    let robot = panda();
    let req: OptimizeRequest = serde_json::from_value(json!({"prior": "smooth"})).unwrap();
    let err = req.validate(&robot).err().unwrap().to_string();
    assert!(err.contains("start"), "{err}");
    let bad = serde_json::from_value::<OptimizeRequest>(json!({"prior": "smoothest"}));
    let err = bad.err().unwrap().to_string();
    assert!(
        err.contains("smoothest") && err.contains("\"smooth\""),
        "{err}"
    );
    // A request that names the paper's basis keeps it; too few functions
    // for the end conditions are refused naming `promp.n_basis`.
    let start = robot.home();
    let req: OptimizeRequest = serde_json::from_value(json!({
        "start": start, "options": {"final_configuration": start},
        "promp": {"n_basis": 2, "width": 0.5}
    }))
    .unwrap();
    let err = req.validate(&robot).err().unwrap().to_string();
    assert!(err.contains("promp.n_basis"), "{err}");
}
