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

/// The request's obstacles as a sensed cloud: 60 points on a 12 mm shell
/// around each one's centre (with balls of 4 mm, the berries' surfaces).
fn sensed(request: &dpmp::optim::OptimizeRequest, seed: u64) -> Vec<[f64; 3]> {
    let centres: Vec<[f64; 3]> = request
        .task
        .obstacles
        .iter()
        .map(|o| o.shape.center())
        .collect();
    shells(&centres, 0.012, 60, seed)
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
        let points = sensed(&request, seed);
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

/// `points` as the compact form's bytes, base64.
fn compact(points: &[[f32; 3]]) -> String {
    use base64::Engine as _;
    let bytes: Vec<u8> = points
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

#[test]
fn the_compact_form_is_the_same_cloud_and_its_mistakes_are_named() {
    let cloud_f32: Vec<[f32; 3]> = (0..50)
        .map(|i| [0.4 + 0.01 * i as f32, -0.1, 0.3 + 0.002 * i as f32])
        .collect();
    let text = format!(
        r#"{{"id": "s", "type": "points", "points_base64": "{}", "radius": 0.005}}"#,
        compact(&cloud_f32)
    );
    let parsed: Obstacle = serde_json::from_str(&text).unwrap();
    let expected: Vec<[f64; 3]> = cloud_f32
        .iter()
        .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
        .collect();
    assert_eq!(
        parsed.shape,
        ObstacleShape::Points {
            points: expected,
            radius: 0.005
        }
    );
    let refused = |body: String| {
        serde_json::from_str::<Obstacle>(&body)
            .unwrap_err()
            .to_string()
    };
    let e = refused(
        r#"{"id": "s", "type": "points", "points_base64": "AAAA", "radius": 0.005}"#.into(),
    );
    assert!(e.contains("12-byte points") && e.contains("\"s\""), "{e}");
    let e =
        refused(r#"{"id": "s", "type": "points", "points_base64": "*!", "radius": 0.005}"#.into());
    assert!(e.contains("not base64"), "{e}");
    let e = refused(format!(
        r#"{{"id": "s", "type": "points", "points": [[0,0,0]], "points_base64": "{}", "radius": 0.005}}"#,
        compact(&cloud_f32)
    ));
    assert!(e.contains("not both"), "{e}");
    let e = refused(
        r#"{"id": "s", "type": "sphere", "points_base64": "", "center": [0,0,0], "radius": 0.005}"#
            .into(),
    );
    assert!(e.contains("only to type"), "{e}");
    // A non-finite coordinate in the bytes is named with its point.
    let e = refused(format!(
        r#"{{"id": "s", "type": "points", "points_base64": "{}", "radius": 0.005}}"#,
        compact(&[[0.1, 0.2, 0.3], [0.1, f32::NAN, 0.3]])
    ));
    assert!(e.contains("point 1 has a non-finite coordinate"), "{e}");
}

#[test]
fn the_service_takes_a_compact_cloud_and_caps_the_points_per_request() {
    use crate::common::http::{client, field, post_json, start, test_config};
    let server = start(test_config());
    let robot = Robot::panda().unwrap();
    let request = typical_request(&robot, 1, &ExampleSettings::default()).unwrap();
    let mut body = serde_json::to_value(&request).unwrap();
    let points: Vec<[f32; 3]> = sensed(&request, 1)
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect();
    body["obstacles"] = serde_json::json!([{
        "id": "sensed", "type": "points", "points_base64": compact(&points), "radius": 0.004
    }]);
    let (status, answer) = post_json(&client(), &server.url("/v1/optimize"), body.to_string());
    assert_eq!(status, 200, "{answer}");
    assert!(answer["report"]["min_clearance_m"].is_number(), "{answer}");
    // Three clouds of 70,000 points: over the 200,000 a request may hold.
    let big = compact(&vec![[0.5f32, 0.5, 0.5]; 70_000]);
    body["obstacles"] = (0..3)
        .map(|i| serde_json::json!({"id": format!("c{i}"), "type": "points", "points_base64": big, "radius": 0.004}))
        .collect();
    let (status, answer) = post_json(&client(), &server.url("/v1/optimize"), body.to_string());
    assert_eq!(
        (status, field(&answer)),
        (422, Some("obstacles")),
        "{answer}"
    );
}
