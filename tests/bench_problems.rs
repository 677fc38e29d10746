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
        assert_eq!(p.expect.feasible, p.meta.category != "infeasible", "{name}");
        let request: OptimizeRequest = serde_json::from_value(p.request.clone()).unwrap();
        request
            .validate(&robot)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        if p.meta.category == "infeasible" {
            let scene = Scene::new(request.obstacles.clone()).unwrap();
            let start = request.start.clone().unwrap();
            let start_clear = scene
                .min_clearance(&robot, &robot.fk(&start))
                .unwrap()
                .distance;
            let g = request.goal.clone().unwrap().position;
            let goal_blocked = scene
                .obstacle_containing(&Point3::new(g[0], g[1], g[2]), 0.0)
                .is_some();
            assert!(
                start_clear < request.clearance_m || goal_blocked,
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
