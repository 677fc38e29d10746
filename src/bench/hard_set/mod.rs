//! The hard optimiser set behind `dpmp bench make-problems --set hard`:
//! problems where something the demonstrations never met stands beside
//! their path, so the prior mean collides and the optimiser must find a way
//! round it.
//!
//! Each problem starts from one of two prior families (alternating by
//! index):
//!
//! - `synth`: a synthetic plant with its demonstrations and their fitted
//!   Gaussian ([`super::synth_target`]); the plant's other berries, stems
//!   and leaflets are obstacles;
//! - `example`: the example annotation prior ([`typical_request`]) with a
//!   plant of stemmed berries 6-12 cm beside its mean path.
//!
//! Then one to three *intruders* (unripe berries with their stems, radius
//! [`INTRUDER_RADIUS_M`]) are placed beside the prior mean's TCP path in
//! mid-motion ([`INTRUDER_PHASES`] of the motion), their centres
//! [`INTRUDER_OFFSET_M`] from it across the path. A draw is kept when the
//! intruders block the prior mean (its dense clearance to them is below the
//! request's) while the mean's start and final configurations stay clear of
//! them, so the goal stays reachable.
//!
//! **Labels.** Each problem is labelled offline by a long search
//! ([`LABEL_RESTARTS`] restarts, [`LABEL_ITERATIONS`] iterations): an
//! `optimal` answer is kept as the witness (`expect.witness`, verified
//! densely and by the continuous certificate), otherwise the problem is
//! marked unknown (`expect.feasible: null`); success rates count the
//! labelled-feasible problems only. The test suite re-verifies every
//! witness against the file as written.

pub mod real;

use super::make_problems::{mean_path, round_significant, round_value, MeanPath};
use super::problem_file::{Expect, Meta, ProblemFile, HARD_CATEGORY};
use super::synth_target::draw_target;
use crate::fixtures::{typical_request, ExampleSettings};
use crate::geometry::random_unit;
use crate::optim::{optimize, OptimizeRequest, Status};
use crate::promp::distribution::matrix_rows;
use crate::robot::Robot;
use crate::scene::{BerryShape, Obstacle, ObstacleShape, Scene};
use crate::synth::generate::Generator;
use crate::{Error, Result};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::{json, Value};

/// Generator name written into every file's `meta.generator`.
pub const HARD_GENERATOR: &str = "dpmp bench make-problems --set hard v1";
/// Required clearance of every hard problem (m).
pub const HARD_CLEARANCE_M: f64 = 0.015;
/// Goal tolerance (m).
pub const HARD_GOAL_TOLERANCE_M: f64 = 0.01;
/// Intruder radius range (m).
pub const INTRUDER_RADIUS_M: (f64, f64) = (0.01, 0.025);
/// Distance of an intruder's centre from the mean TCP path (m).
pub const INTRUDER_OFFSET_M: (f64, f64) = (0.025, 0.06);
/// Fraction of the motion where intruders stand.
pub const INTRUDER_PHASES: (f64, f64) = (0.3, 0.7);
/// Restarts of the labelling search.
pub const LABEL_RESTARTS: usize = 32;
/// Iteration limit of the labelling search's first run.
pub const LABEL_ITERATIONS: usize = 1000;
/// Draws tried per problem before its seed is given up.
const ATTEMPTS: u64 = 64;

/// Where intruders are drawn: their radius, their centre's distance from
/// the prior mean's TCP path, and the fraction of the motion they stand at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntruderRanges {
    /// Radius range (m).
    pub radius_m: (f64, f64),
    /// Range of the centre's distance from the mean TCP path (m).
    pub offset_m: (f64, f64),
    /// Range of the phase (fraction of the motion) beside which they stand.
    pub phases: (f64, f64),
    /// Whether the prior mean's final pose must clear them too (not only
    /// its start and the goal point): needed when the goal fixes the final
    /// pose; with a position goal another wrist pose may reach it, and the
    /// long search decides.
    pub final_pose_clear: bool,
}

/// The intruders of the synthetic and example families.
pub const HARD_INTRUDERS: IntruderRanges = IntruderRanges {
    radius_m: INTRUDER_RADIUS_M,
    offset_m: INTRUDER_OFFSET_M,
    phases: INTRUDER_PHASES,
    final_pose_clear: true,
};
/// The mean's start and final poses keep this much more than the
/// clearance from every intruder.
const ENDS_MARGIN_M: f64 = 0.005;

/// Settings of [`make_hard_set`].
#[derive(Clone, Debug)]
pub struct HardSettings {
    /// Master seed: problem `i` uses `seed * 100_000 + i`.
    pub seed: u64,
    /// Number of problems.
    pub count: usize,
    /// Label each problem by the long search (off: every label unknown).
    pub label: bool,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// Generate `settings.count` hard problems on the rayon pool,
/// deterministic in `settings.seed`, labelled as the module docs say.
pub fn make_hard_set(generator: &Generator, settings: &HardSettings) -> Result<Vec<ProblemFile>> {
    make_set(settings, "hard problems", |i, seed| {
        make_hard_one(generator, i, seed, settings.label)
    })
}

/// `settings.count` problems, problem `i` made by `one(i, seed * 100_000 +
/// i)` on the rayon pool, with a progress bar naming `what`.
fn make_set(
    settings: &HardSettings,
    what: &str,
    one: impl Fn(usize, u64) -> Result<ProblemFile> + Sync,
) -> Result<Vec<ProblemFile>> {
    if settings.count == 0 || settings.count > 10_000 {
        return Err(Error::invalid(
            "count",
            format!("must be in 1..=10000, got {}", settings.count),
        ));
    }
    let base = settings
        .seed
        .checked_mul(100_000)
        .ok_or_else(|| Error::invalid("seed", "too large"))?;
    let bar = super::runner::progress_bar(settings.count, settings.progress, what);
    let out = (0..settings.count)
        .into_par_iter()
        .map(|i| {
            let p = one(i, base + i as u64);
            bar.inc(1);
            p
        })
        .collect::<Result<Vec<_>>>();
    bar.finish_and_clear();
    out
}

/// The file of a kept draw: `request` rounded, labelled by the long search
/// when `label` says so.
fn hard_file(
    name: String,
    request: &Value,
    label: bool,
    robot: &Robot,
    meta: Meta,
) -> Result<ProblemFile> {
    let request = round_value(request);
    let expect = if label {
        long_search_label(&request, robot)?
    } else {
        unknown()
    };
    Ok(ProblemFile {
        name,
        request,
        expect,
        meta,
    })
}

/// Problem `i` of the hard set from its own `seed`.
pub fn make_hard_one(
    generator: &Generator,
    i: usize,
    seed: u64,
    label: bool,
) -> Result<ProblemFile> {
    let robot = generator.robot();
    let family = if i.is_multiple_of(2) {
        "synth"
    } else {
        "example"
    };
    let intruders = 1 + (i / 2) % 3;
    for attempt in 0..ATTEMPTS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(6151).wrapping_add(attempt));
        let Some(base) = base_request(generator, family, &mut rng)? else {
            continue;
        };
        let Some(request) = with_intruders(robot, base, intruders, &HARD_INTRUDERS, &mut rng)?
        else {
            continue;
        };
        let meta = Meta {
            generator: HARD_GENERATOR.to_string(),
            seed,
            category: HARD_CATEGORY.to_string(),
            description: format!(
                "{family} prior and plant + {intruders} intruder(s) beside the mean path"
            ),
            reference_final_tcp: None,
        };
        return hard_file(format!("hard-{i:03}"), &request, label, robot, meta);
    }
    Err(Error::Numerical(format!(
        "hard problem {i} (seed {seed}): no draw blocked the prior mean in {ATTEMPTS} attempts"
    )))
}

/// The request before its intruders: prior, plant, start, goal.
fn base_request(
    generator: &Generator,
    family: &str,
    rng: &mut ChaCha8Rng,
) -> Result<Option<Value>> {
    let robot = generator.robot();
    if family == "example" {
        let settings = ExampleSettings {
            n_obstacles: 6,
            clearance_m: HARD_CLEARANCE_M,
            offset_m: (0.06, 0.12),
            ..Default::default()
        };
        let mut request = typical_request(robot, rng.gen(), &settings)?;
        if let Some(goal) = request.task.goal.as_mut() {
            goal.tolerance_m = HARD_GOAL_TOLERANCE_M;
        }
        let value = serde_json::to_value(&request)
            .map_err(|e| Error::Numerical(format!("cannot serialise request: {e}")))?;
        return Ok(Some(value));
    }
    let Some(target) = draw_target(generator, rng)? else {
        return Ok(None);
    };
    let basis = generator.basis();
    let dist = &target.distribution;
    let path = mean_path(robot, basis, dist);
    let g = target.final_tcp;
    Ok(Some(json!({
        "prior": {"mean": dist.mean.as_slice(), "cov": matrix_rows(&dist.cov)},
        "promp": basis.config(),
        "duration_s": generator.settings().demos.duration_s,
        "start": path.start,
        "goal": {"position": [g.x, g.y, g.z], "tolerance_m": HARD_GOAL_TOLERANCE_M},
        "obstacles": target.obstacles,
        "clearance_m": HARD_CLEARANCE_M,
        "boundary": "rest",
    })))
}

/// `request` with `n` intruders drawn from `ranges` beside its prior
/// mean's path, or `None` when this draw does not block the mean with its
/// ends clear.
fn with_intruders(
    robot: &Robot,
    mut request: Value,
    n: usize,
    ranges: &IntruderRanges,
    rng: &mut ChaCha8Rng,
) -> Result<Option<Value>> {
    let parsed: OptimizeRequest = serde_json::from_value(request.clone())
        .map_err(|e| Error::invalid("request", format!("does not parse: {e}")))?;
    let problem = parsed.validate(robot)?;
    let basis = problem.basis();
    let dist = problem.prior();
    let path = mean_path(robot, basis, dist);
    let goal = parsed.task.goal.as_ref().map(|g| Vector3::from(g.position));
    let mut placed = Vec::new();
    for k in 0..n {
        let Some(intruder) = place_intruder(robot, &path, goal, k, ranges, rng)? else {
            return Ok(None);
        };
        placed.push(intruder);
    }
    let mean = problem.prior().mean.as_slice().to_vec();
    let blocked = {
        let alone = intruders_only(&parsed, &placed, robot)?;
        alone
            .evaluate(&mean)
            .min_clearance_m
            .is_some_and(|d| d < HARD_CLEARANCE_M)
    };
    if !blocked {
        return Ok(None);
    }
    if let Some(list) = request["obstacles"].as_array_mut() {
        for o in placed {
            list.push(serde_json::to_value(o).map_err(|e| Error::Numerical(e.to_string()))?);
        }
    }
    Ok(Some(request))
}

/// The request's problem with the intruders as its only obstacles.
fn intruders_only(
    parsed: &OptimizeRequest,
    intruders: &[Obstacle],
    robot: &Robot,
) -> Result<crate::optim::Problem> {
    let mut alone = parsed.clone();
    alone.task.obstacles = intruders.to_vec();
    alone.validate(robot)
}

/// One unripe berry (with its stem) across the mean TCP path at a random
/// mid-motion phase, its ends' poses and the goal clear of it.
fn place_intruder(
    robot: &Robot,
    path: &MeanPath,
    goal: Option<Vector3<f64>>,
    k: usize,
    ranges: &IntruderRanges,
    rng: &mut ChaCha8Rng,
) -> Result<Option<Obstacle>> {
    let n = path.tcp.len();
    let lo = ((n as f64 * ranges.phases.0) as usize).max(1);
    let hi = ((n as f64 * ranges.phases.1) as usize).min(n - 2);
    for _ in 0..16 {
        let t = rng.gen_range(lo..=hi);
        let tangent = (path.tcp[t + 1] - path.tcp[t - 1]).normalize();
        let across = {
            let u = random_unit(rng);
            let v = u - tangent * u.dot(&tangent);
            if v.norm() < 1e-6 {
                continue;
            }
            v.normalize()
        };
        let radius = rng.gen_range(ranges.radius_m.0..ranges.radius_m.1);
        let centre = path.tcp[t] + across * rng.gen_range(ranges.offset_m.0..ranges.offset_m.1);
        let berry = Obstacle {
            id: format!("intruder-{k}"),
            shape: ObstacleShape::Berry(BerryShape {
                center: centre.into(),
                radius,
                elongation: rng.gen_range(0.0..0.3 * radius),
                stem_top: (centre + Vector3::z() * (radius + rng.gen_range(0.02..0.05))).into(),
                stem_radius: 0.002,
            }),
        };
        if keeps_ends_clear(
            robot,
            path,
            goal,
            &berry,
            (centre, radius),
            ranges.final_pose_clear,
        )? {
            return Ok(Some(berry));
        }
    }
    Ok(None)
}

/// Whether `berry` (its bounding ball `(centre, radius)`) keeps the mean's
/// start pose (and with `final_pose` its final pose) [`ENDS_MARGIN_M`]
/// beyond the clearance, and the goal well outside its tolerance, so the
/// goal stays reachable.
fn keeps_ends_clear(
    robot: &Robot,
    path: &MeanPath,
    goal: Option<Vector3<f64>>,
    berry: &Obstacle,
    (centre, radius): (Vector3<f64>, f64),
    final_pose: bool,
) -> Result<bool> {
    let scene = Scene::new(vec![berry.clone()])?;
    let clear = |q: &[f64]| {
        scene
            .min_clearance(robot, &robot.fk(q))
            .is_none_or(|c| c.distance >= HARD_CLEARANCE_M + ENDS_MARGIN_M)
    };
    let goal_clear = goal.is_none_or(|g| {
        (g - centre).norm() - radius > HARD_GOAL_TOLERANCE_M + HARD_CLEARANCE_M + 0.02
    });
    Ok(clear(&path.start) && (!final_pose || clear(&path.end)) && goal_clear)
}

/// The long search's label of `request`: feasible with its `optimal`
/// answer as the witness, or unknown.
pub fn long_search_label(request: &Value, robot: &Robot) -> Result<Expect> {
    let mut parsed: OptimizeRequest = serde_json::from_value(request.clone())
        .map_err(|e| Error::invalid("request", format!("does not parse: {e}")))?;
    parsed.task.options.restarts = LABEL_RESTARTS;
    parsed.task.options.max_iterations = LABEL_ITERATIONS;
    let answer = optimize(&parsed, robot)?;
    if answer.status != Status::Optimal {
        return Ok(unknown());
    }
    let witness: Vec<f64> = answer
        .weights
        .iter()
        .map(|&w| round_significant(w))
        .collect();
    // The rounded witness must still verify against the file as written.
    let problem = parsed.validate(robot)?;
    if !problem.is_feasible(&problem.evaluate(&witness)) {
        return Ok(unknown());
    }
    Ok(Expect {
        feasible: Some(true),
        min_clearance_m: Some(HARD_CLEARANCE_M),
        witness: Some(witness),
    })
}

fn unknown() -> Expect {
    Expect {
        feasible: None,
        min_clearance_m: None,
        witness: None,
    }
}
