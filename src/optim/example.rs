//! Generated typical problems: a real-like prior (the
//! [`crate::promp::example`] demonstrations), a berry cluster of spheres
//! and stems placed on and near the prior mean's TCP path, the prior's
//! start configuration, and a goal at the mean's final TCP position. Used
//! by the benchmarks, the property tests and the CLI examples.

use super::request::{Boundary, Goal, OptimizeRequest, PriorSpec, SolverOptions};
use crate::promp::example::example_distribution;
use crate::promp::{Basis, PrompConfig, WeightDistribution};
use crate::robot::Robot;
use crate::scene::{Obstacle, ObstacleShape, Scene};
use crate::Result;
use nalgebra::{DMatrix, Vector3};
use rand::{Rng, SeedableRng};

/// Settings of [`typical_request`].
#[derive(Clone, Debug)]
pub struct ExampleSettings {
    /// Obstacles in the cluster (spheres, every third one a stem capsule).
    pub n_obstacles: usize,
    /// Demonstrations behind the prior.
    pub n_demos: usize,
    /// Required clearance (m).
    pub clearance_m: f64,
    /// Obstacle surfaces keep at least this distance from the goal (m).
    pub goal_keep_out_m: f64,
    /// Lateral offset range of obstacle centres from the mean TCP path (m).
    pub offset_m: (f64, f64),
    /// Add a goal constraint.
    pub with_goal: bool,
    /// Add a start constraint (the prior mean's start plus small noise).
    pub with_start: bool,
    /// Velocity and acceleration at the ends (the request default: rest).
    pub boundary: Boundary,
}

impl Default for ExampleSettings {
    fn default() -> Self {
        ExampleSettings {
            n_obstacles: 10,
            n_demos: 12,
            clearance_m: 0.02,
            goal_keep_out_m: 0.06,
            offset_m: (0.02, 0.08),
            with_goal: true,
            with_start: true,
            boundary: Boundary::Rest,
        }
    }
}

/// The prior as a full-covariance request field.
pub fn prior_spec(dist: &WeightDistribution) -> PriorSpec {
    PriorSpec::from(dist)
}

/// A typical optimise request, deterministic in `seed`.
pub fn typical_request(
    robot: &Robot,
    seed: u64,
    settings: &ExampleSettings,
) -> Result<OptimizeRequest> {
    let config = PrompConfig::default();
    let basis = Basis::new(&config)?;
    let dist = example_distribution(&basis, settings.n_demos, seed)?;
    let mean = dist.trajectory_mean(&basis);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_0b57);
    let tcp = tcp_path(robot, &mean);
    let goal = tcp[tcp.len() - 1] + random_unit(&mut rng) * rng.gen_range(0.0..0.005);
    let start_tcp = tcp[0];
    let row = |t: usize| -> Vec<f64> { mean.row(t).iter().cloned().collect() };
    let (q_start, q_final) = (row(0), row(mean.nrows() - 1));
    let mut obstacles = Vec::new();
    let mut attempts = 0;
    while obstacles.len() < settings.n_obstacles && attempts < 1000 {
        attempts += 1;
        let k = rng.gen_range((tcp.len() / 5)..(tcp.len() * 7 / 10));
        let centre = tcp[k]
            + random_unit(&mut rng) * rng.gen_range(settings.offset_m.0..settings.offset_m.1);
        let radius = rng.gen_range(0.01..0.02);
        let stem = obstacles.len() % 3 == 2;
        let top = centre + Vector3::new(0.0, 0.0, rng.gen_range(0.04..0.08));
        let near_goal = if stem {
            segment_distance(&goal, &centre, &top)
        } else {
            (centre - goal).norm()
        };
        if near_goal - radius < settings.goal_keep_out_m
            || (centre - start_tcp).norm() - radius < 0.15
        {
            continue;
        }
        let index = obstacles.len();
        let candidate = if stem {
            Obstacle {
                id: format!("stem-{index}"),
                shape: ObstacleShape::Capsule {
                    a: centre.into(),
                    b: top.into(),
                    radius: 0.004,
                },
            }
        } else {
            Obstacle {
                id: format!("berry-{index}"),
                shape: ObstacleShape::Sphere {
                    center: centre.into(),
                    radius,
                },
            }
        };
        // The arm at the prior mean's start and final poses stays clear, so
        // the cluster blocks the way, not the target.
        let alone = Scene::new(vec![candidate.clone()])?;
        let ends_clear = [&q_start, &q_final].iter().all(|q| {
            alone
                .min_clearance(robot, &robot.fk(q))
                .is_none_or(|c| c.distance > settings.clearance_m)
        });
        if ends_clear {
            obstacles.push(candidate);
        }
    }
    let start = settings.with_start.then(|| {
        (0..mean.ncols())
            .map(|j| mean[(0, j)] + rng.gen_range(-0.003..0.003))
            .collect()
    });
    Ok(OptimizeRequest {
        prior: prior_spec(&dist),
        promp: config,
        duration_s: 4.0,
        start,
        goal: settings.with_goal.then_some(Goal::at(goal.into(), 0.01)),
        obstacles,
        clearance_m: settings.clearance_m,
        joint_limit_margin_rad: 0.0,
        samples: 0,
        options: SolverOptions::default(),
        trajectory_format: Default::default(),
        boundary: settings.boundary,
        acceleration_limits: None,
        jerk_limits: None,
        velocity_scaling: 1.0,
        acceleration_scaling: 1.0,
    })
}

/// TCP positions along a `T x dof` trajectory.
pub fn tcp_path(robot: &Robot, q: &DMatrix<f64>) -> Vec<Vector3<f64>> {
    (0..q.nrows())
        .map(|t| {
            let row: Vec<f64> = q.row(t).iter().cloned().collect();
            robot.tcp_pose(&row).translation.vector
        })
        .collect()
}

/// A uniformly random unit vector (rejection sampling in the unit ball).
pub fn random_unit(rng: &mut impl Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

fn segment_distance(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-300)).clamp(0.0, 1.0);
    (p - (a + ab * t)).norm()
}
