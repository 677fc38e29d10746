//! The sensed world: what a depth frame costs and how a cloud's size moves
//! the solve.
//!
//! - `world/depth_to_cloud`: a generated 640 x 480 depth frame (the plant,
//!   depth noise on) back-projected, range-cut, voxel-downsampled and
//!   indexed (the `points` obstacle's box tree), as `/v1/plan` does with
//!   `world: "depth"`.
//! - `world/solve/*`: typical problems (seeds 0-3) solved with their scene
//!   as primitives, then with the same surfaces as clouds of 1k, 10k and
//!   100k points, and with the 10k cloud plus 10x as many points far from
//!   the robot (a wall 1.5 m behind it). The cost must follow the points
//!   near the robot, not the cloud's size.
//!
//! `cargo bench --bench world` (`-- depth_to_cloud`, `-- solve`).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize, OptimizeRequest};
use dpmp::perception::cloud::{depth_cloud, CloudSettings};
use dpmp::perception::Camera;
use dpmp::robot::Robot;
use dpmp::scene::{Obstacle, ObstacleShape, Scene};
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;

fn depth_to_cloud(c: &mut Criterion) {
    let robot = Robot::panda().expect("the shipped Panda loads");
    let generator = Generator::new(SynthSettings::new(1, 1), robot.clone()).expect("generator");
    let out = generator.config(21, 0).expect("plant");
    let depth = out.depths[0].clone().expect("depth on by default");
    let camera = Camera::at_home(&generator.settings().camera.model, &robot).expect("camera");
    let settings = CloudSettings::default();
    // The same frame with every pixel returning: the background filled
    // in at 0.9 m (a hedge row behind the plant).
    let metres: Vec<f64> = (0..depth.height())
        .flat_map(|y| (0..depth.width()).map(move |x| (x, y)))
        .map(|(x, y)| depth.metres(x, y).unwrap_or(0.9))
        .collect();
    let full = dpmp::perception::DepthImage::from_metres(
        depth.width(),
        depth.height(),
        depth.scale_m(),
        &metres,
    )
    .expect("full frame");
    for (name, frame) in [("plant", &depth), ("full_frame", &full)] {
        let cloud = depth_cloud(frame, &camera, &settings, None);
        eprintln!(
            "depth_to_cloud/{name}: {}x{} frame, {} returns, {} points",
            frame.width(),
            frame.height(),
            cloud.returns,
            cloud.points.len()
        );
        c.bench_function(&format!("world/depth_to_cloud_640x480_{name}"), |b| {
            b.iter(|| {
                let cloud = depth_cloud(black_box(frame), &camera, &settings, None);
                Scene::new(vec![points_obstacle("sensed", cloud.points, 0.006)])
                    .expect("valid cloud")
            })
        });
    }
}

fn points_obstacle(id: &str, points: Vec<[f64; 3]>, radius: f64) -> Obstacle {
    Obstacle {
        id: id.into(),
        shape: ObstacleShape::Points { points, radius },
    }
}

/// Radius of each cloud point's ball (m); the clouds' surfaces are the
/// primitives' inflated by nothing more.
const POINT_RADIUS_M: f64 = 0.003;

/// `n` points spread over the surfaces of `obstacles` (spheres and
/// capsules), shrunk by the points' radius so the balls' union hugs the
/// primitives.
fn surface_cloud(obstacles: &[Obstacle], n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let per = n.div_ceil(obstacles.len().max(1));
    let mut out = Vec::with_capacity(per * obstacles.len());
    for o in obstacles {
        for _ in 0..per {
            let u = unit(&mut rng);
            let p = match &o.shape {
                ObstacleShape::Sphere(s) => {
                    Vector3::from(s.center) + u * (s.radius - POINT_RADIUS_M)
                }
                ObstacleShape::Capsule(cap) => {
                    let (a, b) = (Vector3::from(cap.a), Vector3::from(cap.b));
                    a + (b - a) * rng.gen_range(0.0..1.0)
                        + u * (cap.radius - POINT_RADIUS_M).max(0.0)
                }
                _ => continue,
            };
            out.push([p.x, p.y, p.z]);
        }
    }
    out.truncate(n);
    out
}

fn unit(rng: &mut impl Rng) -> Vector3<f64> {
    let z: f64 = rng.gen_range(-1.0..1.0);
    let phi = rng.gen_range(0.0..2.0 * PI);
    let r = (1.0 - z * z).sqrt();
    Vector3::new(r * phi.cos(), r * phi.sin(), z)
}

/// `n` points on a 2 x 2 m wall 1.5 m behind the robot's base.
fn far_wall(n: usize) -> Vec<[f64; 3]> {
    let side = (n as f64).sqrt().ceil() as usize;
    (0..n)
        .map(|i| {
            let (u, v) = (
                (i % side) as f64 / side as f64,
                (i / side) as f64 / side as f64,
            );
            [-1.5, -1.0 + 2.0 * u, 2.0 * v]
        })
        .collect()
}

fn solve(c: &mut Criterion) {
    let robot = Robot::panda().expect("the shipped Panda loads");
    let base: Vec<OptimizeRequest> = (0..4)
        .map(|seed| typical_request(&robot, seed, &ExampleSettings::default()).expect("typical"))
        .collect();
    let with = |make: &dyn Fn(&[Obstacle], u64) -> Vec<Obstacle>| -> Vec<OptimizeRequest> {
        base.iter()
            .enumerate()
            .map(|(i, r)| {
                let mut r = r.clone();
                r.task.obstacles = make(&r.task.obstacles, i as u64);
                r
            })
            .collect()
    };
    let cloud_of = |n: usize, far: usize| {
        move |obstacles: &[Obstacle], seed: u64| {
            let mut cloud = vec![points_obstacle(
                "cloud",
                surface_cloud(obstacles, n, seed),
                POINT_RADIUS_M,
            )];
            if far > 0 {
                cloud.push(points_obstacle("far-wall", far_wall(far), POINT_RADIUS_M));
            }
            cloud
        }
    };
    let cases: Vec<(&str, Vec<OptimizeRequest>)> = vec![
        ("primitives", base.clone()),
        ("cloud_1k", with(&cloud_of(1_000, 0))),
        ("cloud_10k", with(&cloud_of(10_000, 0))),
        ("cloud_100k", with(&cloud_of(100_000, 0))),
        ("cloud_10k_plus_100k_far", with(&cloud_of(10_000, 100_000))),
    ];
    let mut group = c.benchmark_group("world/solve");
    group.sample_size(10);
    for (name, requests) in &cases {
        let statuses: Vec<String> = requests
            .iter()
            .map(|r| format!("{:?}", optimize(r, &robot).expect("solves").status))
            .collect();
        eprintln!("solve/{name}: {statuses:?}");
        group.bench_function(*name, |b| {
            b.iter(|| {
                for r in requests {
                    black_box(optimize(r, &robot).expect("solves"));
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, depth_to_cloud, solve);
criterion_main!(benches);
