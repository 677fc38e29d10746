//! Request handling: field-naming validation errors, infeasibility
//! diagnoses, the annotation prior with repair, samples, determinism and
//! cancellation.

use crate::common::requests::{needs_restarts, typical};
use crate::common::scene::sphere;
use dpmp::fixtures::ExampleSettings;
use dpmp::geometry::Sphere;
use dpmp::optim::{
    optimize, optimize_with, OptimizeRequest, OptimizeResponse, PriorSpec, SolveControl, Status,
    StopReason,
};
use dpmp::promp::annotation::joints_from_distribution;
use dpmp::promp::codec::{decode_covariance, encode_covariance, DiagEncoding};
use dpmp::robot::Robot;
use dpmp::scene::ObstacleShape;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

fn request(seed: u64, n_obstacles: usize) -> (Robot, OptimizeRequest) {
    let settings = ExampleSettings {
        n_obstacles,
        ..Default::default()
    };
    typical(seed, &settings)
}

fn field_of(req: &OptimizeRequest, robot: &Robot) -> String {
    req.validate(robot)
        .err()
        .and_then(|e| e.field().map(str::to_string))
        .unwrap_or_default()
}

#[test]
fn bad_input_names_the_field() {
    let (robot, base) = request(1, 2);
    let mut r = base.clone();
    if let PriorSpec::Full { cov, .. } = &mut r.prior {
        cov[3][4] = f64::NAN;
    }
    assert_eq!(field_of(&r, &robot), "prior.cov[3][4]");
    let mut r = base.clone();
    if let PriorSpec::Full { cov, .. } = &mut r.prior {
        cov[5].pop();
    }
    assert_eq!(field_of(&r, &robot), "prior.cov[5]");
    let mut r = base.clone();
    if let PriorSpec::Full { cov, .. } = &mut r.prior {
        cov.pop();
    }
    assert_eq!(field_of(&r, &robot), "prior.cov");
    let mut r = base.clone();
    if let PriorSpec::Full { mean, .. } = &mut r.prior {
        mean.push(0.0);
    }
    assert_eq!(field_of(&r, &robot), "prior.mean");
    let mut r = base.clone();
    if let PriorSpec::Full { cov, .. } = &mut r.prior {
        cov[4][3] += 1.0;
    }
    assert_eq!(field_of(&r, &robot), "prior.cov[4][3]");
    let mut r = base.clone();
    r.task.start = Some(vec![0.0; 6]);
    assert_eq!(field_of(&r, &robot), "start");
    let mut r = base.clone();
    r.task.start.as_mut().unwrap()[2] = f64::INFINITY;
    assert_eq!(field_of(&r, &robot), "start[2]");
    let mut r = base.clone();
    r.task.duration_s = -1.0;
    assert_eq!(field_of(&r, &robot), "duration_s");
    let mut r = base.clone();
    r.task.clearance_m = -0.01;
    assert_eq!(field_of(&r, &robot), "clearance_m");
    let mut r = base.clone();
    r.task.joint_limit_margin_rad = 2.0;
    assert_eq!(field_of(&r, &robot), "joint_limit_margin_rad");
    let mut r = base.clone();
    r.task.samples = 1000;
    assert_eq!(field_of(&r, &robot), "samples");
    let mut r = base.clone();
    r.task.promp.n_samples = 5000;
    assert_eq!(field_of(&r, &robot), "promp.n_samples");
    let mut r = base.clone();
    r.task.promp.n_basis = 6;
    assert_eq!(field_of(&r, &robot), "prior.mean");
    let mut r = base.clone();
    r.task.goal.as_mut().unwrap().tolerance_m = 0.0;
    assert_eq!(field_of(&r, &robot), "goal.tolerance_m");
    let mut r = base.clone();
    r.task.goal.as_mut().unwrap().position[1] = f64::NAN;
    assert_eq!(field_of(&r, &robot), "goal.position[1]");
    let mut r = base.clone();
    r.task.options.verify_factor = 2;
    assert_eq!(field_of(&r, &robot), "options.verify_factor");
    let mut r = base.clone();
    r.task.options.activation_distance_m = Some(0.001);
    assert_eq!(field_of(&r, &robot), "options.activation_distance_m");
    let mut r = base.clone();
    if let ObstacleShape::Sphere(Sphere { radius, .. }) = &mut r.task.obstacles[0].shape {
        *radius = -1.0;
    }
    assert!(
        field_of(&r, &robot).starts_with("obstacles[0]"),
        "{}",
        field_of(&r, &robot)
    );
    // Via points: one time each, inside the motion, a finite configuration
    // of the robot's size or a TCP position near the robot with a positive
    // tolerance, no two at once.
    let q = vec![0.0; 7];
    let via =
        |phase: Option<f64>, time_s: Option<f64>, configuration: Vec<f64>| dpmp::optim::Waypoint {
            phase,
            time_s,
            configuration: Some(configuration),
            position: None,
            tolerance_m: None,
            tolerance_rad: None,
        };
    let at = |position: [f64; 3], tolerance_m: Option<f64>| dpmp::optim::Waypoint {
        phase: Some(0.5),
        time_s: None,
        configuration: None,
        position: Some(position),
        tolerance_m,
        tolerance_rad: None,
    };
    let mut both = at([0.5, 0.0, 0.5], None);
    both.configuration = Some(q.clone());
    let neither = dpmp::optim::Waypoint {
        position: None,
        ..at([0.5, 0.0, 0.5], None)
    };
    let mut tolerant = via(Some(0.5), None, q.clone());
    tolerant.tolerance_m = Some(0.01);
    let mut negative = via(Some(0.5), None, q.clone());
    negative.tolerance_rad = Some(-0.1);
    let mut angled = at([0.5, 0.0, 0.5], None);
    angled.tolerance_rad = Some(0.1);
    for (points, field) in [
        (vec![both], "via_points[0]"),
        (vec![neither], "via_points[0]"),
        (vec![tolerant], "via_points[0].tolerance_m"),
        (vec![negative], "via_points[0].tolerance_rad"),
        (vec![angled], "via_points[0].tolerance_rad"),
        (
            vec![at([0.5, f64::NAN, 0.5], None)],
            "via_points[0].position[1]",
        ),
        (vec![at([20.0, 0.0, 0.5], None)], "via_points[0].position"),
        (
            vec![at([0.5, 0.0, 0.5], Some(0.0))],
            "via_points[0].tolerance_m",
        ),
        (vec![via(Some(0.5), Some(1.0), q.clone())], "via_points[0]"),
        (vec![via(None, None, q.clone())], "via_points[0]"),
        (vec![via(Some(1.0), None, q.clone())], "via_points[0].phase"),
        (
            vec![via(Some(f64::NAN), None, q.clone())],
            "via_points[0].phase",
        ),
        (
            vec![via(None, Some(4.0), q.clone())],
            "via_points[0].time_s",
        ),
        (
            vec![via(None, Some(-0.1), q.clone())],
            "via_points[0].time_s",
        ),
        (
            vec![via(Some(0.5), None, vec![0.0; 6])],
            "via_points[0].configuration",
        ),
        (
            vec![
                via(Some(0.2), None, q.clone()),
                via(
                    Some(0.5),
                    None,
                    vec![0.0, f64::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0],
                ),
            ],
            "via_points[1].configuration[1]",
        ),
        (
            vec![
                via(Some(0.5), None, q.clone()),
                via(None, Some(2.0), q.clone()),
            ],
            "via_points[1]",
        ),
        (
            (0..33)
                .map(|k| via(Some((k as f64 + 1.0) / 40.0), None, q.clone()))
                .collect(),
            "via_points",
        ),
    ] {
        let mut r = base.clone();
        r.task.via_points = points;
        assert_eq!(field_of(&r, &robot), field);
    }
    // Unknown fields and malformed JSON are rejected by serde.
    let json = serde_json::to_value(&base).unwrap();
    let mut extra = json.clone();
    extra["bogus"] = serde_json::json!(1);
    assert!(serde_json::from_value::<OptimizeRequest>(extra).is_err());
    let mut extra = json.clone();
    extra["options"]["bogus"] = serde_json::json!(1);
    assert!(serde_json::from_value::<OptimizeRequest>(extra).is_err());
    // Defaults from DESIGN.md.
    let minimal: OptimizeRequest =
        serde_json::from_value(serde_json::json!({"prior": json["prior"].clone()})).unwrap();
    assert_eq!(minimal.task.duration_s, 4.0);
    assert_eq!(minimal.task.clearance_m, 0.02);
    assert_eq!(minimal.task.promp.n_samples, 150);
    assert!(minimal.validate(&robot).is_ok());
}

#[test]
fn infeasible_cases_are_diagnosed_with_the_constraint() {
    let (robot, base) = request(2, 3);
    // Start outside the joint limits.
    let mut r = base.clone();
    r.task.start.as_mut().unwrap()[3] = 0.5;
    let resp = optimize(&r, &robot).unwrap();
    assert_eq!(resp.status, Status::Infeasible);
    assert_eq!(resp.stop_reason, StopReason::ProvenInfeasible);
    assert!(
        resp.reason.as_deref().unwrap().contains("start[3]"),
        "{:?}",
        resp.reason
    );
    // Start in collision: a sphere on the start TCP.
    let mut r = base.clone();
    let tcp = robot
        .tcp_pose(r.task.start.as_ref().unwrap())
        .translation
        .vector;
    r.task.obstacles.push(sphere("blocker", tcp.into(), 0.03));
    let resp = optimize(&r, &robot).unwrap();
    assert_eq!(resp.status, Status::Infeasible);
    let reason = resp.reason.unwrap();
    assert!(
        reason.contains("start is in collision") && reason.contains("blocker"),
        "{reason}"
    );
    // Goal out of reach.
    let mut r = base.clone();
    r.task.goal.as_mut().unwrap().position = [2.0, 0.0, 0.5];
    let resp = optimize(&r, &robot).unwrap();
    assert_eq!(resp.status, Status::Infeasible);
    assert!(resp.reason.unwrap().contains("out of reach"));
    // Goal buried in an obstacle (deeper than tolerance + the TCP's
    // distance to the nearest robot shape - clearance): diagnosed up front.
    let mut r = base.clone();
    let goal = r.task.goal.as_ref().unwrap().position;
    r.task.obstacles.push(sphere("over-goal", goal, 0.1));
    let resp = optimize(&r, &robot).unwrap();
    assert_eq!(resp.status, Status::Infeasible);
    let reason = resp.reason.unwrap();
    assert!(
        reason.contains("over-goal") && reason.contains("deep inside"),
        "{reason}"
    );
    // A berry just around the goal point is not a proof of infeasibility
    // (the TCP is not a collision shape): never `optimal` with a violation.
    if let ObstacleShape::Sphere(Sphere { radius, .. }) = &mut r.task.obstacles[0].shape {
        *radius = 0.02;
    }
    let resp = optimize(&r, &robot).unwrap();
    let problem = r.validate(&robot).unwrap();
    if resp.status == Status::Optimal {
        assert!(problem.is_feasible(&problem.evaluate(&resp.weights)));
    }
}

#[test]
fn annotation_prior_with_an_indefinite_joint_is_repaired_and_solved() {
    let (robot, base) = request(4, 4);
    let problem = base.validate(&robot).unwrap();
    let mut joints = joints_from_distribution(problem.prior()).unwrap();
    // Make joint 5's covariance indefinite, as in the published K = 4 file.
    let mut cov = decode_covariance(&joints[4].l, DiagEncoding::Raw).unwrap();
    cov[(7, 7)] -= 2.0 * cov.symmetric_eigenvalues().amax();
    joints[4].l = encode_covariance(&cov, DiagEncoding::Raw).unwrap();
    // Through JSON, in the paper's column format.
    let mut json = serde_json::to_value(&base).unwrap();
    let annotation: Vec<serde_json::Value> = joints
        .iter()
        .map(|j| {
            serde_json::json!({
                "mean_weights": j.mean_weights.iter().map(|v| vec![*v]).collect::<Vec<_>>(),
                "L": j.l,
            })
        })
        .collect();
    json["prior"] = serde_json::json!({ "annotation": annotation });
    let req: OptimizeRequest = serde_json::from_value(json).unwrap();
    let resp = optimize(&req, &robot).unwrap();
    assert!(
        resp.report
            .warnings
            .iter()
            .any(|w| w.contains("joint 5") && w.contains("positive semi-definite")),
        "{:?}",
        resp.report.warnings
    );
    // The repaired prior is badly conditioned (eigenvalues clipped to 1e-9
    // of the largest): the SCP may stop on its iteration limit (known
    // limitation), but never claims `optimal` for an infeasible answer and
    // never calls this solvable problem infeasible.
    assert_ne!(resp.status, Status::Infeasible, "{:?}", resp.reason);
    let problem = req.validate(&robot).unwrap();
    let feasible = problem.is_feasible(&problem.evaluate(&resp.weights));
    assert_eq!(
        resp.status == Status::Optimal,
        resp.status == Status::Optimal && feasible
    );
    assert!(resp.mahalanobis.is_finite());
}

#[test]
fn same_request_gives_the_same_bytes_except_solve_ms() {
    let (robot, mut req) = request(6, 3);
    req.task.samples = 1;
    let a = optimize(&req, &robot).unwrap();
    let b = optimize(&req, &robot).unwrap();
    assert_eq!(a.deterministic_json(), b.deterministic_json());
    let text = serde_json::to_string(&a).unwrap();
    for key in [
        "\"status\"",
        "\"weights\"",
        "\"mahalanobis\"",
        "\"trajectory\"",
        "\"joint_names\"",
        "\"points\"",
        "\"positions\"",
        "\"velocities\"",
        "\"time_from_start\"",
        "\"report\"",
        "\"min_clearance_m\"",
        "\"max_joint_limit_violation_rad\"",
        "\"max_velocity_ratio\"",
        "\"goal_error_m\"",
        "\"iterations\"",
        "\"solve_ms\"",
        "\"verified_samples\"",
        "\"warnings\"",
        "\"prior_mean_report\"",
    ] {
        assert!(text.contains(key), "missing {key}");
    }
    assert_eq!(a.report.verified_samples, 600);
    assert_eq!(a.trajectory.points.len(), 150);
    // Every returned sample is feasible and no closer to the prior than the optimum.
    let problem = req.validate(&robot).unwrap();
    for s in &a.samples {
        assert_eq!(s.status, Status::Optimal);
        assert!(problem.is_feasible(&problem.evaluate(&s.weights)));
        if a.status == Status::Optimal {
            assert!(s.mahalanobis >= a.mahalanobis - 1e-6);
        }
    }
}

#[test]
fn a_cancelled_solve_stops_with_max_iterations_and_a_warning() {
    let (robot, req) = request(7, 10);
    let flag = Arc::new(AtomicBool::new(true));
    let ctl = SolveControl {
        deadline: None,
        cancel: Some(flag),
        sharing: None,
    };
    let resp = optimize_with(&req, &robot, &ctl).unwrap();
    let problem = req.validate(&robot).unwrap();
    let mean_ok = problem.is_feasible(&resp.prior_mean_report);
    if !mean_ok {
        assert_eq!(resp.status, Status::MaxIterations);
        assert_eq!(resp.stop_reason, StopReason::Cancelled);
        assert!(resp.report.warnings.iter().any(|w| w.contains("cancelled")));
    }
    let past = SolveControl {
        deadline: Some(std::time::Instant::now()),
        cancel: None,
        sharing: None,
    };
    let resp = optimize_with(&req, &robot, &past).unwrap();
    if !mean_ok {
        assert_eq!(resp.status, Status::MaxIterations);
        assert_eq!(resp.stop_reason, StopReason::Deadline);
        assert!(resp.report.warnings.iter().any(|w| w.contains("deadline")));
    }
}

#[test]
fn a_local_minimum_from_the_prior_mean_is_escaped_by_a_seeded_restart() {
    // The run from the prior mean ends in a local minimum of the violation
    // (the TCP short of the goal: max_iterations), but the problem is
    // feasible and a seeded restart solves it.
    let (robot, mut req) = needs_restarts();
    req.task.options.restarts = 0;
    let stuck = optimize(&req, &robot).unwrap();
    assert_eq!(stuck.status, Status::MaxIterations);
    assert!(
        matches!(
            stuck.stop_reason,
            StopReason::LocalMinimum | StopReason::IterationLimit
        ),
        "{:?}",
        stuck.stop_reason
    );
    req.task.options.restarts = 4;
    let found = optimize(&req, &robot).unwrap();
    assert_verified_optimal(&req, &robot, &found);
    // The report counts the work of every run and says what happened.
    assert!(found.report.iterations > stuck.report.iterations);
    assert!(found
        .report
        .warnings
        .iter()
        .any(|w| w.contains("restart") && w.contains("local optimum")));
    // The draws are seeded: the same request gives the same bytes.
    let again = optimize(&req, &robot).unwrap();
    assert_eq!(found.deterministic_json(), again.deterministic_json());
    req.task.options.restarts = 33;
    assert_eq!(field_of(&req, &robot), "options.restarts");
}

#[test]
fn a_stalled_infeasible_run_raises_its_penalty_with_a_fresh_trust_region() {
    // Typical problem 2 stalls infeasible at the first penalty (the
    // violation creeps towards a local minimum in ever smaller steps) and
    // is solved after the penalty rises. Counting that creep as a stall,
    // and restarting the trust region after the increase instead of
    // doubling it back from the ~1e-4 it shrank to, took 23 SCP iterations
    // where the old rules took 44 on the former capsule geometry; on the
    // mesh hulls it takes 33. The iteration count is deterministic.
    let (robot, mut req) = request(2, 10);
    req.task.options.restarts = 0;
    let found = optimize(&req, &robot).unwrap();
    assert_verified_optimal(&req, &robot, &found);
    assert!(found.report.iterations <= 36, "{}", found.report.iterations);
    assert!(found.mahalanobis < 6.33, "{}", found.mahalanobis);
}

/// `found` is `optimal`, feasible under the problem's own evaluation, and
/// its report shows the clearance and the goal tolerance held.
fn assert_verified_optimal(req: &OptimizeRequest, robot: &Robot, found: &OptimizeResponse) {
    assert_eq!(found.status, Status::Optimal);
    assert_eq!(found.stop_reason, StopReason::Converged);
    let problem = req.validate(robot).unwrap();
    assert!(problem.is_feasible(&problem.evaluate(&found.weights)));
    let clearance = found.report.min_clearance_m.unwrap();
    assert!(clearance >= req.task.clearance_m - 1e-9, "{clearance}");
    let goal = req.task.goal.as_ref().unwrap();
    assert!(found.report.goal_error_m.unwrap() <= goal.tolerance_m + 1e-9);
}

/// Distance from the TCP to the nearest robot collision shape (rigid with
/// the TCP), measured with a tiny sphere at the TCP.
fn tcp_to_nearest_shape(robot: &Robot) -> f64 {
    let home = robot.home();
    let tcp = robot.tcp_pose(&home).translation.vector;
    let probe = dpmp::scene::Scene::new(vec![sphere("probe", tcp.into(), 1e-9)]).unwrap();
    probe
        .min_clearance(robot, &robot.fk(&home))
        .unwrap()
        .distance
}

#[test]
fn the_buried_goal_certificate_is_sharp_and_holds_for_the_real_gripper() {
    // A sphere centred on the goal: the goal's depth is the radius, and
    // the certificate fires above tolerance + r - clearance.
    let (robot, base) = request(2, 0);
    let goal = base.task.goal.as_ref().unwrap().clone();
    let reach = tcp_to_nearest_shape(&robot).max(0.0);
    let threshold = goal.tolerance_m + reach - base.task.clearance_m;
    let with_sphere = |radius: f64| {
        let mut r = base.clone();
        r.task.obstacles = vec![sphere("over-goal", goal.position, radius)];
        r
    };
    let above = with_sphere(threshold.max(0.0) + 5e-4);
    let problem = above.validate(&robot).unwrap();
    let reason = problem.diagnose().unwrap_or_default();
    assert!(reason.contains("deep inside"), "{reason}");
    // Half a millimetre shallower than the threshold it must stay quiet.
    if threshold > 1e-3 {
        let below = with_sphere(threshold - 5e-4).validate(&robot).unwrap();
        assert!(!below.diagnose().unwrap_or_default().contains("deep inside"));
    }
    // The proof, checked on the robot: every TCP on the tolerance sphere
    // (the least deep points) leaves some robot shape closer than the
    // clearance to the obstacle.
    let scene = dpmp::scene::Scene::new(above.task.obstacles.clone()).unwrap();
    let start = base.task.start.clone().unwrap();
    let options = dpmp::robot::IkOptions {
        tolerance_m: 1e-5,
        ..Default::default()
    };
    let mut checked = 0;
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut position = goal.position;
            position[axis] += sign * goal.tolerance_m;
            let target = dpmp::robot::IkTarget {
                position: position.into(),
                approach_axis: None,
            };
            let Ok(sol) = robot.ik(&target, &start, &options) else {
                continue;
            };
            if sol.position_error_m > 1e-4 {
                continue;
            }
            let closest = scene.min_clearance(&robot, &robot.fk(&sol.q)).unwrap();
            assert!(
                closest.distance < base.task.clearance_m,
                "TCP at {position:?}: clearance {} >= {}",
                closest.distance,
                base.task.clearance_m
            );
            checked += 1;
        }
    }
    assert!(checked >= 3, "only {checked} IK solutions");
}
