//! The seeded problem generator behind `dpmp bench make-problems`.
//!
//! Every problem uses a real-like prior (the [`crate::promp::example`]
//! demonstrations from home towards a berry, fitted per demonstration and
//! turned into a full Gaussian over the 7 x 8 weights), starts at the prior
//! mean's start configuration and asks for the TCP to end at the prior
//! mean's final TCP position (so the un-optimised mean satisfies the start
//! and the goal, and every difficulty comes from the category). Berries are
//! spheres or [`ObstacleShape::Berry`] bodies with stems, stems capsules,
//! placed relative to the prior mean's TCP path (computed with the Panda's
//! FK). Category by category:
//!
//! - `easy`: a cluster 0.25-0.4 m away from the whole arm along the mean.
//! - `on-path`: a berry (and its stem) centred on the mean TCP path between
//!   45 % and 75 % of the motion, plus neighbours: the optimiser must deviate.
//! - `dense`: 12 berries with stems 7-12 cm around the goal.
//! - `velocity`: durations of 0.5-0.7 s, so the mean breaks velocity limits.
//! - `joint-limit`: demonstrations whose joint 6 ends at 3.70-3.80 rad, at
//!   or beyond its 3.7525 rad upper limit (as in the real data).
//! - `degenerate-prior`: 3 demonstrations (rank-2 covariance) or an
//!   indefinite covariance (a symmetric perturbation beyond Cauchy-Schwarz).
//! - `infeasible`: a sphere around the TCP at the start configuration
//!   (start in collision) or around the goal (goal inside an obstacle).
//!
//! Feasible categories are checked at generation: the start is at least
//! 5 cm clear of every obstacle and no obstacle comes within 5 cm of the
//! goal; a draw that fails is replaced by the next sub-seed.

use super::problem_file::{Expect, Meta, ProblemFile, CATEGORIES};
use crate::optim::example::random_unit;
use crate::promp::example::{demonstrations, example_distribution, TYPICAL_FINAL};
use crate::promp::{fit_weights, Basis, PrompConfig, WeightDistribution};
use crate::robot::Robot;
use crate::scene::{Obstacle, ObstacleShape, Scene};
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;

/// Generator name written into every file's `meta.generator`.
pub const GENERATOR: &str = "dpmp bench make-problems v1";
/// Required clearance of every generated problem (m).
pub const CLEARANCE_M: f64 = 0.02;
/// Goal tolerance of every generated problem (m).
pub const GOAL_TOLERANCE_M: f64 = 0.01;
const DEMOS: usize = 12;
const ATTEMPTS: u64 = 64;

/// Settings of [`make_problems`].
#[derive(Clone, Debug)]
pub struct MakeSettings {
    /// Master seed: problem `i` of category `c` uses `seed * 10_000 + c * 100 + i`.
    pub seed: u64,
    /// Problems per category (7 categories).
    pub per_category: usize,
}

impl Default for MakeSettings {
    fn default() -> Self {
        MakeSettings {
            seed: 1,
            per_category: 9,
        }
    }
}

/// Generate `7 * per_category` problems, deterministic in `settings.seed`.
pub fn make_problems(robot: &Robot, settings: &MakeSettings) -> Result<Vec<ProblemFile>> {
    if settings.per_category == 0 || settings.per_category > 100 {
        return Err(Error::invalid(
            "per_category",
            format!("must be in 1..=100, got {}", settings.per_category),
        ));
    }
    let basis = Basis::new(&PrompConfig::default())?;
    let mut out = Vec::new();
    for (c, category) in CATEGORIES.iter().enumerate() {
        for i in 0..settings.per_category {
            let seed = settings
                .seed
                .checked_mul(10_000)
                .and_then(|s| s.checked_add(c as u64 * 100 + i as u64))
                .ok_or_else(|| Error::invalid("seed", "too large"))?;
            let problem = make_one(robot, &basis, category, i, seed)?;
            out.push(problem);
        }
    }
    Ok(out)
}

/// One problem of `category` (index `i` within it), first sub-seed that
/// passes the generation checks.
pub fn make_one(
    robot: &Robot,
    basis: &Basis,
    category: &str,
    i: usize,
    seed: u64,
) -> Result<ProblemFile> {
    for attempt in 0..ATTEMPTS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(7919).wrapping_add(attempt));
        if let Some(p) = try_make(robot, basis, category, i, seed, &mut rng)? {
            return Ok(p);
        }
    }
    Err(Error::Numerical(format!(
        "{category} problem {i} (seed {seed}): no draw passed the checks in {ATTEMPTS} attempts"
    )))
}

/// The prior mean's geometry a category places obstacles against.
struct MeanPath {
    start: Vec<f64>,
    goal: Vector3<f64>,
    tcp: Vec<Vector3<f64>>,
    q: DMatrix<f64>,
}

fn try_make(
    robot: &Robot,
    basis: &Basis,
    category: &str,
    i: usize,
    seed: u64,
    rng: &mut ChaCha8Rng,
) -> Result<Option<ProblemFile>> {
    let demo_seed: u64 = rng.gen();
    let (dist, prior_note) = prior_for(basis, category, i, demo_seed, rng)?;
    let path = mean_path(robot, basis, &dist);
    let mut duration = 4.0;
    let (obstacles, feasible, note) = match category {
        "easy" => (
            far_cluster(robot, &path, rng, 6)?,
            true,
            "cluster far from the arm",
        ),
        "on-path" => (on_path(&path, rng), true, "berry on the mean TCP path"),
        "dense" => (
            dense_cluster(&path, rng),
            true,
            "12 berries around the goal",
        ),
        "velocity" => {
            duration = rng.gen_range(0.5..0.7);
            (far_cluster(robot, &path, rng, 3)?, true, "short duration")
        }
        "joint-limit" => (
            far_cluster(robot, &path, rng, 3)?,
            true,
            "joint 6 at its upper limit",
        ),
        "degenerate-prior" => (near_path(&path, rng, 4), true, "degenerate covariance"),
        _ => infeasible(robot, &path, i, rng),
    };
    let scene = Scene::new(obstacles.clone())?;
    if feasible && !clear_start_and_goal(robot, &scene, &path) {
        return Ok(None);
    }
    let mut request = json!({
        "prior": {"mean": dist.mean.as_slice(), "cov": rows(&dist.cov)},
        "promp": basis.config(),
        "duration_s": duration,
        "start": path.start,
        "goal": {"position": [path.goal.x, path.goal.y, path.goal.z], "tolerance_m": GOAL_TOLERANCE_M},
        "obstacles": obstacles,
        "clearance_m": CLEARANCE_M,
    });
    if category == "joint-limit" {
        request["joint_limit_margin_rad"] = json!(0.0);
    }
    Ok(Some(ProblemFile {
        name: format!("{category}-{i:02}"),
        request,
        expect: Expect {
            feasible,
            min_clearance_m: feasible.then_some(CLEARANCE_M),
        },
        meta: Meta {
            generator: GENERATOR.to_string(),
            seed,
            category: category.to_string(),
            description: format!("{note}; {prior_note}"),
        },
    }))
}

fn prior_for(
    basis: &Basis,
    category: &str,
    i: usize,
    demo_seed: u64,
    rng: &mut ChaCha8Rng,
) -> Result<(WeightDistribution, String)> {
    match category {
        "joint-limit" => {
            let mut final_q = TYPICAL_FINAL;
            final_q[5] = rng.gen_range(3.70..3.80);
            let dist = fitted(basis, &final_q, DEMOS, demo_seed)?;
            Ok((
                dist,
                format!("demonstrations end at joint 6 = {:.3} rad", final_q[5]),
            ))
        }
        "degenerate-prior" if i % 2 == 0 => {
            let dist = fitted(basis, &TYPICAL_FINAL, 3, demo_seed)?;
            Ok((dist, "3 demonstrations: rank-2 covariance".to_string()))
        }
        "degenerate-prior" => {
            let mut dist = example_distribution(basis, DEMOS, demo_seed)?;
            let (a, b) = (rng.gen_range(0..dist.dim()), rng.gen_range(0..dist.dim()));
            let b = if a == b { (b + 1) % dist.dim() } else { b };
            let bump = 2.0 * (dist.cov[(a, a)] * dist.cov[(b, b)]).sqrt();
            dist.cov[(a, b)] += bump;
            dist.cov[(b, a)] += bump;
            Ok((
                dist,
                format!("indefinite: cov[{a}][{b}] raised beyond Cauchy-Schwarz"),
            ))
        }
        _ => Ok((
            example_distribution(basis, DEMOS, demo_seed)?,
            format!("{DEMOS} demonstrations"),
        )),
    }
}

fn fitted(basis: &Basis, final_q: &[f64; 7], n: usize, seed: u64) -> Result<WeightDistribution> {
    let demos = demonstrations(final_q, n, basis.n_samples(), seed);
    let weights: Vec<DVector<f64>> = demos
        .iter()
        .map(|d| fit_weights(basis, d))
        .collect::<Result<_>>()?;
    WeightDistribution::from_demonstrations(&weights, 7, basis.n_basis())
}

fn mean_path(robot: &Robot, basis: &Basis, dist: &WeightDistribution) -> MeanPath {
    let q = dist.trajectory_mean(basis);
    let tcp: Vec<Vector3<f64>> = (0..q.nrows())
        .map(|t| robot.tcp_pose(&row(&q, t)).translation.vector)
        .collect();
    MeanPath {
        start: row(&q, 0),
        goal: tcp[tcp.len() - 1],
        tcp,
        q,
    }
}

fn row(q: &DMatrix<f64>, t: usize) -> Vec<f64> {
    q.row(t).iter().copied().collect()
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|r| m.row(r).iter().copied().collect())
        .collect()
}

fn sphere(id: String, c: Vector3<f64>, radius: f64) -> Obstacle {
    Obstacle {
        id,
        shape: ObstacleShape::Sphere {
            center: c.into(),
            radius,
        },
    }
}

fn stem(id: String, a: Vector3<f64>, length: f64) -> Obstacle {
    Obstacle {
        id,
        shape: ObstacleShape::Capsule {
            a: a.into(),
            b: (a + Vector3::z() * length).into(),
            radius: 0.003,
        },
    }
}

/// `n` berries around a centre at least 0.25 m from the arm along the mean.
fn far_cluster(
    robot: &Robot,
    path: &MeanPath,
    rng: &mut ChaCha8Rng,
    n: usize,
) -> Result<Vec<Obstacle>> {
    let mut dir = random_unit(rng);
    dir.z = dir.z.abs() * 0.3;
    let centre = path.goal + dir.normalize() * rng.gen_range(0.25..0.4);
    let obstacles: Vec<Obstacle> = (0..n)
        .map(|k| {
            sphere(
                format!("berry-{k}"),
                centre + random_unit(rng) * 0.05,
                rng.gen_range(0.01..0.02),
            )
        })
        .collect();
    let scene = Scene::new(obstacles.clone())?;
    let far = (0..path.q.nrows()).step_by(5).all(|t| {
        scene
            .min_clearance(robot, &robot.fk(&row(&path.q, t)))
            .is_none_or(|c| c.distance > 0.1)
    });
    Ok(if far { obstacles } else { Vec::new() })
}

/// A berry with a stem on the mean TCP path, plus 3 neighbours.
fn on_path(path: &MeanPath, rng: &mut ChaCha8Rng) -> Vec<Obstacle> {
    let n = path.tcp.len();
    let k = rng.gen_range(n * 45 / 100..n * 75 / 100);
    let radius = rng.gen_range(0.015..0.025);
    let centre = path.tcp[k];
    let mut obstacles = vec![
        sphere("berry-0".into(), centre, radius),
        stem("stem-0".into(), centre + Vector3::z() * radius, 0.05),
    ];
    obstacles.extend(near_path(path, rng, 3).into_iter().map(|mut o| {
        o.id = format!("n{}", o.id);
        o
    }));
    obstacles
}

/// `n` berries 4-10 cm from random points of the mean TCP path's second half.
fn near_path(path: &MeanPath, rng: &mut ChaCha8Rng, n: usize) -> Vec<Obstacle> {
    let len = path.tcp.len();
    (0..n)
        .map(|k| {
            let t = rng.gen_range(len / 2..len);
            let c = path.tcp[t] + random_unit(rng) * rng.gen_range(0.04..0.10);
            sphere(format!("berry-{k}"), c, rng.gen_range(0.01..0.02))
        })
        .collect()
}

/// 12 stemmed berries 8-13 cm around the goal.
fn dense_cluster(path: &MeanPath, rng: &mut ChaCha8Rng) -> Vec<Obstacle> {
    (0..12)
        .map(|k| {
            let c = path.goal + random_unit(rng) * rng.gen_range(0.08..0.13);
            let radius = rng.gen_range(0.01..0.018);
            Obstacle {
                id: format!("berry-{k}"),
                shape: ObstacleShape::Berry {
                    center: c.into(),
                    radius,
                    elongation: rng.gen_range(0.0..0.006),
                    stem_top: (c + Vector3::z() * rng.gen_range(0.03..0.05)).into(),
                    stem_radius: 0.002,
                },
            }
        })
        .collect()
}

/// Start in collision (even `i`) or goal inside an obstacle (odd `i`).
fn infeasible(
    robot: &Robot,
    path: &MeanPath,
    i: usize,
    rng: &mut ChaCha8Rng,
) -> (Vec<Obstacle>, bool, &'static str) {
    let radius = rng.gen_range(0.025..0.04);
    if i % 2 == 0 {
        let tcp = robot.tcp_pose(&path.start).translation.vector;
        (
            vec![sphere("berry-on-start".into(), tcp, radius)],
            false,
            "start in collision",
        )
    } else {
        (
            vec![sphere("berry-on-goal".into(), path.goal, radius)],
            false,
            "goal inside an obstacle",
        )
    }
}

fn clear_start_and_goal(robot: &Robot, scene: &Scene, path: &MeanPath) -> bool {
    if scene.is_empty() {
        return false;
    }
    let start_clear = scene
        .min_clearance(robot, &robot.fk(&path.start))
        .is_none_or(|c| c.distance >= CLEARANCE_M + 0.03);
    let goal = Point3::from(path.goal);
    start_clear && scene.obstacle_containing(&goal, 0.05).is_none()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generation_is_deterministic_and_checks_hold() {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let a = make_one(&robot, &basis, "on-path", 0, 42).unwrap();
        let b = make_one(&robot, &basis, "on-path", 0, 42).unwrap();
        assert_eq!(a.to_json().unwrap(), b.to_json().unwrap());
        assert!(a.expect.feasible);
        let inf = make_one(&robot, &basis, "infeasible", 1, 43).unwrap();
        assert!(!inf.expect.feasible);
        let goal: Vec<f64> =
            serde_json::from_value(inf.request["goal"]["position"].clone()).unwrap();
        let obstacles: Vec<Obstacle> =
            serde_json::from_value(inf.request["obstacles"].clone()).unwrap();
        let scene = Scene::new(obstacles).unwrap();
        assert!(scene
            .obstacle_containing(&Point3::new(goal[0], goal[1], goal[2]), 0.0)
            .is_some());
    }
}
