//! Minimum clearance of the whole Panda against a 20-berry cluster, with
//! its gradient, on the shipped mesh model (convex hulls of Franka's
//! collision meshes) and, in the same run, on the former capsule model
//! (`benches/fixtures/panda_capsules.urdf`, not conservative) for the ratio.
//! Then the hull-versus-segment query alone: the local certified walk
//! against the full face scan on the same queries.
//!
//! Last, a sensed point cloud as one `points` obstacle (its box tree)
//! against the same balls as separate spheres.
//!
//! `cargo bench --bench clearance` (`-- hull_query` for the query alone,
//! `-- cloud` for the point cloud).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use dpmp::robot::{Robot, PANDA_HOME};
use dpmp::scene::{BerryShape, Obstacle, ObstacleShape, Scene};
use nalgebra::Point3;

/// 20 berries with stems in a 12 x 10 x 16 cm cluster centred `ahead` m in
/// front of the gripper at home, i.e. around the hand at the approach.
fn berry_cluster(robot: &Robot, ahead: f64) -> Vec<Obstacle> {
    let tcp = robot.tcp_pose(&PANDA_HOME);
    (0..20)
        .map(|i| {
            let t = i as f64;
            let local = Point3::new(
                0.05 * (t * 1.3).sin(),
                -0.06 + 0.006 * t,
                ahead + 0.04 * (t * 0.7).cos(),
            );
            let c = tcp * local;
            Obstacle {
                id: format!("berry-{i}"),
                shape: ObstacleShape::Berry(BerryShape {
                    center: [c.x, c.y, c.z],
                    radius: 0.012 + 0.001 * (i % 4) as f64,
                    elongation: 0.004,
                    stem_top: [c.x, c.y, c.z + 0.07],
                    stem_radius: 0.002,
                }),
            }
        })
        .collect()
}

const CAPSULE_URDF: &str = include_str!("fixtures/panda_capsules.urdf");

fn clearance(c: &mut Criterion) {
    let meshes = Robot::panda().expect("the shipped Panda loads");
    let capsules = Robot::from_urdf_str(CAPSULE_URDF, "panda_link0", "panda_tcp")
        .and_then(|r| r.with_home(&PANDA_HOME))
        .expect("the capsule fixture loads");
    for (model, robot) in [("mesh", &meshes), ("capsules", &capsules)] {
        for (name, ahead) in [("near", 0.12), ("far", 0.5)] {
            let scene = Scene::new(berry_cluster(robot, ahead)).expect("valid cluster");
            c.bench_function(
                &format!("{model}/min_clearance_gradient_20_berries_{name}"),
                |b| b.iter(|| scene.min_clearance_with_gradient(robot, black_box(&PANDA_HOME))),
            );
            let frames = robot.fk(&PANDA_HOME);
            c.bench_function(
                &format!("{model}/clearances_within_5cm_20_berries_{name}"),
                |b| b.iter(|| scene.clearances_within(robot, black_box(&frames), 0.05)),
            );
        }
    }
}

/// One hull query per (Panda hull, random segment near it): the local
/// certified walk against the full scan of every face, same queries, same
/// run. Limit 4 cm (a 2 cm clearance plus a berry radius).
fn hull_query(c: &mut Criterion) {
    use dpmp::robot::ShapeGeometry;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    let robot = Robot::panda().expect("the shipped Panda loads");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut queries = Vec::new();
    for s in robot.collision_shapes() {
        let ShapeGeometry::Convex(hull) = &s.geometry else {
            continue;
        };
        let (ca, cb, r) = hull.bound();
        let (ca, cb) = (Vector3::from(ca), Vector3::from(cb));
        for _ in 0..200 {
            let around = ca + (cb - ca) * rng.gen_range(0.0..1.0);
            let a = around + Vector3::from_fn(|_, _| rng.gen_range(-(r + 0.05)..r + 0.05));
            let b = a + Vector3::from_fn(|_, _| rng.gen_range(-0.04..0.04));
            queries.push((hull.clone(), a, b));
        }
    }
    let limit = 0.04;
    c.bench_function("hull_query/local_certified", |b| {
        b.iter(|| {
            for (hull, a, bb) in &queries {
                black_box(hull.segment_contact_within(a, bb, black_box(limit)));
            }
        })
    });
    c.bench_function("hull_query/full_scan", |b| {
        b.iter(|| {
            for (hull, a, bb) in &queries {
                black_box(hull.segment_contact_scan(a, bb, black_box(limit)));
            }
        })
    });
}

/// A sensed cloud: `n` points on a 30 x 30 cm leaf wall `ahead` m in front
/// of the gripper at home, as one `points` obstacle (the box tree) and, in
/// the same run, as `n` separate spheres (a scan over every one).
fn cloud_points(robot: &Robot, n: usize, ahead: f64) -> Vec<[f64; 3]> {
    let tcp = robot.tcp_pose(&PANDA_HOME);
    let side = (n as f64).sqrt().ceil() as usize;
    (0..n)
        .map(|i| {
            let (u, v) = ((i % side) as f64, (i / side) as f64);
            let local = Point3::new(
                -0.15 + 0.3 * u / side as f64,
                -0.15 + 0.3 * v / side as f64,
                ahead + 0.01 * (u * 0.9).sin() * (v * 0.7).cos(),
            );
            let p = tcp * local;
            [p.x, p.y, p.z]
        })
        .collect()
}

fn cloud(c: &mut Criterion) {
    let robot = Robot::panda().expect("the shipped Panda loads");
    let frames = robot.fk(&PANDA_HOME);
    for n in [1_000, 10_000] {
        let points = cloud_points(&robot, n, 0.06);
        let tree = Scene::new(vec![Obstacle {
            id: "sensed".into(),
            shape: ObstacleShape::Points {
                points: points.clone(),
                radius: 0.005,
            },
        }])
        .expect("valid cloud");
        let spheres = Scene::new(
            points
                .iter()
                .enumerate()
                .map(|(i, p)| Obstacle {
                    id: format!("p{i}"),
                    shape: ObstacleShape::Sphere(dpmp::geometry::Sphere {
                        center: *p,
                        radius: 0.005,
                    }),
                })
                .collect(),
        )
        .expect("valid spheres");
        for (name, scene) in [("tree", &tree), ("spheres", &spheres)] {
            c.bench_function(&format!("cloud/clearances_within_5cm_{n}_{name}"), |b| {
                b.iter(|| scene.clearances_within(&robot, black_box(&frames), 0.05))
            });
        }
    }
}

criterion_group!(benches, clearance, hull_query, cloud);
criterion_main!(benches);
