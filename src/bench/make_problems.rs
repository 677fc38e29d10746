//! The seeded problem generator behind `dpmp bench make-problems`, drawing
//! from the synthetic generator ([`crate::synth`], via [`super::synth_target`]).
//!
//! Every problem starts from one synthetic target: a plant (all its
//! obstacles: berries, stems, leaflets, tray), 10 demonstrations towards one
//! of its berries and the full Gaussian fitted to their ProMP weights (the
//! prior). The request starts at the prior mean's start configuration (home
//! up to the demonstrations' start noise) and asks for the TCP to end within
//! 1 cm of the demonstrations' mean pre-grasp TCP position. Category by
//! category:
//!
//! - `easy`: the plant as drawn.
//! - `on-path`: plus a small berry (and its stem) at the prior mean's TCP
//!   path (centre within one radius + 3 cm of it) at a phase where the
//!   mean's start and final poses stay clear; the mean is checked to
//!   violate the clearance, so the optimiser must deviate.
//! - `dense`: plus 6 stemmed berries 7-14 cm around the goal.
//! - `velocity`: the shortest duration at which some candidate still keeps
//!   the velocity limits, times 1.02-1.10: the limits bind.
//! - `joint-limit`: a joint-limit margin that puts joint 6's effective upper
//!   limit 1-10 mrad above the witness' highest joint-6 position (joint 6
//!   near its upper limit, as in the real data); every candidate reaching
//!   higher violates it.
//! - `degenerate-prior`: the Gaussian of only 3 demonstrations (rank 2,
//!   even index) or an indefinite covariance (a symmetric perturbation
//!   beyond Cauchy-Schwarz, odd index).
//! - `infeasible`: a sphere around the TCP at the start configuration
//!   (start in collision, even index) or around the goal (goal inside an
//!   obstacle, odd index).
//!
//! Checks at generation, on the request exactly as written (floats rounded
//! to 10 significant digits first): it parses and validates like the
//! runner's; a feasible problem has a *witness* ([`super::witness`]) — the
//! prior mean, a demonstration, or a detour of the mean (a smooth bump of
//! ±0.1/0.2 rad at mid-motion on joint 1, 2 or 4, fitted into the basis),
//! pinned to the start, that passes the dense verification of every
//! constraint; an infeasible one is infeasible
//! by a geometric certificate (the start configuration penetrates the
//! sphere, or the sphere contains the whole goal-tolerance ball). A draw
//! that fails is replaced by the next sub-seed.

use super::problem_file::{Expect, Meta, ProblemFile, CATEGORIES};
use super::synth_target::{bench_generator, draw_target, SynthTarget};
use super::witness::{find_witness, pin_start, reports, validated};
use crate::geometry::{random_unit, Capsule, Sphere};
use crate::promp::distribution::matrix_rows;
use crate::promp::{fit_weights, Basis, WeightDistribution};
use crate::robot::Robot;
use crate::scene::{BerryShape, Obstacle, ObstacleShape, Scene};
use crate::synth::demos::via_bump;
use crate::synth::generate::Generator;
use crate::{Error, Result};
use nalgebra::{DVector, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::{json, Value};

/// Generator name written into every file's `meta.generator`.
pub const GENERATOR: &str = "dpmp bench make-problems v2 (synth)";
/// Required clearance of every generated problem (m).
pub const CLEARANCE_M: f64 = 0.02;
/// Goal tolerance of every generated problem (m).
pub const GOAL_TOLERANCE_M: f64 = 0.01;
/// Significant digits kept in the written floats.
pub const SIGNIFICANT_DIGITS: usize = 10;
const ATTEMPTS: u64 = 48;
/// Added to a problem's seed when no draw of its own seed passes.
const SPARE_SEED_OFFSET: u64 = 5_000;
const PLACEMENTS_PER_DRAW: usize = 8;
const JOINT6: usize = 5;

/// Settings of [`make_problems`] (a problem whose seed yields no draw that
/// passes the checks is drawn from its spare seed, `seed + 5000`, instead).
#[derive(Clone, Debug)]
pub struct MakeSettings {
    /// Master seed: problem `i` of category `c` uses `seed * 10_000 + c * 100 + i`.
    pub seed: u64,
    /// Problems per category (7 categories).
    pub per_category: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

impl Default for MakeSettings {
    fn default() -> Self {
        MakeSettings {
            seed: 1,
            per_category: 9,
            progress: false,
        }
    }
}

/// Generate `7 * per_category` problems on the rayon pool, deterministic
/// in `settings.seed` (each problem has its own seed; the order is fixed).
pub fn make_problems(generator: &Generator, settings: &MakeSettings) -> Result<Vec<ProblemFile>> {
    if settings.per_category == 0 || settings.per_category > 100 {
        return Err(Error::invalid(
            "per_category",
            format!("must be in 1..=100, got {}", settings.per_category),
        ));
    }
    let mut jobs = Vec::new();
    for (c, category) in CATEGORIES.iter().enumerate() {
        for i in 0..settings.per_category {
            let seed = settings
                .seed
                .checked_mul(10_000)
                .and_then(|s| s.checked_add(c as u64 * 100 + i as u64))
                .ok_or_else(|| Error::invalid("seed", "too large"))?;
            jobs.push((*category, i, seed));
        }
    }
    let bar = super::runner::progress_bar(jobs.len(), settings.progress, "problems generated");
    let out = jobs
        .par_iter()
        .map(|&(category, i, seed)| {
            // A seed whose draws all fail the checks gives way to a spare one.
            let p = make_one(generator, category, i, seed)
                .or_else(|_| make_one(generator, category, i, seed + SPARE_SEED_OFFSET));
            bar.inc(1);
            p
        })
        .collect::<Result<Vec<_>>>();
    bar.finish_and_clear();
    out
}

/// The synthetic generator the suite is drawn from (see
/// [`super::synth_target::bench_generator`]).
pub fn generator(robot: &Robot) -> Result<Generator> {
    bench_generator(robot)
}

/// One problem of `category` (index `i` within it), first sub-seed that
/// passes the generation checks.
pub fn make_one(generator: &Generator, category: &str, i: usize, seed: u64) -> Result<ProblemFile> {
    if !CATEGORIES.contains(&category) {
        return Err(Error::invalid(
            "category",
            format!("must be one of {CATEGORIES:?}, got {category:?}"),
        ));
    }
    let mut last = String::from("no synthetic target drawn");
    for attempt in 0..ATTEMPTS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(7919).wrapping_add(attempt));
        let Some(target) = draw_target(generator, &mut rng)? else {
            continue;
        };
        for _ in 0..PLACEMENTS_PER_DRAW {
            match try_make(generator, &target, category, i, seed, &mut rng)? {
                Ok(p) => return Ok(p),
                Err(reason) => last = reason,
            }
        }
    }
    Err(Error::Numerical(format!(
        "{category} problem {i} (seed {seed}): no draw passed the checks in {ATTEMPTS} attempts; last: {last}"
    )))
}

/// The prior mean's geometry a category places obstacles against.
pub(super) struct MeanPath {
    /// The mean's start configuration.
    pub(super) start: Vec<f64>,
    /// The mean's final configuration.
    pub(super) end: Vec<f64>,
    /// The mean's TCP position at every basis sample.
    pub(super) tcp: Vec<Vector3<f64>>,
}

/// A request under construction with its witness candidates.
struct Draft {
    request: Value,
    candidates: Vec<DVector<f64>>,
    feasible: bool,
    note: String,
}

fn try_make(
    generator: &Generator,
    target: &SynthTarget,
    category: &str,
    i: usize,
    seed: u64,
    rng: &mut ChaCha8Rng,
) -> Result<std::result::Result<ProblemFile, String>> {
    let robot = generator.robot();
    let basis = generator.basis();
    let (dist, demos, prior_note) = prior_for(target, category, i, rng);
    let path = mean_path(robot, basis, &dist);
    let mut obstacles = target.obstacles.clone();
    let mut note = String::from("synthetic plant");
    let feasible = category != "infeasible";
    match category {
        "on-path" => {
            let Some(berry) = on_path(robot, &path, rng)? else {
                return Ok(Err(
                    "no phase of the mean path leaves start and goal clear".into()
                ));
            };
            obstacles.extend(berry);
            note.push_str(" + a berry on the mean TCP path");
        }
        "dense" => {
            obstacles.extend(dense_cluster(&target.final_tcp, rng));
            note.push_str(" + 6 berries 7-14 cm around the goal");
        }
        "infeasible" => {
            let (o, n) = infeasible(robot, &path, &target.final_tcp, i, rng);
            obstacles.push(o);
            note = format!("synthetic plant + {n}");
        }
        _ => {}
    }
    let request = round_value(&json!({
        "prior": {"mean": dist.mean.as_slice(), "cov": matrix_rows(&dist.cov)},
        "promp": basis.config(),
        "duration_s": generator.settings().demos.duration_s,
        "start": path.start,
        "goal": {"position": [target.final_tcp.x, target.final_tcp.y, target.final_tcp.z],
                 "tolerance_m": GOAL_TOLERANCE_M},
        "obstacles": obstacles,
        "clearance_m": CLEARANCE_M,
        "boundary": "rest",
    }));
    let start: Vec<f64> = serde_json::from_value(request["start"].clone())
        .map_err(|e| Error::Numerical(format!("start: {e}")))?;
    let mut candidates = vec![pin_start(basis, &dist.mean, &start)];
    candidates.extend(demos.iter().map(|w| pin_start(basis, w, &start)));
    candidates.extend(
        detours(basis, &dist)?
            .iter()
            .map(|w| pin_start(basis, w, &start)),
    );
    let mut draft = Draft {
        request,
        candidates,
        feasible,
        note,
    };
    let checked = match category {
        "velocity" => bind_velocity(&mut draft, robot, rng)?,
        "joint-limit" => bind_joint6(&mut draft, robot, basis, rng)?,
        "on-path" => mean_blocked(&draft, robot)?,
        _ => true,
    };
    if !checked {
        return Ok(Err(format!("the {category} construction does not bind")));
    }
    if !check_claim(&draft, robot, &target.final_tcp)? {
        return Ok(Err(if feasible {
            "no candidate verifies feasible".into()
        } else {
            "infeasibility not certified".into()
        }));
    }
    Ok(Ok(ProblemFile {
        name: format!("{category}-{i:02}"),
        request: draft.request,
        expect: Expect {
            feasible: Some(feasible),
            min_clearance_m: feasible.then_some(CLEARANCE_M),
            witness: None,
        },
        meta: Meta {
            generator: GENERATOR.to_string(),
            seed,
            category: category.to_string(),
            description: format!("{}; target {}; {prior_note}", draft.note, target.berry_id),
            reference_final_tcp: None,
        },
    }))
}

/// The prior, the demonstrations it was fitted to, and a note.
fn prior_for(
    target: &SynthTarget,
    category: &str,
    i: usize,
    rng: &mut ChaCha8Rng,
) -> (WeightDistribution, Vec<DVector<f64>>, String) {
    let demos = target.demo_weights.clone();
    let n = demos.len();
    if category == "degenerate-prior" && i.is_multiple_of(2) {
        let few = demos[..3.min(n)].to_vec();
        let d = &target.distribution;
        if let Ok(dist) = WeightDistribution::from_demonstrations(&few, d.n_joints, d.n_basis) {
            return (
                dist,
                few,
                "prior of 3 demonstrations: rank-2 covariance".into(),
            );
        }
    }
    let mut dist = target.distribution.clone();
    if category == "degenerate-prior" {
        let (a, b) = (rng.gen_range(0..dist.dim()), rng.gen_range(0..dist.dim()));
        let b = if a == b { (b + 1) % dist.dim() } else { b };
        let bump = 2.0 * (dist.cov[(a, a)] * dist.cov[(b, b)]).sqrt();
        dist.cov[(a, b)] += bump;
        dist.cov[(b, a)] += bump;
        return (
            dist,
            demos,
            format!("indefinite: cov[{a}][{b}] raised beyond Cauchy-Schwarz"),
        );
    }
    (dist, demos, format!("prior of {n} demonstrations"))
}

/// The prior mean's start, end and TCP path.
pub(super) fn mean_path(robot: &Robot, basis: &Basis, dist: &WeightDistribution) -> MeanPath {
    let q = dist.trajectory_mean(basis);
    MeanPath {
        start: q.row(0).iter().copied().collect(),
        end: q.row(q.nrows() - 1).iter().copied().collect(),
        tcp: robot.tcp_path(&q),
    }
}

/// `x` rounded to [`SIGNIFICANT_DIGITS`] significant digits.
pub fn round_significant(x: f64) -> f64 {
    if !x.is_finite() || x == 0.0 {
        return x;
    }
    format!("{x:.*e}", SIGNIFICANT_DIGITS - 1)
        .parse()
        .unwrap_or(x)
}

/// Every float in `v` rounded with [`round_significant`] (integers kept).
pub fn round_value(v: &Value) -> Value {
    match v {
        Value::Number(n) if n.is_f64() => n
            .as_f64()
            .and_then(|x| serde_json::Number::from_f64(round_significant(x)))
            .map_or_else(|| v.clone(), Value::Number),
        Value::Array(a) => Value::Array(a.iter().map(round_value).collect()),
        Value::Object(m) => {
            Value::Object(m.iter().map(|(k, x)| (k.clone(), round_value(x))).collect())
        }
        _ => v.clone(),
    }
}

fn sphere(id: String, c: Vector3<f64>, radius: f64) -> Obstacle {
    Obstacle {
        id,
        shape: ObstacleShape::Sphere(Sphere {
            center: c.into(),
            radius,
        }),
    }
}

/// A small berry with a stem at the mean TCP path (its centre within one
/// radius + 3 cm of it, so that the mean's hand passes it closer than the
/// clearance), at a random phase in 20-80 % of the motion where both the
/// start and the final configuration of the mean stay clear of it (the
/// short synthetic reaches put the arm's final pose over the end of the
/// TCP path, and a berry there would make the goal itself unreachable).
/// `None` when no phase qualifies. The generation check then asks that it
/// blocks the mean and that a witness passes beside it.
fn on_path(robot: &Robot, path: &MeanPath, rng: &mut ChaCha8Rng) -> Result<Option<Vec<Obstacle>>> {
    let n = path.tcp.len();
    let mut phases: Vec<usize> = (n * 20 / 100..n * 80 / 100).collect();
    phases.shuffle(rng);
    let radius = rng.gen_range(0.006..0.012);
    for k in phases {
        let centre = path.tcp[k] + random_unit(rng) * rng.gen_range(0.0..radius + 0.03);
        let berry = on_path_berry(centre, radius);
        let scene = Scene::new(berry.clone())?;
        let clear = |q: &[f64]| {
            scene
                .min_clearance(robot, &robot.fk(q))
                .is_none_or(|c| c.distance >= CLEARANCE_M + 0.005)
        };
        if clear(&path.start) && clear(&path.end) {
            return Ok(Some(berry));
        }
    }
    Ok(None)
}

/// The on-path berry: a sphere and a 2 cm stem above it.
fn on_path_berry(centre: Vector3<f64>, radius: f64) -> Vec<Obstacle> {
    let top = centre + Vector3::z() * (radius + 0.02);
    vec![
        sphere("bench-berry-on-path".into(), centre, radius),
        Obstacle {
            id: "bench-stem-on-path".into(),
            shape: ObstacleShape::Capsule(Capsule {
                a: (centre + Vector3::z() * radius).into(),
                b: top.into(),
                radius: 0.002,
            }),
        },
    ]
}

/// Joints a detour moves (base yaw, shoulder, elbow).
const DETOUR_JOINTS: [usize; 3] = [0, 1, 3];
/// Detour amplitudes at mid-motion (rad).
const DETOUR_AMPLITUDES: [f64; 4] = [-0.2, -0.1, 0.1, 0.2];

/// Witness candidates that leave the mean: the mean trajectory plus
/// `a * 64 t³(1-t)³` on one joint (zero position, velocity and acceleration
/// at both ends, `a` at mid-motion), fitted back into the basis.
fn detours(basis: &Basis, dist: &WeightDistribution) -> Result<Vec<DVector<f64>>> {
    let mean = dist.trajectory_mean(basis);
    let phases = basis.phases();
    let mut out = Vec::new();
    for &j in &DETOUR_JOINTS {
        for &a in &DETOUR_AMPLITUDES {
            let mut q = mean.clone();
            for (t, z) in phases.iter().enumerate() {
                q[(t, j)] += a * via_bump(*z);
            }
            out.push(fit_weights(basis, &q)?);
        }
    }
    Ok(out)
}

/// 6 stemmed berries 7-14 cm around the goal.
fn dense_cluster(goal: &Vector3<f64>, rng: &mut ChaCha8Rng) -> Vec<Obstacle> {
    (0..6)
        .map(|k| {
            let c = goal + random_unit(rng) * rng.gen_range(0.07..0.14);
            let radius = rng.gen_range(0.01..0.018);
            Obstacle {
                id: format!("bench-berry-{k}"),
                shape: ObstacleShape::Berry(BerryShape {
                    center: c.into(),
                    radius,
                    elongation: rng.gen_range(0.0..0.006),
                    stem_top: (c + Vector3::z() * rng.gen_range(0.03..0.05)).into(),
                    stem_radius: 0.002,
                }),
            }
        })
        .collect()
}

/// Start in collision (even `i`) or goal inside an obstacle (odd `i`).
fn infeasible(
    robot: &Robot,
    path: &MeanPath,
    goal: &Vector3<f64>,
    i: usize,
    rng: &mut ChaCha8Rng,
) -> (Obstacle, &'static str) {
    let radius = rng.gen_range(0.03..0.045);
    if i.is_multiple_of(2) {
        let tcp = robot.tcp_pose(&path.start).translation.vector;
        (
            sphere("bench-berry-on-start".into(), tcp, radius),
            "a sphere around the start TCP (start in collision)",
        )
    } else {
        (
            sphere("bench-berry-on-goal".into(), *goal, radius),
            "a sphere around the goal (goal inside an obstacle)",
        )
    }
}

/// The on-path berry must actually block the prior mean.
fn mean_blocked(draft: &Draft, robot: &Robot) -> Result<bool> {
    let problem = validated(&draft.request, robot)?;
    let mean = problem.evaluate(draft.candidates[0].as_slice());
    Ok(mean.min_clearance_m.is_some_and(|d| d < CLEARANCE_M))
}

/// Shorten the duration until the velocity limits bind for the slowest
/// candidate that is otherwise feasible.
fn bind_velocity(draft: &mut Draft, robot: &Robot, rng: &mut ChaCha8Rng) -> Result<bool> {
    let problem = validated(&draft.request, robot)?;
    let duration = problem.duration();
    let slowest = reports(&problem, &draft.candidates)
        .into_iter()
        .filter(|r| problem.is_feasible(r))
        .map(|r| r.max_velocity_ratio)
        .fold(f64::INFINITY, f64::min);
    if !slowest.is_finite() || slowest <= 0.0 {
        return Ok(false);
    }
    let short = round_significant(duration * slowest * rng.gen_range(1.02..1.10));
    draft.request["duration_s"] = json!(short);
    draft.note = format!("synthetic plant, duration {short:.3} s: velocity limits bind");
    Ok(true)
}

/// Put joint 6's effective upper limit just above the lowest peak of joint
/// 6 among the otherwise feasible candidates.
fn bind_joint6(
    draft: &mut Draft,
    robot: &Robot,
    basis: &Basis,
    rng: &mut ChaCha8Rng,
) -> Result<bool> {
    let problem = validated(&draft.request, robot)?;
    let nb = basis.n_basis();
    let lowest_peak = reports(&problem, &draft.candidates)
        .iter()
        .zip(&draft.candidates)
        .filter(|(r, _)| problem.is_feasible(r))
        .map(|(_, w)| {
            let q6 = basis.matrix() * w.rows(JOINT6 * nb, nb);
            q6.max()
        })
        .fold(f64::INFINITY, f64::min);
    let upper = robot.limits()[JOINT6].upper;
    let margin = round_significant(upper - lowest_peak - rng.gen_range(0.001..0.01));
    if !lowest_peak.is_finite() || margin < 0.0 {
        return Ok(false);
    }
    draft.request["joint_limit_margin_rad"] = json!(margin);
    draft.note = format!(
        "synthetic plant, joint-limit margin {margin:.3} rad: joint 6 capped at {:.3} rad",
        upper - margin
    );
    Ok(true)
}

/// Verify the feasibility claim of the request as written.
fn check_claim(draft: &Draft, robot: &Robot, goal: &Vector3<f64>) -> Result<bool> {
    let problem = validated(&draft.request, robot)?;
    if draft.feasible {
        return Ok(find_witness(&problem, &draft.candidates).is_some());
    }
    let start: Vec<f64> = serde_json::from_value(draft.request["start"].clone())
        .map_err(|e| Error::Numerical(format!("start: {e}")))?;
    Ok(start_in_collision(problem.scene(), robot, &start)
        || goal_ball_inside(problem.scene(), goal))
}

/// The start configuration penetrates an obstacle.
fn start_in_collision(scene: &Scene, robot: &Robot, start: &[f64]) -> bool {
    scene
        .min_clearance(robot, &robot.fk(start))
        .is_some_and(|c| c.distance < 0.0)
}

/// A sphere obstacle contains the whole goal-tolerance ball with 1 cm to
/// spare, so every TCP position the goal allows lies 1 cm deep inside it.
fn goal_ball_inside(scene: &Scene, goal: &Vector3<f64>) -> bool {
    scene.obstacles().iter().any(|o| match &o.shape {
        ObstacleShape::Sphere(Sphere { center, radius }) => {
            (Vector3::from(*center) - goal).norm() + GOAL_TOLERANCE_M + 0.01 <= *radius
        }
        _ => false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_keeps_ten_significant_digits() {
        for x in [1.0 / 3.0, -2.718281828459045e-7, 12345.678901234] {
            let r = round_significant(x);
            assert!(((r - x) / x).abs() < 1e-9, "{x} -> {r}");
        }
        assert_eq!(round_significant(0.0), 0.0);
        let v = round_value(&json!({"a": [0.1234567890123, 3], "b": 2}));
        assert_eq!(v["a"][1], 3);
        assert_eq!(v["a"][0].as_f64().unwrap(), 0.123456789);
    }
}
