//! The continuous-motion certificate: the displacement bound is never
//! smaller than the displacement measured by 100× oversampling, and an
//! obstacle that slips between two verification samples makes the
//! trajectory infeasible (and the optimiser's answer, when `optimal`, clear
//! at 100× the verification sampling).

use crate::common::scene::sphere;
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::geometry::{OrientedBox, Primitive};
use dpmp::optim::verify::continuous::{
    displacement_bound, displacement_bound_between, path_lengths,
};
use dpmp::optim::{optimize, OptimizeRequest, PriorSpec, Status};
use dpmp::promp::{Basis, PrompConfig};
use dpmp::robot::{Robot, ShapeGeometry};
use dpmp::scene::Scene;
use nalgebra::{DMatrix, DVector, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Every hull vertex and finger-box corner of the robot at `q` (base
/// frame): the points whose motion the bound must cover.
fn robot_points(robot: &Robot, q: &[f64]) -> Vec<Vector3<f64>> {
    let frames = robot.fk(q);
    let mut out = Vec::new();
    for s in robot.collision_shapes() {
        let pose = frames.poses[s.link];
        match &s.geometry {
            ShapeGeometry::Convex(h) => out.extend(
                h.vertices()
                    .iter()
                    .map(|v| (pose * Point3::from(*v)).coords),
            ),
            ShapeGeometry::Primitive(Primitive::Box(OrientedBox { center, .. })) => {
                out.push((pose * Point3::from(*center)).coords)
            }
            _ => {}
        }
    }
    out
}

/// Joint positions and velocities (per second) of weights `wm` at phase z.
fn state(basis: &Basis, wm: &DMatrix<f64>, z: f64, duration: f64) -> (Vec<f64>, Vec<f64>) {
    let q = (wm.transpose() * basis.row_at(z)).iter().copied().collect();
    let qd = (wm.transpose() * basis.derivative_row_at(z) / duration)
        .iter()
        .copied()
        .collect();
    (q, qd)
}

#[test]
fn the_displacement_bound_covers_100x_oversampled_motion() {
    let robot = Robot::panda().unwrap();
    let config = PrompConfig::default();
    let basis = Basis::new(&config).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(22);
    let mut worst_ratio: f64 = 0.0;
    let mut tight_ratio = Vec::new();
    for trial in 0..12 {
        // Random smooth motions within the limits: each joint's weights
        // drawn around mid-range, spread up to a third of the range.
        let wm = DMatrix::from_fn(config.n_basis, 7, |_, j| {
            let l = robot.limits()[j];
            l.mid() + (l.upper - l.lower) * rng.gen_range(-0.33..0.33)
        });
        let duration = [0.5, 2.0, 4.0][trial % 3];
        let n = 40;
        for k in 0..n {
            let (za, zb) = (k as f64 / n as f64, (k + 1) as f64 / n as f64);
            let (qa, qda) = state(&basis, &wm, za, duration);
            let (qb, qdb) = state(&basis, &wm, zb, duration);
            let bound = displacement_bound(
                robot.lever_arms(),
                &qa,
                &qb,
                &qda,
                &qdb,
                (zb - za) * duration,
            );
            let h = (zb - za) * duration;
            let tight = displacement_bound_between(
                &robot,
                &robot.lever_arms_at(&robot.fk(&qa)),
                &robot.lever_arms_at(&robot.fk(&qb)),
                &path_lengths(&qa, &qb, &qda, &qdb, h),
            );
            assert!(tight <= bound + 1e-15, "{tight} > {bound}");
            tight_ratio.push(tight / bound.max(f64::MIN_POSITIVE));
            let pa = robot_points(&robot, &qa);
            let mut largest: f64 = 0.0;
            for s in 1..=100 {
                let z = za + (zb - za) * s as f64 / 100.0;
                let (q, _) = state(&basis, &wm, z, duration);
                let p = robot_points(&robot, &q);
                for (x, y) in pa.iter().zip(&p) {
                    largest = largest.max((x - y).norm());
                }
            }
            assert!(
                largest <= tight + 1e-12,
                "trial {trial}, interval {k}: moved {largest} > bound {tight} (configuration-free {bound})"
            );
            if tight > 0.0 {
                worst_ratio = worst_ratio.max(largest / tight);
            }
        }
    }
    tight_ratio.sort_by(f64::total_cmp);
    let median_tight = tight_ratio[tight_ratio.len() / 2];
    eprintln!(
        "largest measured displacement / bound: {worst_ratio:.3}; configuration bound / free bound, median {median_tight:.3}"
    );
    // The configurations' arms are markedly tighter on these motions.
    assert!(median_tight < 0.9, "{median_tight}");
    assert!(
        worst_ratio > 0.05,
        "the bound is uselessly loose: {worst_ratio}"
    );
}

/// A fast swing of joint 1 (−1.5 → 1.5 rad in 2 s) verified on only 20
/// samples, on the prior of typical problem 0.
fn swing_request(robot: &Robot) -> (OptimizeRequest, Vec<f64>) {
    let settings = ExampleSettings {
        n_obstacles: 0,
        with_goal: false,
        with_start: false,
        ..Default::default()
    };
    let mut req = typical_request(robot, 0, &settings).unwrap();
    req.task.promp.n_samples = 5;
    req.task.options.verify_factor = 4;
    req.task.duration_s = 2.0;
    req.task.clearance_m = 0.0;
    let PriorSpec::Full { mean, .. } = &req.prior else {
        panic!("typical requests carry a full prior");
    };
    let nb = req.task.promp.n_basis;
    let mut w = mean.clone();
    for (i, wi) in w.iter_mut().take(nb).enumerate() {
        *wi = -1.5 + 3.0 * i as f64 / (nb - 1) as f64;
    }
    (req, w)
}

#[test]
fn an_obstacle_between_two_samples_is_caught() {
    let robot = Robot::panda().unwrap();
    let (mut req, w) = swing_request(&robot);
    let problem = req.validate(&robot).unwrap();
    let basis = problem.basis().resampled(20).unwrap();
    let nb = req.task.promp.n_basis;
    let wm = DMatrix::from_fn(nb, 7, |i, j| w[j * nb + i]);
    // Find a point the robot covers at the middle of a verification
    // interval but clears at both of its samples.
    let phases = basis.phases().to_vec();
    let mut found = None;
    'search: for k in 0..phases.len() - 1 {
        let mid = 0.5 * (phases[k] + phases[k + 1]);
        let (qm, _) = state(&basis, &wm, mid, req.task.duration_s);
        let (qa, _) = state(&basis, &wm, phases[k], req.task.duration_s);
        let (qb, _) = state(&basis, &wm, phases[k + 1], req.task.duration_s);
        for p in robot_points(&robot, &qm) {
            let ball = Scene::new(vec![sphere("slipped", p.into(), 0.003)]).unwrap();
            let clear = |q: &[f64]| ball.min_clearance(&robot, &robot.fk(q)).unwrap().distance;
            if clear(&qa) > 0.005 && clear(&qb) > 0.005 && clear(&qm) < 0.0 {
                found = Some((p, mid));
                break 'search;
            }
        }
    }
    let (centre, mid) = found.expect("a fast swing leaves points between its samples");
    req.task.obstacles = vec![sphere("slipped", centre.into(), 0.003)];
    let problem = req.validate(&robot).unwrap();
    let report = problem.evaluate(&w);
    // Clear at every verification sample, penetrating in between: the
    // certificate sees it and the trajectory is not feasible.
    assert!(report.min_clearance_m.unwrap() >= 0.0, "{report:?}");
    let continuous = report.continuous_clearance_m.unwrap();
    assert!(continuous < 0.0, "{report:?}");
    assert!(!problem.is_feasible(&report));
    let (qm, _) = state(&basis, &wm, mid, req.task.duration_s);
    let scene = Scene::new(req.task.obstacles.clone()).unwrap();
    let truth = scene
        .min_clearance(&robot, &robot.fk(&qm))
        .unwrap()
        .distance;
    assert!(continuous <= truth, "{continuous} > {truth}");
    // Optimising from a narrow prior around this swing never returns it as
    // `optimal`: an optimal answer clears the ball at 100× the
    // verification sampling.
    let n = w.len();
    req.prior = PriorSpec::Full {
        mean: w.clone(),
        cov: (0..n)
            .map(|i| (0..n).map(|j| if i == j { 0.01 } else { 0.0 }).collect())
            .collect(),
    };
    let resp = optimize(&req, &robot).unwrap();
    if resp.status == Status::Optimal {
        let out = DVector::from_column_slice(&resp.weights);
        let wm = DMatrix::from_fn(nb, 7, |i, j| out[j * nb + i]);
        for s in 0..=2000 {
            let (q, _) = state(&basis, &wm, s as f64 / 2000.0, req.task.duration_s);
            let d = scene.min_clearance(&robot, &robot.fk(&q)).unwrap().distance;
            assert!(
                d >= -1e-6,
                "optimal answer penetrates by {d} at phase {}",
                s as f64 / 2000.0
            );
        }
        assert!(resp.report.continuous_clearance_m.unwrap() >= -1e-6);
    }
}

/// With 40 verification samples and a 10 cm activation distance the
/// pairs beyond the activation distance are certified by it, so the
/// certificate bisects pair by pair: a ball that the arm passes through
/// between two samples (clear at both) is flagged at a phase where it truly
/// penetrates, so the optimiser can put a constraint there.
#[test]
fn a_dip_between_close_samples_is_flagged_pair_by_pair() {
    let robot = Robot::panda().unwrap();
    let (mut req, w) = swing_request(&robot);
    req.task.promp.n_samples = 10;
    req.task.options.activation_distance_m = Some(0.1);
    let problem = req.validate(&robot).unwrap();
    let nb = req.task.promp.n_basis;
    let wm = DMatrix::from_fn(nb, 7, |i, j| w[j * nb + i]);
    let duration = req.task.duration_s;
    let warp = req.task.time_warp();
    let at = |tau: f64| state(problem.basis(), &wm, warp.at(tau)[0], duration).0;
    // The verification samples (time fractions).
    let times = problem.basis().resampled(40).unwrap().phases().to_vec();
    let ball = |p: Vector3<f64>| sphere("slipped", p.into(), 0.003);
    let mut found = None;
    'search: for k in (0..times.len() - 1).step_by(7) {
        let (ta, tb) = (times[k], times[k + 1]);
        let (qa, qb) = (at(ta), at(tb));
        for p in robot_points(&robot, &at(0.5 * (ta + tb))) {
            let scene = Scene::new(vec![ball(p)]).unwrap();
            let clear = |q: &[f64]| scene.min_clearance(&robot, &robot.fk(q)).unwrap().distance;
            if clear(&qa) > 0.001 && clear(&qb) > 0.001 {
                found = Some(p);
                break 'search;
            }
        }
    }
    let centre = found.expect("a vertex that passes through the ball between two samples");
    req.task.obstacles = vec![ball(centre)];
    let problem = req.validate(&robot).unwrap();
    let scene = Scene::new(req.task.obstacles.clone()).unwrap();
    let v = problem
        .verifier()
        .verify(&DVector::from_column_slice(&w), &Default::default());
    assert!(v.report.min_clearance_m.unwrap() >= 0.0, "{:?}", v.report);
    assert!(
        v.report.continuous_clearance_m.unwrap() < 0.0,
        "{:?}",
        v.report
    );
    let dips = v
        .flagged
        .iter()
        .filter(|&&tau| {
            scene
                .min_clearance(&robot, &robot.fk(&at(tau)))
                .unwrap()
                .distance
                < 0.0
        })
        .count();
    assert!(dips > 0, "flagged {:?}", v.flagged);
}

/// Typical prior 5 without obstacles and with a 0.55 rad joint-limit
/// margin rides a joint limit: sampled coarsely (10, 20 and 40 samples, 4
/// dense per sample), the `optimal` answer stays within the limits at
/// every one of 10,000 phases, not only at its verification samples, and
/// its report's excess is never below the scan's.
#[test]
fn an_optimal_answer_keeps_its_joint_limits_between_samples() {
    let robot = Robot::panda().unwrap();
    let settings = ExampleSettings {
        n_obstacles: 0,
        with_start: false,
        ..Default::default()
    };
    let margin = 0.55;
    for n_samples in [10, 20, 40] {
        let mut req = typical_request(&robot, 5, &settings).unwrap();
        req.task.joint_limit_margin_rad = margin;
        req.task.promp.n_samples = n_samples;
        req.task.options.verify_factor = 4;
        let problem = req.validate(&robot).unwrap();
        let resp = optimize(&req, &robot).unwrap();
        assert_eq!(
            resp.status,
            Status::Optimal,
            "{n_samples}: {:?}",
            resp.reason
        );
        let nb = req.task.promp.n_basis;
        let wm = DMatrix::from_fn(nb, 7, |i, j| resp.weights[j * nb + i]);
        let basis = problem.basis().resampled(10_000).unwrap();
        let mut scan = f64::NEG_INFINITY;
        for &z in basis.phases() {
            let (q, _) = state(&basis, &wm, z, req.task.duration_s);
            for (qj, limit) in q.iter().zip(robot.limits()) {
                scan = scan.max((qj - (limit.upper - margin)).max(limit.lower + margin - qj));
            }
        }
        // The answer rides a limit (the case is a real test) and keeps it.
        assert!(scan > -1e-4, "{n_samples}: no joint near its limit: {scan}");
        assert!(
            scan <= 1e-6,
            "{n_samples}: beyond a joint limit by {scan} rad between samples"
        );
        let reported = resp.report.max_joint_limit_violation_rad;
        assert!(
            reported >= scan - 1e-9,
            "{n_samples}: report {reported} below the scan {scan}"
        );
    }
}

/// The certificate bisects pair by pair near the closest pair: its bound
/// must still never exceed the clearance measured by exact queries at
/// 2,000 phases (against every obstacle, not only the pairs it followed),
/// on optimised answers (which touch the clearance, so every interval near
/// the closest pair bisects) and on trajectories pulled halfway back to the
/// colliding prior mean (where the bound must fall short). Two scene
/// families: the typical cluster, and a denser one with obstacles closer
/// to the path.
#[test]
fn the_pairwise_certificate_never_exceeds_the_oversampled_clearance() {
    let robot = Robot::panda().unwrap();
    let dense = ExampleSettings {
        n_obstacles: 20,
        offset_m: (0.02, 0.06),
        ..Default::default()
    };
    let cases = [
        (0, ExampleSettings::default()),
        (3, ExampleSettings::default()),
        (7, ExampleSettings::default()),
        (11, dense.clone()),
        (12, dense),
    ];
    let mut answers_checked = 0;
    for (seed, settings) in cases {
        let req = typical_request(&robot, seed, &settings).unwrap();
        let problem = req.validate(&robot).unwrap();
        let resp = optimize(&req, &robot).unwrap();
        let PriorSpec::Full { mean, .. } = &req.prior else {
            panic!("typical requests carry a full prior");
        };
        let halfway: Vec<f64> = resp
            .weights
            .iter()
            .zip(mean)
            .map(|(a, m)| 0.5 * (a + m))
            .collect();
        let scene = Scene::new(req.task.obstacles.clone()).unwrap();
        let nb = req.task.promp.n_basis;
        let basis = problem.basis().resampled(2000).unwrap();
        for (what, w) in [("answer", &resp.weights), ("halfway", &halfway)] {
            let report = problem.evaluate(w);
            let certified = report.continuous_clearance_m.unwrap();
            let wm = DMatrix::from_fn(nb, 7, |i, j| w[j * nb + i]);
            let sampled = basis
                .phases()
                .iter()
                .map(|&z| {
                    let (q, _) = state(&basis, &wm, z, req.task.duration_s);
                    scene.min_clearance(&robot, &robot.fk(&q)).unwrap().distance
                })
                .fold(f64::INFINITY, f64::min);
            assert!(
                certified <= sampled + 1e-9,
                "seed {seed} {what}: certificate {certified} above the sampled clearance {sampled}"
            );
            // A trajectory that dips below the clearance between its
            // samples is told where: some flagged phase for the optimiser.
            let v = problem
                .verifier()
                .verify(&DVector::from_column_slice(w), &Default::default());
            if certified < req.task.clearance_m - 1e-6 {
                assert!(
                    !v.flagged.is_empty(),
                    "seed {seed} {what}: certificate {certified} below the clearance, nothing flagged"
                );
            }
            if what == "answer" && resp.status == Status::Optimal {
                answers_checked += 1;
                // Not vacuous: within 2 mm of the truth on an answer that
                // touches the clearance.
                assert!(
                    sampled - certified < 2e-3,
                    "seed {seed}: certificate {certified} far below {sampled}"
                );
            }
        }
    }
    assert!(
        answers_checked >= 4,
        "only {answers_checked} optimal answers"
    );
}
