//! The committed `problems/` suite: enough files, every category, valid
//! requests, and infeasible-by-construction files that really are.

use dpmp::bench::{load_dir, CATEGORIES};
use dpmp::optim::OptimizeRequest;
use dpmp::robot::Robot;
use dpmp::scene::Scene;
use nalgebra::Point3;
use std::path::Path;

#[test]
fn committed_suite_covers_every_category_with_valid_requests() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("problems");
    if !dir.exists() {
        eprintln!(
            "skipping: {} does not exist (run `dpmp bench make-problems`)",
            dir.display()
        );
        return;
    }
    let problems = load_dir(&dir).unwrap();
    assert!(problems.len() >= 60, "{} problems", problems.len());
    let robot = Robot::panda().unwrap();
    let mut per_category = std::collections::BTreeMap::new();
    for (name, p) in &problems {
        let p = p.as_ref().unwrap_or_else(|e| panic!("{name}: {e}"));
        *per_category.entry(p.meta.category.clone()).or_insert(0) += 1;
        assert_eq!(
            p.expect.feasible,
            Some(p.meta.category != "infeasible"),
            "{name}"
        );
        let request: OptimizeRequest = serde_json::from_value(p.request.clone()).unwrap();
        request
            .validate(&robot)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        if p.meta.category == "infeasible" {
            let scene = Scene::new(request.task.obstacles.clone()).unwrap();
            let start = request.task.start.clone().unwrap();
            let start_clear = scene
                .min_clearance(&robot, &robot.fk(&start))
                .unwrap()
                .distance;
            let g = request.task.goal.clone().unwrap().position;
            let goal_blocked = scene
                .obstacle_containing(&Point3::new(g[0], g[1], g[2]), 0.0)
                .is_some();
            assert!(
                start_clear < request.task.clearance_m || goal_blocked,
                "{name} is not infeasible by construction"
            );
        }
    }
    for c in CATEGORIES {
        assert!(
            per_category.get(c).copied().unwrap_or(0) >= 5,
            "category {c}: {per_category:?}"
        );
    }
}

/// Generation from the synthetic generator is deterministic in the seed,
/// marks its provenance, and its claims hold on the written request: the
/// on-path berry blocks the prior mean, and an infeasible problem's goal
/// lies inside an obstacle; unknown categories are refused.
#[test]
fn generated_problems_are_deterministic_and_their_constructions_bind() {
    use dpmp::bench::make_problems::{generator, make_one, GENERATOR};
    let robot = Robot::panda().unwrap();
    let g = generator(&robot).unwrap();
    let a = make_one(&g, "on-path", 0, 77).unwrap();
    let b = make_one(&g, "on-path", 0, 77).unwrap();
    assert_eq!(a.to_json().unwrap(), b.to_json().unwrap());
    assert_eq!(a.meta.generator, GENERATOR);
    assert_eq!((a.meta.seed, a.meta.category.as_str()), (77, "on-path"));
    assert_eq!(a.expect.feasible, Some(true));
    let request: OptimizeRequest = serde_json::from_value(a.request.clone()).unwrap();
    let problem = request.validate(&robot).unwrap();
    let mean: Vec<f64> = match &request.prior {
        dpmp::optim::PriorSpec::Full { mean, .. } => mean.clone(),
        other => panic!("unexpected prior {other:?}"),
    };
    let report = problem.evaluate(&mean);
    assert!(report.min_clearance_m.unwrap() < request.task.clearance_m);

    let inf = make_one(&g, "infeasible", 1, 78).unwrap();
    assert_eq!(inf.expect.feasible, Some(false));
    let request: OptimizeRequest = serde_json::from_value(inf.request.clone()).unwrap();
    let g_pos = request.task.goal.clone().unwrap().position;
    let scene = Scene::new(request.task.obstacles.clone()).unwrap();
    assert!(scene
        .obstacle_containing(&Point3::new(g_pos[0], g_pos[1], g_pos[2]), 0.0)
        .is_some());
    assert!(make_one(&g, "hard", 0, 1).is_err());
}
