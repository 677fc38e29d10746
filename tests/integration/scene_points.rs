//! The `points` obstacle: a point cloud whose clearance is the closest
//! point's ball, found through a box tree. Checked against independent
//! references: the same balls posted as separate sphere obstacles (a scan,
//! no tree), and each robot hull's own point distance; the optimiser's
//! `optimal` answer against the balls as spheres; and the validation.

use crate::common::scene::{obstacle, sphere};
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, Status};
use dpmp::robot::{Robot, ShapeGeometry};
use dpmp::scene::{Obstacle, ObstacleShape, Scene};
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};

/// `n` points on spheres of radius `shell` around `centres`.
fn shells(centres: &[[f64; 3]], shell: f64, n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    centres
        .iter()
        .flat_map(|c| {
            let c = Vector3::from(*c);
            (0..n)
                .map(|_| {
                    let d = dpmp::geometry::random_unit(&mut rng);
                    (c + d * shell).into()
                })
                .collect::<Vec<[f64; 3]>>()
        })
        .collect()
}

fn cloud(id: &str, points: Vec<[f64; 3]>, radius: f64) -> Obstacle {
    obstacle(id, ObstacleShape::Points { points, radius })
}

/// The same balls as one sphere obstacle each.
fn as_spheres(points: &[[f64; 3]], radius: f64) -> Vec<Obstacle> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| sphere(&format!("p{i}"), *p, radius))
        .collect()
}

fn random_q(robot: &Robot, rng: &mut impl Rng) -> Vec<f64> {
    robot
        .limits()
        .iter()
        .map(|l| rng.gen_range(l.lower..l.upper))
        .collect()
}

#[test]
fn a_cloud_is_as_close_as_its_nearest_ball_posted_alone() {
    let robot = Robot::panda().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    for seed in 0..6u64 {
        // Points scattered through the workspace in front of the robot.
        let centres: Vec<[f64; 3]> = (0..12)
            .map(|_| {
                [
                    rng.gen_range(0.2..0.8),
                    rng.gen_range(-0.4..0.4),
                    rng.gen_range(0.1..0.9),
                ]
            })
            .collect();
        let points = shells(&centres, 0.03, 40, seed);
        let radius = 0.004 + 0.002 * seed as f64;
        let one = Scene::new(vec![cloud("sensed", points.clone(), radius)]).unwrap();
        let many = Scene::new(as_spheres(&points, radius)).unwrap();
        for _ in 0..25 {
            let q = random_q(&robot, &mut rng);
            let frames = robot.fk(&q);
            let a = one.min_clearance(&robot, &frames).unwrap();
            let b = many.min_clearance(&robot, &frames).unwrap();
            assert!(
                (a.distance - b.distance).abs() < 1e-12,
                "seed {seed}: cloud {} vs balls {}",
                a.distance,
                b.distance
            );
            assert_eq!(a.shape, b.shape);
            // Within an activation distance: per robot shape, the cloud's
            // pair is the closest of the balls' pairs.
            let near_one = one.clearances_within(&robot, &frames, 0.05);
            let near_many = many.clearances_within(&robot, &frames, 0.05);
            for c in &near_one {
                let best = near_many
                    .iter()
                    .filter(|m| m.shape == c.shape)
                    .map(|m| m.distance)
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    (c.distance - best).abs() < 1e-12,
                    "{} vs {best}",
                    c.distance
                );
            }
            let shapes = |v: &[dpmp::scene::Clearance]| {
                let mut s: Vec<usize> = v.iter().map(|c| c.shape).collect();
                s.dedup();
                s
            };
            assert_eq!(shapes(&near_one), shapes(&near_many));
        }
    }
}

#[test]
fn no_link_mesh_is_closer_to_a_point_than_the_cloud_says() {
    let robot = Robot::panda().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let points: Vec<[f64; 3]> = (0..400)
        .map(|_| {
            [
                rng.gen_range(0.1..0.8),
                rng.gen_range(-0.5..0.5),
                rng.gen_range(0.0..1.0),
            ]
        })
        .collect();
    let radius = 0.005;
    let scene = Scene::new(vec![cloud("sensed", points.clone(), radius)]).unwrap();
    for _ in 0..4 {
        let q = random_q(&robot, &mut rng);
        let frames = robot.fk(&q);
        let reported = scene.min_clearance(&robot, &frames).unwrap().distance;
        // The independent reference: every point against every published
        // link mesh (exact f64 point-triangle distances, link frame).
        for s in robot.collision_shapes() {
            let ShapeGeometry::Convex(hull) = &s.geometry else {
                continue;
            };
            let Some(mesh) = hull.source() else {
                continue;
            };
            let inverse = frames.poses[s.link].inverse();
            for p in &points {
                let local = inverse * Point3::from(*p);
                let d = mesh.distance_to_point(&local.coords.into()) - radius;
                assert!(
                    reported <= d + 1e-9,
                    "reported {reported} > {d} to a point of link {}",
                    s.link
                );
            }
        }
    }
}

#[test]
fn an_optimal_answer_clears_the_cloud_posted_as_spheres() {
    let robot = Robot::panda().unwrap();
    let mut solved = 0;
    for seed in [1u64, 4, 6] {
        let mut request = typical_request(&robot, seed, &ExampleSettings::default()).unwrap();
        // Each berry and stem becomes the cloud of its surface (points 4 mm
        // inside it, balls of 4 mm): the sensed version of the same scene.
        let centres: Vec<[f64; 3]> = request
            .task
            .obstacles
            .iter()
            .map(|o| o.shape.center())
            .collect();
        let points = shells(&centres, 0.012, 60, seed);
        request.task.obstacles = vec![cloud("sensed", points.clone(), 0.004)];
        let answer = optimize(&request, &robot).unwrap();
        if answer.status != Status::Optimal {
            continue;
        }
        solved += 1;
        // Verified again against the balls as separate spheres.
        let mut spheres = request.clone();
        spheres.task.obstacles = as_spheres(&points, 0.004);
        let problem = spheres.validate(&robot).unwrap();
        let report = problem.evaluate(&answer.weights);
        assert!(problem.is_feasible(&report), "seed {seed}: {report:?}");
        let clearance = report.continuous_clearance_m.unwrap();
        assert!(
            clearance >= request.task.clearance_m - 1e-6,
            "seed {seed}: {clearance}"
        );
    }
    assert!(solved >= 2, "{solved} of 3 solved");
}

#[test]
fn a_cloud_is_validated_naming_the_field() {
    let check = |shape: ObstacleShape| match Scene::new(vec![obstacle("c", shape)]) {
        Err(dpmp::Error::Invalid { field, .. }) => field,
        other => panic!("expected a refusal, got {other:?}"),
    };
    let points = |points: Vec<[f64; 3]>, radius: f64| ObstacleShape::Points { points, radius };
    assert_eq!(check(points(vec![], 0.01)), "obstacles[0].points");
    assert_eq!(
        check(points(vec![[0.0; 3], [0.1, f64::NAN, 0.0]], 0.01)),
        "obstacles[0].points[1][1]"
    );
    assert_eq!(check(points(vec![[0.0; 3]], 0.0)), "obstacles[0].radius");
    let too_many = vec![[0.0; 3]; dpmp::scene::obstacle::MAX_CLOUD_POINTS + 1];
    assert_eq!(check(points(too_many, 0.01)), "obstacles[0].points");
    // The JSON form, and an unknown field refused.
    let parsed: Obstacle = serde_json::from_str(
        r#"{"id": "s", "type": "points", "points": [[0.5, 0, 0.5]], "radius": 0.005}"#,
    )
    .unwrap();
    assert_eq!(parsed.shape, points(vec![[0.5, 0.0, 0.5]], 0.005));
    let e = serde_json::from_str::<Obstacle>(
        r#"{"id": "s", "type": "points", "points": [[0.5, 0, 0.5]], "radius": 0.005, "r": 1}"#,
    )
    .unwrap_err();
    assert!(e.to_string().contains("unknown field"), "{e}");
}
