//! The dual active-set inner solver against Clarabel on random QPs of the
//! SCP's working-set shape (49 whitened coordinates, ~40 hard limit rows,
//! ~42 L1-penalised clearance rows), and on the cases that break
//! active-set methods: near-parallel rows, degenerate vertices, drift in
//! the factor updates, incompatible hard rows.

use dpmp::optim::qp::dual_active_set::{self as das, Failure, Row, Settings, WarmStart};
use dpmp::optim::qp::{Inequality, Qp, QpFailure, QpSettings};
use nalgebra::DVector;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

fn gaussian(rng: &mut ChaCha8Rng, n: usize) -> DVector<f64> {
    DVector::from_fn(n, |_, _| StandardNormal.sample(rng))
}

/// A random problem: hard rows satisfied by a known point, soft rows of
/// which about half are broken at the centre, some rows near-parallel to
/// another (neighbouring phases of one constraint).
fn random_problem(seed: u64) -> (DVector<f64>, Vec<Row>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = rng.gen_range(5..=49);
    let n_hard = rng.gen_range(0..=40);
    let n_soft = rng.gen_range(0..=42);
    let centre = gaussian(&mut rng, n) * 2.0;
    let inside = gaussian(&mut rng, n) * 0.5;
    let mut rows: Vec<Row> = Vec::new();
    for i in 0..n_hard + n_soft {
        let a = if i > 0 && rng.gen_bool(0.25) {
            // Near-parallel to the previous row.
            &rows[i - 1].a + gaussian(&mut rng, n) * 1e-3
        } else {
            gaussian(&mut rng, n) * rng.gen_range(0.1..10.0)
        };
        let (b, cap) = if i < n_hard {
            (a.dot(&inside) + rng.gen_range(0.0..1.0), None)
        } else {
            let b = a.dot(&centre) + rng.gen_range(-2.0..1.0) * a.norm();
            (b, Some(rng.gen_range(0.5..50.0)))
        };
        rows.push(Row { a, b, cap });
    }
    (centre, rows)
}

/// The problem as a [`Qp`]: `|z - c|² + Σ ρ s` is twice `½|z - c|² +
/// Σ (ρ/2) s`, so the penalties are twice the caps.
fn as_qp(centre: &DVector<f64>, rows: &[Row]) -> Qp {
    let mut qp = Qp::new(centre.len());
    qp.center = centre.clone();
    qp.inequalities = rows
        .iter()
        .map(|r| Inequality {
            a: r.a.clone(),
            b: r.b,
            penalty: r.cap.map(|u| 2.0 * u),
        })
        .collect();
    qp
}

/// The same problem for Clarabel: `|z - c|² + Σ ρ s` is twice
/// `½|z - c|² + Σ (ρ/2) s`, so caps are half the penalties and the
/// multipliers half Clarabel's duals.
fn clarabel_solve(centre: &DVector<f64>, rows: &[Row]) -> dpmp::optim::qp::QpSolution {
    let qp = as_qp(centre, rows);
    // As tight as Clarabel reaches on the problem (it may report
    // insufficient progress below 1e-10 on the near-parallel rows).
    [1e-11, 1e-10, 1e-9]
        .iter()
        .find_map(|&tolerance| {
            let settings = QpSettings {
                tolerance,
                ..QpSettings::default()
            };
            qp.solve(&settings).ok()
        })
        .expect("Clarabel solves the random QP")
}

#[test]
fn matches_clarabel_on_a_thousand_random_working_set_qps() {
    let mut total_steps = 0;
    for seed in 0..1000 {
        let (centre, rows) = random_problem(seed);
        let sol = das::solve(&centre, &rows, &Settings::default(), &WarmStart::default()).unwrap();
        let kkt = sol.kkt_residual(&centre, &rows);
        assert!(kkt < 1e-9, "seed {seed}: KKT residual {kkt:e}");
        let reference = clarabel_solve(&centre, &rows);
        // Clarabel's objective is twice ours.
        let ours = 2.0 * sol.objective;
        let rel = (ours - reference.objective).abs() / (1.0 + reference.objective.abs());
        assert!(
            rel < 1e-8,
            "seed {seed}: objective {ours} vs Clarabel {}",
            reference.objective
        );
        let gap = (&sol.x - &reference.z).amax();
        assert!(gap < 1e-5, "seed {seed}: |x - x_clarabel| = {gap:e}");
        // Same active set: every multiplier clearly inside (0, cap) belongs
        // to a row Clarabel also holds at equality with the same dual.
        let scale = 1.0 + sol.multipliers.iter().fold(0.0f64, |m, v| m.max(*v));
        for (i, (&ours, &theirs)) in sol
            .multipliers
            .iter()
            .zip(&reference.inequality_duals)
            .enumerate()
        {
            let diff = (2.0 * ours - theirs).abs();
            assert!(
                diff < 1e-4 * 2.0 * scale,
                "seed {seed} row {i}: multiplier {} vs Clarabel {theirs}",
                2.0 * ours
            );
        }
        total_steps += sol.steps;
    }
    // About one step per active row: far fewer than rows x problems.
    assert!(total_steps < 1000 * 60, "{total_steps} steps");
}

#[test]
fn a_warm_start_from_the_active_set_gives_the_same_optimum_in_fewer_steps() {
    let mut cold_steps = 0;
    let mut warm_steps = 0;
    for seed in 1000..1100 {
        let (centre, rows) = random_problem(seed);
        let cold = das::solve(&centre, &rows, &Settings::default(), &WarmStart::default()).unwrap();
        let warm = das::solve(&centre, &rows, &Settings::default(), &cold.warm_start()).unwrap();
        assert!((&cold.x - &warm.x).amax() < 1e-9, "seed {seed}");
        assert!((cold.objective - warm.objective).abs() < 1e-9 * (1.0 + cold.objective));
        cold_steps += cold.steps;
        warm_steps += warm.steps;
    }
    assert!(warm_steps <= cold_steps, "{warm_steps} vs {cold_steps}");
}

#[test]
fn factor_drift_is_contained_by_refactoring() {
    // Refactoring after every update and never (within the solve) must
    // agree: the Givens updates do not drift on these sizes.
    for seed in 2000..2050 {
        let (centre, rows) = random_problem(seed);
        let every = Settings {
            refactor_every: 1,
            ..Settings::default()
        };
        let never = Settings {
            refactor_every: usize::MAX,
            ..Settings::default()
        };
        let a = das::solve(&centre, &rows, &every, &WarmStart::default()).unwrap();
        let b = das::solve(&centre, &rows, &never, &WarmStart::default()).unwrap();
        assert!((&a.x - &b.x).amax() < 1e-9, "seed {seed}");
        assert!(b.kkt_residual(&centre, &rows) < 1e-9);
    }
}

#[test]
fn near_parallel_and_duplicated_rows_do_not_break_the_factor() {
    // Twenty copies of one hard row, rotated by up to 1e-12, plus a second
    // family: a degenerate vertex where many rows are active at once.
    let n = 10;
    let centre = DVector::from_element(n, 1.0);
    let mut rows = Vec::new();
    for k in 0..20 {
        let mut a = DVector::zeros(n);
        a[0] = 1.0;
        a[1] = 1e-13 * k as f64;
        rows.push(Row {
            a,
            b: 0.0,
            cap: None,
        });
        let mut a2 = DVector::zeros(n);
        a2[1] = 1.0;
        a2[0] = -1e-13 * k as f64;
        rows.push(Row {
            a: a2,
            b: 0.0,
            cap: Some(0.25),
        });
    }
    let sol = das::solve(&centre, &rows, &Settings::default(), &WarmStart::default()).unwrap();
    // x0 ≤ 0 binds; x1 pays 0.25 per unit for each of 20 soft rows: the
    // total cap 5 exceeds the pull 1, so x1 = 0 as well.
    assert!(
        sol.x[0].abs() < 1e-9 && sol.x[1].abs() < 1e-9,
        "{:?}",
        sol.x
    );
    assert!((sol.x.rows(2, n - 2).add_scalar(-1.0)).amax() < 1e-12);
    assert!(sol.kkt_residual(&centre, &rows) < 1e-9);
}

#[test]
fn incompatible_hard_rows_are_reported_and_soft_ones_are_not() {
    let n = 4;
    let mut e0 = DVector::zeros(n);
    e0[0] = 1.0;
    // x0 ≤ -1 and -x0 ≤ -1 (x0 ≥ 1).
    let hard = vec![
        Row {
            a: e0.clone(),
            b: -1.0,
            cap: None,
        },
        Row {
            a: -&e0,
            b: -1.0,
            cap: None,
        },
    ];
    let centre = DVector::zeros(n);
    let err = das::solve(&centre, &hard, &Settings::default(), &WarmStart::default()).unwrap_err();
    assert!(matches!(err, Failure::Infeasible { .. }), "{err:?}");
    // The same rows, the second soft with penalty 3: x0 = -1 (hard) and
    // the soft row pays 3 x 2.
    let mut mixed = hard.clone();
    mixed[1].cap = Some(3.0);
    let sol = das::solve(&centre, &mixed, &Settings::default(), &WarmStart::default()).unwrap();
    assert!((sol.x[0] + 1.0).abs() < 1e-12);
    assert!((sol.objective - (0.5 + 6.0)).abs() < 1e-12);
    assert_eq!(sol.multipliers[1], 3.0);
}

#[test]
fn a_saturated_row_that_becomes_satisfied_is_released_in_reverse() {
    // Soft row x0 ≥ 2 (penalty 1) saturates first (the centre is at 0);
    // then a hard row x0 + x1 ≥ 6 pulls x0 past 2, so the soft row must
    // leave its cap. Closed form: minimise ½(x0² + x1²) s.t. x0 + x1 ≥ 6:
    // x = (3, 3), the soft row holds with multiplier 0.
    let n = 2;
    let rows = vec![
        Row {
            a: DVector::from_vec(vec![-1.0, 0.0]),
            b: -2.0,
            cap: Some(1.0),
        },
        Row {
            a: DVector::from_vec(vec![-1.0, -1.0]),
            b: -6.0,
            cap: None,
        },
    ];
    let centre = DVector::zeros(n);
    let sol = das::solve(
        &centre,
        &rows,
        &Settings::default(),
        &WarmStart {
            saturated: vec![0],
            active: vec![],
        },
    )
    .unwrap();
    assert!(
        (&sol.x - DVector::from_vec(vec![3.0, 3.0])).amax() < 1e-12,
        "{:?}",
        sol.x
    );
    assert!(sol.multipliers[0].abs() < 1e-12);
    assert!((sol.multipliers[1] - 3.0).abs() < 1e-12);
}

#[test]
fn bad_input_is_named() {
    let centre = DVector::zeros(3);
    let rows = vec![Row {
        a: DVector::zeros(2),
        b: 0.0,
        cap: None,
    }];
    let err = das::solve(&centre, &rows, &Settings::default(), &WarmStart::default()).unwrap_err();
    assert!(
        matches!(err, Failure::BadInput(ref m) if m.contains("row 0")),
        "{err:?}"
    );
    let rows = vec![Row {
        a: DVector::zeros(3),
        b: f64::NAN,
        cap: None,
    }];
    assert!(das::solve(&centre, &rows, &Settings::default(), &WarmStart::default()).is_err());
}

#[test]
fn a_deadline_passed_stops_both_solvers_before_any_work() {
    // A problem with broken rows (so the solve has steps to take), under a
    // deadline already past: the active-set method stops at its first
    // step, Clarabel before its set-up; without the deadline both solve it.
    let (centre, rows) = (0..)
        .map(random_problem)
        .find(|(c, rows)| rows.iter().any(|r| r.a.dot(c) > r.b + 1e-3))
        .unwrap();
    let past = Some(std::time::Instant::now());
    let settings = Settings {
        deadline: past,
        ..Settings::default()
    };
    let err = das::solve(&centre, &rows, &settings, &WarmStart::default()).unwrap_err();
    assert_eq!(err, Failure::OutOfTime);
    assert!(das::solve(&centre, &rows, &Settings::default(), &WarmStart::default()).is_ok());

    let qp = as_qp(&centre, &rows);
    let warm = WarmStart::default();
    let stopped = qp.solve_active_set(&warm, 0.0, past);
    assert!(matches!(stopped, Err(QpFailure::OutOfTime)), "{stopped:?}");
    assert!(qp.solve_active_set(&warm, 0.0, None).is_ok());
    let out_of_time = QpSettings {
        time_limit: Some(0.0),
        ..QpSettings::default()
    };
    let stopped = qp.solve(&out_of_time);
    assert!(matches!(stopped, Err(QpFailure::OutOfTime)), "{stopped:?}");
}
