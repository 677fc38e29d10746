//! Trajectories a Franka accepts: rest at both ends, acceleration and jerk
//! limits, the approach direction, and the shortest feasible duration —
//! each checked on the returned weights by an independent dense evaluation
//! at 10× the optimisation sampling against Franka's published numbers.

use crate::common::robot::panda;
use dpmp::fixtures::example_distribution;
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, Boundary, OptimizeRequest, OptimizeResponse, Status};
use dpmp::promp::{Basis, PrompConfig};
use dpmp::robot::Robot;
use dpmp::Error;
use nalgebra::Vector3;
use proptest::prelude::*;

/// Franka's published limits (FCI documentation), typed in here rather
/// than read from the shipped file, so the check is independent of it.
const FRANKA_ACCELERATION: [f64; 7] = [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0];
const FRANKA_JERK: [f64; 7] = [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0];

/// The documented phase of `boundary: rest`, typed in here: ramps over the
/// first and last quarter with `ds/dτ = v (3x² − 2x³)`, `x = τ / 0.25`,
/// constant `v = 4/3` between; `s` is that speed integrated.
fn rest_phase(tau: f64) -> f64 {
    let (r, v) = (0.25, 4.0 / 3.0);
    let ramp = |t: f64| {
        let x = t / r;
        v * r * (x.powi(3) - 0.5 * x.powi(4))
    };
    if tau < r {
        ramp(tau)
    } else if tau > 1.0 - r {
        1.0 - ramp(1.0 - tau)
    } else {
        ramp(r) + v * (tau - r)
    }
}

/// Joint `j`'s position at time `t` of `weights`' trajectory: the basis at
/// the phase the timing gives (positions only; derivatives below are
/// finite differences of this).
fn position(req: &OptimizeRequest, basis: &Basis, weights: &[f64], j: usize, t: f64) -> f64 {
    let tau = t / req.task.duration_s;
    let s = match req.task.boundary {
        Boundary::Rest => rest_phase(tau),
        Boundary::Free => tau,
    };
    let psi = basis.row_at(s);
    let nb = basis.n_basis();
    (0..nb).map(|i| psi[i] * weights[j * nb + i]).sum()
}

/// `[max |v| at the ends, max |a| at the ends, max acceleration ratio, max
/// jerk ratio]` of `weights` at `factor` × the request's sampling, by
/// central finite differences of positions in time.
fn dense_figures(req: &OptimizeRequest, weights: &[f64], factor: usize) -> [f64; 4] {
    let basis = Basis::new(&req.task.promp).unwrap();
    let h = 1e-4 * req.task.duration_s;
    let n = req.task.promp.n_samples * factor;
    let mut out = [0.0f64; 4];
    for j in 0..7 {
        let q = |t: f64| position(req, &basis, weights, j, t);
        let derivatives = |t: f64| {
            let v = (q(t + h) - q(t - h)) / (2.0 * h);
            let a = (q(t + h) - 2.0 * q(t) + q(t - h)) / (h * h);
            let jerk = (q(t + 2.0 * h) - 2.0 * q(t + h) + 2.0 * q(t - h) - q(t - 2.0 * h))
                / (2.0 * h * h * h);
            (v, a, jerk)
        };
        for t in [0.0, req.task.duration_s] {
            let (v, a, _) = derivatives(t);
            out[0] = out[0].max(v.abs());
            out[1] = out[1].max(a.abs());
        }
        for k in 0..n {
            let t = req.task.duration_s * k as f64 / (n - 1) as f64;
            let (_, a, jerk) = derivatives(t);
            let limit = FRANKA_ACCELERATION[j] * req.task.acceleration_scaling;
            out[2] = out[2].max(a.abs() / limit);
            out[3] = out[3].max(jerk.abs() / FRANKA_JERK[j]);
        }
    }
    out
}

/// Finite differences at h = 1e-4 × the duration are good to about 1e-6
/// here.
const FD_TOLERANCE: f64 = 1e-5;

fn assert_franka_feasible(req: &OptimizeRequest, resp: &OptimizeResponse, what: &str) {
    let [v_end, a_end, acc, jerk] = dense_figures(req, &resp.weights, 10);
    assert!(
        v_end <= FD_TOLERANCE && a_end <= FD_TOLERANCE,
        "{what}: ends {v_end:e} rad/s, {a_end:e} rad/s²"
    );
    assert!(
        acc <= 1.0 + FD_TOLERANCE,
        "{what}: acceleration ratio {acc}"
    );
    assert!(jerk <= 1.0 + FD_TOLERANCE, "{what}: jerk ratio {jerk}");
    let reported = resp.report.max_acceleration_ratio.unwrap();
    assert!(reported <= 1.0 + 1e-6, "{what}: reported {reported}");
    assert!(
        (reported - acc).abs() < 0.02 * acc.max(1e-2),
        "{what}: {reported} vs {acc}"
    );
    assert!(resp.report.max_jerk_ratio.unwrap() <= 1.0 + 1e-6);
}

/// The optimiser's answer to `req`, asserted `optimal` (problem `seed`).
fn optimal(req: &OptimizeRequest, robot: &Robot, seed: u64) -> OptimizeResponse {
    let resp = optimize(req, robot).unwrap();
    assert_eq!(
        resp.status,
        Status::Optimal,
        "seed {seed}: {:?}",
        resp.reason
    );
    resp
}

#[test]
fn typical_problems_end_at_rest_within_franka_s_limits() {
    let robot = panda();
    for seed in 0..3 {
        let req = typical_request(&robot, seed, &ExampleSettings::default()).unwrap();
        assert_eq!(req.task.boundary, Boundary::Rest);
        let resp = optimal(&req, &robot, seed);
        assert_franka_feasible(&req, &resp, &format!("seed {seed}"));
        // The same path with free ends does not stop: rest is the timing's.
        let mut free = req.clone();
        free.task.boundary = Boundary::Free;
        let moving = dense_figures(&free, &resp.weights, 1);
        assert!(moving[0] > 1e-3, "seed {seed}: the path itself rests");
        // The returned trajectory's first and last points stand still.
        for point in [
            &resp.trajectory.points[0],
            resp.trajectory.points.last().unwrap(),
        ] {
            assert!(point.velocities.iter().all(|v| v.abs() < 1e-9));
        }
    }
}

fn mean_weights(req: &OptimizeRequest, robot: &Robot) -> Vec<f64> {
    req.validate(robot)
        .unwrap()
        .prior()
        .mean
        .as_slice()
        .to_vec()
}

#[test]
fn a_tight_acceleration_scaling_is_met_or_explained() {
    let robot = panda();
    let mut req = typical_request(&robot, 5, &ExampleSettings::default()).unwrap();
    req.task.acceleration_scaling = 0.3;
    req.task.velocity_scaling = 0.5;
    let resp = optimize(&req, &robot).unwrap();
    match resp.status {
        Status::Optimal => {
            assert_franka_feasible(&req, &resp, "scaled");
            assert!(resp.report.max_velocity_ratio <= 1.0 + 1e-6);
        }
        _ => assert!(resp.reason.is_some()),
    }
}

/// The gripper's z axis at the end of `weights`' trajectory.
fn final_gripper_axis(req: &OptimizeRequest, robot: &Robot, weights: &[f64]) -> Vector3<f64> {
    let basis = Basis::new(&req.task.promp).unwrap();
    let psi = basis.row_at(1.0);
    let nb = basis.n_basis();
    let q: Vec<f64> = (0..7)
        .map(|j| (0..nb).map(|i| psi[i] * weights[j * nb + i]).sum())
        .collect();
    robot.tcp_pose(&q).rotation * Vector3::z()
}

#[test]
fn the_gripper_ends_within_the_approach_tolerance() {
    let robot = panda();
    for seed in [0, 7] {
        let mut req = typical_request(&robot, seed, &ExampleSettings::default()).unwrap();
        // An axis 0.25 rad off the prior mean's final gripper axis, asked
        // within 0.1 rad: the optimiser has to turn the hand.
        let axis0 = final_gripper_axis(&req, &robot, &mean_weights(&req, &robot));
        let side = axis0.cross(&Vector3::x()).normalize();
        let axis =
            nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(side), 0.25)
                * axis0;
        let goal = req.task.goal.as_mut().unwrap();
        goal.approach_axis = Some([axis.x, axis.y, axis.z]);
        goal.approach_tolerance_rad = 0.1;
        let resp = optimal(&req, &robot, seed);
        let end = final_gripper_axis(&req, &robot, &resp.weights);
        let angle = end.dot(&axis).clamp(-1.0, 1.0).acos();
        assert!(angle <= 0.1 + 1e-6, "seed {seed}: {angle} rad");
        let reported = resp.report.goal_angle_error_rad.unwrap();
        assert!((reported - angle).abs() < 1e-9, "{reported} vs {angle}");
        assert!(resp.prior_mean_report.goal_angle_error_rad.unwrap() > 0.2);
        assert_franka_feasible(&req, &resp, &format!("seed {seed}"));
    }
}

/// A request with a random prior, its mean's start and end as start and
/// final configuration, no obstacle, no goal, `duration_s` seconds.
fn duration_request(seed: u64, duration_s: f64) -> OptimizeRequest {
    let basis = Basis::new(&PrompConfig::default()).unwrap();
    let dist = example_distribution(&basis, 12, seed).unwrap();
    let mean = dist.trajectory_mean(&basis);
    let row = |t: usize| (0..7).map(|j| mean[(t, j)]).collect::<Vec<f64>>();
    let mut req: OptimizeRequest = serde_json::from_value(serde_json::json!({
        "prior": dpmp::optim::PriorSpec::from(&dist),
        "duration_s": duration_s,
        "start": row(0),
    }))
    .unwrap();
    req.task.options.final_configuration = Some(row(basis.n_samples() - 1));
    req.task.options.restarts = 0;
    req
}

/// Per joint, the path length `∫|q̇| dt` of an answer's trajectory (the
/// trapezoid rule on its velocities).
fn joint_path_lengths(resp: &dpmp::optim::OptimizeResponse) -> Vec<f64> {
    let points = &resp.trajectory.points;
    (0..7)
        .map(|j| {
            points
                .windows(2)
                .map(|w| {
                    let h = w[1].time_from_start - w[0].time_from_start;
                    0.5 * h * (w[0].velocities[j].abs() + w[1].velocities[j].abs())
                })
                .sum()
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 6, ..ProptestConfig::default() })]

    /// A too short duration is proven infeasible by the closed-form bound;
    /// every duration below the reported lower bound is too; a reported
    /// `min_duration_s` gives a verified optimum; and every optimal
    /// trajectory's joint path lengths stay within the bound's.
    #[test]
    fn the_duration_bound_is_a_proof_and_min_duration_s_is_verified(
        seed in 0u64..1000,
        duration in 0.05f64..0.6,
    ) {
        let robot = panda();
        let req = duration_request(seed, duration);
        let resp = optimize(&req, &robot).unwrap();
        let check_lengths = |req: &OptimizeRequest, resp: &dpmp::optim::OptimizeResponse| {
            let rates = req.validate(&robot).unwrap().joint_rates();
            for (j, length) in joint_path_lengths(resp).iter().enumerate() {
                let bound = rates[j].path_length_bound(req.task.duration_s);
                assert!(*length <= bound * (1.0 + 1e-3) + 1e-9, "joint {j}: {length} > {bound}");
            }
        };
        if resp.status == Status::Optimal {
            prop_assert!(resp.duration_lower_bound_s.is_none());
            assert_franka_feasible(&req, &resp, "short but feasible");
            check_lengths(&req, &resp);
            return Ok(());
        }
        let Some(bound) = resp.duration_lower_bound_s else {
            // Not proven too short: the solver's own verdict stands.
            prop_assert!(resp.min_duration_s.is_none());
            return Ok(());
        };
        prop_assert_eq!(resp.status, Status::Infeasible);
        prop_assert_eq!(resp.stop_reason, dpmp::optim::StopReason::DurationTooShort);
        let reason = resp.reason.clone().unwrap();
        prop_assert!(reason.starts_with("duration_s:"), "{}", reason);
        prop_assert!(bound >= duration);
        let below = optimize(&duration_request(seed, 0.9 * bound), &robot).unwrap();
        prop_assert_eq!(below.status, Status::Infeasible);
        prop_assert!(below.duration_lower_bound_s.is_some());
        if let Some(d) = resp.min_duration_s {
            prop_assert!(d >= bound);
            // At the reported duration the optimiser finds a verified
            // optimum (checked again here at 10× its sampling).
            let at = duration_request(seed, d);
            let ok = optimize(&at, &robot).unwrap();
            prop_assert_eq!(ok.status, Status::Optimal, "at {} s: {:?}", d, ok.reason);
            assert_franka_feasible(&at, &ok, "at the verified duration");
            check_lengths(&at, &ok);
        }
    }
}

fn field_of(mut edit: impl FnMut(&mut OptimizeRequest)) -> String {
    let robot = panda();
    let mut req = typical_request(&robot, 0, &ExampleSettings::default()).unwrap();
    edit(&mut req);
    match req.validate(&robot) {
        Err(Error::Invalid { field, .. }) => field,
        other => panic!("expected an invalid-input error, got {:?}", other.err()),
    }
}

#[test]
fn bad_limits_scalings_and_axes_are_named() {
    let axis = |a: [f64; 3]| {
        move |r: &mut OptimizeRequest| r.task.goal.as_mut().unwrap().approach_axis = Some(a)
    };
    assert_eq!(field_of(axis([0.0, 0.0, 0.0])), "goal.approach_axis");
    assert_eq!(field_of(axis([0.0, 0.0, 2.0])), "goal.approach_axis");
    assert_eq!(
        field_of(axis([f64::NAN, 0.0, 1.0])),
        "goal.approach_axis[0]"
    );
    assert_eq!(
        field_of(|r| {
            axis([0.0, 0.0, 1.0])(r);
            r.task.goal.as_mut().unwrap().approach_tolerance_rad = 0.0;
        }),
        "goal.approach_tolerance_rad"
    );
    assert_eq!(
        field_of(|r| r.task.velocity_scaling = 0.0),
        "velocity_scaling"
    );
    assert_eq!(
        field_of(|r| r.task.velocity_scaling = 1.5),
        "velocity_scaling"
    );
    assert_eq!(
        field_of(|r| r.task.acceleration_scaling = f64::NAN),
        "acceleration_scaling"
    );
    assert_eq!(
        field_of(|r| r.task.acceleration_limits = Some(vec![1.0; 6])),
        "acceleration_limits"
    );
    assert_eq!(
        field_of(|r| r.task.jerk_limits = Some(vec![1.0, 1.0, -1.0, 1.0, 1.0, 1.0, 1.0])),
        "jerk_limits[2]"
    );
}

#[test]
fn a_limits_file_beside_a_urdf_is_read_and_wrong_joint_names_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = dir.path().join("panda.urdf");
    std::fs::write(&urdf, dpmp::robot::PANDA_URDF).unwrap();
    // Primitive collision geometry is not needed: the URDF's meshes are
    // looked up beside it, so copy them too.
    for (name, bytes) in dpmp::robot::PANDA_MESHES {
        let path = dir.path().join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, bytes).unwrap();
    }
    let plain = Robot::from_urdf_file(&urdf, "panda_link0", "panda_tcp").unwrap();
    assert!(plain.limits().iter().all(|l| l.acceleration.is_none()));
    assert!(plain
        .warnings()
        .iter()
        .any(|w| w.contains("joint_limits.yaml")));
    let limits = dir.path().join("joint_limits.yaml");
    std::fs::write(&limits, dpmp::robot::limits_file::PANDA_JOINT_LIMITS).unwrap();
    let robot = Robot::from_urdf_file(&urdf, "panda_link0", "panda_tcp").unwrap();
    assert_eq!(robot.limits()[1].acceleration, Some(7.5));
    assert_eq!(robot.limits()[6].jerk, Some(10000.0));
    let wrong = dpmp::robot::limits_file::PANDA_JOINT_LIMITS.replace("panda_joint7", "joint7");
    std::fs::write(&limits, wrong).unwrap();
    let err = Robot::from_urdf_file(&urdf, "panda_link0", "panda_tcp")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("joint_limits.yaml") && err.contains("joint_limits.joint7"),
        "{err}"
    );
}
