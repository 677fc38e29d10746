//! Property tests over random priors, start states and berry clusters on
//! and near the prior mean path: every `optimal` answer satisfies every
//! constraint under dense verification, and the cost is never below the
//! unconstrained optimum (0) nor below the start-only optimum.

use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, PriorSpec, SolveControl, Status};
use dpmp::robot::Robot;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig { cases: 4, ..ProptestConfig::default() })]

    #[test]
    fn optimal_answers_are_feasible_and_never_cheaper_than_relaxations(
        seed in 0u64..10_000,
        n_obstacles in 0usize..4,
        offset in 0.0f64..0.04,
        shift in -0.02f64..0.02,
    ) {
        let robot = Robot::panda().unwrap();
        let settings = ExampleSettings {
            n_obstacles,
            offset_m: (offset, offset + 0.03),
            ..Default::default()
        };
        let mut req = typical_request(&robot, seed, &settings).unwrap();
        // Perturb the prior mean: the start no longer matches it exactly.
        if let PriorSpec::Full { mean, .. } = &mut req.prior {
            for (i, m) in mean.iter_mut().enumerate() {
                *m += shift * ((i % 5) as f64 - 2.0);
            }
        }
        let resp = optimize(&req, &robot).unwrap();
        let problem = req.validate(&robot).unwrap();
        prop_assert!(resp.mahalanobis >= 0.0);
        match resp.status {
            Status::Optimal => {
                let report = problem.evaluate(&resp.weights);
                prop_assert!(problem.is_feasible(&report), "{:?}", report);
                prop_assert!(problem.is_feasible(&resp.report));
                // Relaxation: only the start equality (and the limits).
                let mut relaxed = req.clone();
                relaxed.task.obstacles.clear();
                relaxed.task.goal = None;
                let rp = relaxed.validate(&robot).unwrap();
                let r = rp.solve(&SolveControl::default()).unwrap();
                if r.status == Status::Optimal {
                    prop_assert!(resp.mahalanobis >= r.mahalanobis - 1e-6,
                        "{} < relaxed {}", resp.mahalanobis, r.mahalanobis);
                }
            }
            Status::Infeasible | Status::MaxIterations => {
                prop_assert!(resp.reason.is_some());
            }
        }
    }

    #[test]
    fn a_wall_through_the_whole_workspace_is_reported_infeasible(seed in 0u64..1000) {
        let robot = Robot::panda().unwrap();
        let settings = ExampleSettings { n_obstacles: 0, ..Default::default() };
        let mut req = typical_request(&robot, seed, &settings).unwrap();
        req.task.options.max_iterations = 6;
        // A box between the start TCP and the goal that the arm cannot pass:
        // the goal lies beyond a wall spanning the whole reachable space.
        let goal = req.task.goal.as_ref().unwrap().position;
        req.task.obstacles.push(dpmp::scene::Obstacle {
            id: "wall".into(),
            shape: dpmp::scene::ObstacleShape::Box(dpmp::geometry::OrientedBox {
                center: [goal[0] - 0.08, 0.0, 0.5],
                half_extents: [0.01, 2.0, 2.0],
                rotation: [0.0, 0.0, 0.0, 1.0],
            }),
        });
        let resp = optimize(&req, &robot).unwrap();
        prop_assert_ne!(resp.status, Status::Optimal);
        prop_assert!(resp.reason.is_some());
    }
}
