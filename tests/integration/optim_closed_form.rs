//! Closed forms and optimality: the equality-only optimum is Gaussian
//! conditioning, and convex instances agree with a tightly solved re-run.

use crate::common::requests::typical;
use dpmp::fixtures::ExampleSettings;
use dpmp::optim::problem::whiten::Whitening;
use dpmp::optim::{Boundary, OptimizeRequest, SolveControl, Status, Waypoint};
use dpmp::promp::{ViaPoint, WeightDistribution};
use dpmp::robot::Robot;
use nalgebra::DMatrix;

fn convex_request(seed: u64) -> (Robot, OptimizeRequest) {
    let settings = ExampleSettings {
        n_obstacles: 0,
        with_goal: false,
        with_start: false,
        ..Default::default()
    };
    typical(seed, &settings)
}

/// The prior the optimiser whitens: `Σ + λI` with the default `λ`.
fn whitened_prior(prior: &WeightDistribution) -> WeightDistribution {
    let n = prior.dim();
    let lambda = Whitening::default_lambda(prior);
    WeightDistribution::new(
        prior.mean.clone(),
        &prior.cov + DMatrix::identity(n, n) * lambda,
        7,
        8,
    )
    .unwrap()
}

#[test]
fn equality_only_optimum_is_gaussian_conditioning() {
    let (robot, mut req) = convex_request(3);
    let base = req.validate(&robot).unwrap();
    let mean = base.prior().trajectory_mean(base.basis());
    let t = mean.nrows() - 1;
    let start: Vec<f64> = (0..7)
        .map(|j| mean[(0, j)] + 0.01 * (j as f64 - 3.0))
        .collect();
    let fin: Vec<f64> = (0..7)
        .map(|j| mean[(t, j)] - 0.02 + 0.005 * j as f64)
        .collect();
    req.task.start = Some(start.clone());
    req.task.options.final_configuration = Some(fin.clone());
    let problem = req.validate(&robot).unwrap();
    let sol = problem.solve(&SolveControl::default()).unwrap();
    assert_eq!(sol.status, Status::Optimal, "{:?}", sol.reason);

    let shifted = whitened_prior(problem.prior());
    let post = shifted
        .condition(
            problem.basis(),
            &[
                ViaPoint {
                    phase: 0.0,
                    q: start,
                    noise_var: 0.0,
                },
                ViaPoint {
                    phase: 1.0,
                    q: fin,
                    noise_var: 0.0,
                },
            ],
        )
        .unwrap();
    let diff = sol
        .weights
        .iter()
        .zip(post.mean.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-8, "weights differ from conditioning by {diff:e}");
    let m_post = problem.mahalanobis(post.mean.as_slice());
    assert!(
        (sol.mahalanobis - m_post).abs() < 1e-8,
        "{} vs {m_post}",
        sol.mahalanobis
    );
}

/// Via configurations are ProMP via-point conditioning: with nothing else
/// binding (no obstacles, no goal; free ends, so that a phase of the
/// motion is the basis phase), the answer is the prior conditioned on the
/// start and the via points, over several priors and via points (1e-8),
/// whether a via point is given by `phase` or by `time_s`.
#[test]
fn via_configurations_are_gaussian_conditioning() {
    for seed in [3u64, 7, 11, 19] {
        let (robot, mut req) = convex_request(seed);
        req.task.boundary = Boundary::Free;
        let base = req.validate(&robot).unwrap();
        let mean = base.prior().trajectory_mean(base.basis());
        let phases = base.basis().phases().to_vec();
        let wobble = |k: usize, j: usize| 0.02 * ((seed as f64 + 1.7 * j as f64 + k as f64).sin());
        let at = |k: usize| -> Vec<f64> { (0..7).map(|j| mean[(k, j)] + wobble(k, j)).collect() };
        let (k1, k2) = (phases.len() / 3 + seed as usize % 5, 2 * phases.len() / 3);
        let start = at(0);
        req.task.start = Some(start.clone());
        req.task.via_points = vec![
            Waypoint {
                phase: Some(phases[k1]),
                configuration: Some(at(k1)),
                ..waypoint()
            },
            Waypoint {
                time_s: Some(phases[k2] * req.task.duration_s),
                configuration: Some(at(k2)),
                ..waypoint()
            },
        ];
        let problem = req.validate(&robot).unwrap();
        let sol = problem.solve(&SolveControl::default()).unwrap();
        assert_eq!(sol.status, Status::Optimal, "seed {seed}: {:?}", sol.reason);
        assert!(
            sol.report.equality_error_rad < 1e-8,
            "{}",
            sol.report.equality_error_rad
        );

        let shifted = whitened_prior(problem.prior());
        let via = |phase: f64, q: Vec<f64>| ViaPoint {
            phase,
            q,
            noise_var: 0.0,
        };
        let post = shifted
            .condition(
                problem.basis(),
                &[
                    via(0.0, start),
                    via(phases[k1], at(k1)),
                    via(phases[k2], at(k2)),
                ],
            )
            .unwrap();
        let worst = largest_position_gap(
            &problem.trajectory(&sol.weights),
            &problem.trajectory(post.mean.as_slice()),
        );
        assert!(worst < 1e-8, "seed {seed}: {worst:e} rad from conditioning");
    }
}

/// With the default rest-to-rest timing a via point holds at its time: the
/// trajectory's sample at that time is the via configuration.
#[test]
fn a_rest_to_rest_trajectory_passes_its_via_configuration_at_its_time() {
    let (robot, mut req) = convex_request(5);
    let base = req.validate(&robot).unwrap();
    let mean = base.prior().trajectory_mean(base.basis());
    let k = base.basis().phases().len() / 2;
    let q: Vec<f64> = (0..7).map(|j| mean[(k, j)] + 0.03).collect();
    req.task.via_points = vec![Waypoint {
        time_s: Some(base.basis().phases()[k] * req.task.duration_s),
        configuration: Some(q.clone()),
        ..waypoint()
    }];
    let problem = req.validate(&robot).unwrap();
    let sol = problem.solve(&SolveControl::default()).unwrap();
    assert_eq!(sol.status, Status::Optimal, "{:?}", sol.reason);
    let trajectory = problem.trajectory(&sol.weights);
    for (a, b) in trajectory.points[k].positions.iter().zip(&q) {
        assert!((a - b).abs() < 1e-8, "{a} vs {b}");
    }
    // Outside the joint limits: diagnosed, naming the via point.
    let mut outside = req.clone();
    outside.task.via_points[0].configuration.as_mut().unwrap()[3] = 3.0;
    let answer = dpmp::optim::optimize(&outside, &robot).unwrap();
    assert_eq!(answer.status, Status::Infeasible);
    let reason = answer.reason.unwrap_or_default();
    assert!(
        reason.contains("via_points[0].configuration[3]"),
        "{reason}"
    );
}

/// A waypoint with no time, place or tolerance yet.
fn waypoint() -> Waypoint {
    Waypoint {
        phase: None,
        time_s: None,
        configuration: None,
        position: None,
        tolerance_m: None,
        tolerance_rad: None,
    }
}

/// A configuration waypoint with a tolerance holds every joint within it
/// at its time, and costs no more than the same waypoint met exactly, which
/// costs more than none.
#[test]
fn a_tolerant_configuration_waypoint_is_met_within_its_tolerance() {
    let robot = Robot::panda().unwrap();
    let (_, mut req) = convex_request(7);
    let plain = req.validate(&robot).unwrap();
    let free = plain.solve(&SolveControl::default()).unwrap();
    assert_eq!(free.status, Status::Optimal);
    let k = plain.basis().phases().len() / 2;
    let q_free = plain.trajectory(&free.weights).points[k].positions.clone();
    let target: Vec<f64> = q_free.iter().map(|q| q + 0.1).collect();
    let mut solve = |tolerance_rad: Option<f64>| {
        req.task.via_points = vec![Waypoint {
            phase: Some(plain.basis().phases()[k]),
            configuration: Some(target.clone()),
            tolerance_rad,
            ..waypoint()
        }];
        let p = req.validate(&robot).unwrap();
        let sol = p.solve(&SolveControl::default()).unwrap();
        assert_eq!(sol.status, Status::Optimal, "{:?}", sol.reason);
        let q = p.trajectory(&sol.weights).points[k].positions.clone();
        (sol, q)
    };
    let (loose, q) = solve(Some(0.04));
    let excess = loose.report.via_configuration_excess_rad.unwrap();
    assert!(excess <= 1e-6, "{excess}");
    for (a, c) in q.iter().zip(&target) {
        assert!((a - c).abs() <= 0.04 + 1e-6, "{a} vs {c}");
    }
    let (exact, q) = solve(None);
    for (a, c) in q.iter().zip(&target) {
        assert!((a - c).abs() <= 1e-8, "{a} vs {c}");
    }
    assert!(free.mahalanobis < loose.mahalanobis);
    assert!(loose.mahalanobis < exact.mahalanobis);
}

/// A TCP position waypoint bends the path through it: the answer is
/// `optimal`, its TCP at that time is within the tolerance (forward
/// kinematics of the returned trajectory, not the solver's own figure),
/// and a waypoint the prior mean already meets changes nothing.
#[test]
fn a_position_waypoint_is_met_at_its_time_and_a_met_one_changes_nothing() {
    let robot = Robot::panda().unwrap();
    let (_, mut req) = convex_request(5);
    let plain = req.validate(&robot).unwrap();
    let free = plain.solve(&SolveControl::default()).unwrap();
    assert_eq!(free.status, Status::Optimal);
    let k = plain.basis().phases().len() / 2;
    let q_mid = plain.trajectory(&free.weights).points[k].positions.clone();
    let tcp = robot.tcp_pose(&q_mid).translation.vector;

    // 3 cm sideways, within 5 mm.
    let target = [tcp.x, tcp.y + 0.03, tcp.z];
    req.task.via_points = vec![Waypoint {
        phase: Some(plain.basis().phases()[k]),
        position: Some(target),
        tolerance_m: Some(0.005),
        ..waypoint()
    }];
    let problem = req.validate(&robot).unwrap();
    let sol = problem.solve(&SolveControl::default()).unwrap();
    assert_eq!(sol.status, Status::Optimal, "{:?}", sol.reason);
    let excess = sol.report.via_position_excess_m.unwrap();
    assert!(excess <= 1e-6, "{excess}");
    let q = &problem.trajectory(&sol.weights).points[k].positions;
    let reached = robot.tcp_pose(q).translation.vector;
    let miss = (reached - nalgebra::Vector3::from(target)).norm();
    assert!(miss <= 0.005 + 1e-6, "{miss} m from the waypoint");
    assert!(sol.mahalanobis > free.mahalanobis);

    // Already met (the free answer's own TCP, 1 cm tolerance): same answer.
    req.task.via_points[0].position = Some(tcp.into());
    req.task.via_points[0].tolerance_m = Some(0.01);
    let met = req
        .validate(&robot)
        .unwrap()
        .solve(&SolveControl::default())
        .unwrap();
    assert_eq!(met.status, Status::Optimal);
    let gap = met
        .weights
        .iter()
        .zip(&free.weights)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(gap < 1e-6, "{gap}");
}

#[test]
fn binding_limits_agree_with_a_tightly_solved_rerun_and_cost_more_than_equalities_alone() {
    let (robot, mut req) = convex_request(5);
    // Joint 6's prior reaches ~3.24 rad: a 0.55 rad margin makes its limit bind.
    req.task.joint_limit_margin_rad = 0.55;
    let problem = req.validate(&robot).unwrap();
    let prior_report = problem.evaluate(problem.prior().mean.as_slice());
    assert!(prior_report.max_joint_limit_violation_rad > 0.01);
    let sol = problem.solve(&SolveControl::default()).unwrap();
    assert_eq!(sol.status, Status::Optimal, "{:?}", sol.reason);
    assert!(problem.is_feasible(&sol.report));
    assert!(sol.mahalanobis > 0.0);

    let mut tight = req.clone();
    tight.task.options.qp_tolerance = 1e-11;
    let tight_problem = tight.validate(&robot).unwrap();
    let tight_sol = tight_problem.solve(&SolveControl::default()).unwrap();
    assert_eq!(tight_sol.status, Status::Optimal);
    assert!((sol.mahalanobis - tight_sol.mahalanobis).abs() < 1e-6 * (1.0 + sol.mahalanobis));
    let q = problem.trajectory(&sol.weights);
    let qt = tight_problem.trajectory(&tight_sol.weights);
    for (a, b) in q.points.iter().zip(&qt.points) {
        for (x, y) in a.positions.iter().zip(&b.positions) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
    }
    // Convexity: feasible perturbations of the optimum never cost less.
    let prior = problem.prior();
    let mut rng = 12345u64;
    let mut feasible_seen = 0;
    for _ in 0..40 {
        let w: Vec<f64> = sol
            .weights
            .iter()
            .enumerate()
            .map(|(i, s)| {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                s + 0.02 * u * prior.cov[(i, i)].sqrt()
            })
            .collect();
        let report = problem.evaluate(&w);
        if problem.is_feasible(&report) {
            feasible_seen += 1;
            assert!(problem.mahalanobis(&w) >= sol.mahalanobis - 1e-9);
        }
    }
    assert!(feasible_seen > 0);
}

/// Largest joint-position difference between two trajectories (rad).
fn largest_position_gap(a: &dpmp::optim::JointTrajectory, b: &dpmp::optim::JointTrajectory) -> f64 {
    a.points
        .iter()
        .zip(&b.points)
        .flat_map(|(p, q)| {
            p.positions
                .iter()
                .zip(&q.positions)
                .map(|(x, y)| (x - y).abs())
        })
        .fold(0.0, f64::max)
}

/// The Mahalanobis distance of `weights` under `prior` as stated (its
/// covariance inverted directly, no regularisation).
fn stated_mahalanobis(prior: &WeightDistribution, weights: &[f64]) -> f64 {
    let d = nalgebra::DVector::from_column_slice(weights) - &prior.mean;
    (d.transpose() * prior.cov.clone().try_inverse().unwrap() * &d)[0].sqrt()
}

/// A positive definite prior (smallest eigenvalue 1e-2) with only a start
/// equality, default options: the optimum is Gaussian conditioning of the
/// prior as stated (no regularisation in the reference), to 1e-6 rad on
/// the trajectory and 1e-7 relative in cost.
#[test]
fn default_options_solve_a_positive_definite_prior_exactly() {
    let (robot, mut req) = convex_request(3);
    let base = req.validate(&robot).unwrap();
    let stated = base.prior().clone();
    let n = stated.dim();
    let cov = &stated.cov + DMatrix::identity(n, n) * 1e-2;
    let pd = WeightDistribution::new(stated.mean.clone(), cov, 7, 8).unwrap();
    req.prior = dpmp::optim::PriorSpec::from(&pd);
    let mean = base.prior().trajectory_mean(base.basis());
    let start: Vec<f64> = (0..7)
        .map(|j| mean[(0, j)] + 0.02 * (j as f64 - 3.0))
        .collect();
    req.task.start = Some(start.clone());
    req.task.options.lambda = None;
    let problem = req.validate(&robot).unwrap();
    let sol = problem.solve(&SolveControl::default()).unwrap();
    assert_eq!(sol.status, Status::Optimal, "{:?}", sol.reason);
    let post = pd
        .condition(
            problem.basis(),
            &[ViaPoint {
                phase: 0.0,
                q: start,
                noise_var: 0.0,
            }],
        )
        .unwrap();
    let ours = problem.trajectory(&sol.weights);
    let exact = problem.trajectory(post.mean.as_slice());
    let worst = largest_position_gap(&ours, &exact);
    assert!(worst <= 1e-6, "trajectory {worst:e} rad from conditioning");
    // The cost under the stated prior, computed directly.
    let direct = stated_mahalanobis(&pd, &sol.weights);
    let best = stated_mahalanobis(&pd, post.mean.as_slice());
    assert!((direct - best).abs() <= 1e-7 * best, "{direct} vs {best}");
    assert!(
        (sol.mahalanobis - best).abs() <= 1e-7 * best,
        "{} vs {best}",
        sol.mahalanobis
    );
    // The former default (λ = 1e-6 × the mean variance) for comparison.
    let mut old = req.clone();
    old.task.options.lambda = Some(1e-6 * pd.cov.trace() / n as f64);
    let old_problem = old.validate(&robot).unwrap();
    let old_sol = old_problem.solve(&SolveControl::default()).unwrap();
    let old_traj = old_problem.trajectory(&old_sol.weights);
    let old_worst = largest_position_gap(&old_traj, &exact);
    let old_cost = stated_mahalanobis(&pd, &old_sol.weights);
    eprintln!(
        "default λ: {worst:.1e} rad, cost {:+.1e} relative; former λ: {old_worst:.1e} rad, cost {:+.1e}",
        direct / best - 1.0,
        old_cost / best - 1.0
    );
}
