//! `dpmp bench world`: does the world the planner is given clear what is
//! really there? Every target of a dataset split (generated with
//! `--intruders`, so something the demonstrations never met stands in the
//! way) is planned through the whole `/v1/plan` pipeline three ways:
//!
//! - `none`: no obstacles, the network's prior and the goal only;
//! - `depth`: the world sensed from the target's depth image
//!   (`world: "depth"`, [`crate::plan::world`]) and nothing posted;
//! - `oracle`: the record's true scene posted as primitives.
//!
//! Each answer's trajectory is then checked against the record's **true**
//! scene (the plant and its intruders) at [`CHECK_PHASES`] phases, denser
//! than the optimiser's own grid, with the exact robot-hull distances; a
//! plan is collision-free when it keeps [`MIN_TRUE_CLEARANCE_M`] from
//! every true obstacle. Targets run one after another, so the plan times
//! are those of a single request.

use super::report::Percentiles;
use crate::net::Model;
use crate::optim::Status;
use crate::plan::{predict_and_optimize, PlanParts, PlanRequest, WorldSource};
use crate::promp::Basis;
use crate::robot::Robot;
use crate::scene::{Obstacle, Scene};
use crate::synth::dataset::{self, TargetEntry, TargetRecord};
use crate::train::plan_eval::{record_fields, record_plan_input};
use crate::{Error, Result};
use nalgebra::DMatrix;
use serde::Serialize;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// Clearance (m) every plan asks for.
pub const ASKED_CLEARANCE_M: f64 = 0.015;
/// True clearance (m) a plan must keep to count as collision-free.
pub const MIN_TRUE_CLEARANCE_M: f64 = 0.010;
/// Phases at which a trajectory is checked against the true scene.
pub const CHECK_PHASES: usize = 1000;

/// The world a plan is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum WorldGiven {
    /// No obstacles.
    None,
    /// The cloud sensed from the depth image.
    Depth,
    /// The true scene as primitives.
    Oracle,
}

impl WorldGiven {
    /// The three, in table order.
    pub const ALL: [WorldGiven; 3] = [WorldGiven::None, WorldGiven::Depth, WorldGiven::Oracle];

    /// The table's name of it.
    pub fn name(self) -> &'static str {
        match self {
            WorldGiven::None => "none (prior + goal only)",
            WorldGiven::Depth => "sensed from depth",
            WorldGiven::Oracle => "true primitives (oracle)",
        }
    }
}

/// One target planned one way.
#[derive(Clone, Debug, Serialize)]
pub struct WorldOutcome {
    /// Target id.
    pub target: String,
    /// The world given.
    pub world: WorldGiven,
    /// The answer's status.
    pub status: Status,
    /// Its least distance to the true scene (m; negative: penetration).
    pub true_clearance_m: f64,
    /// Points in the sensed cloud (depth only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensed_points: Option<usize>,
    /// Wall time of the plan (ms).
    pub plan_ms: f64,
}

/// One row of the table.
#[derive(Clone, Debug, Serialize)]
pub struct WorldRow {
    /// The world given.
    pub world: WorldGiven,
    /// Targets planned.
    pub targets: usize,
    /// Share that keeps [`MIN_TRUE_CLEARANCE_M`] from the true scene.
    pub collision_free: f64,
    /// Share answered `optimal`.
    pub optimal: f64,
    /// Least true clearance over the targets (m).
    pub min_true_clearance_m: f64,
    /// Median plan time (ms).
    pub plan_ms_p50: f64,
    /// 95th-percentile plan time (ms).
    pub plan_ms_p95: f64,
    /// Median points of the sensed cloud (depth only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensed_points_p50: Option<f64>,
}

/// The whole evaluation.
#[derive(Clone, Debug, Serialize)]
pub struct WorldEval {
    /// Dataset split evaluated.
    pub split: String,
    /// Targets with depth and at least one intruder, planned.
    pub targets: usize,
    /// Targets skipped (no depth, or no intruder).
    pub skipped: usize,
    /// One row per world, in [`WorldGiven::ALL`] order.
    pub rows: Vec<WorldRow>,
    /// Every plan.
    pub outcomes: Vec<WorldOutcome>,
}

/// Plan every target of `split` in `dir` that has depth and an intruder,
/// three ways, and check each plan against the true scene.
pub fn evaluate_worlds(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    dir: &Path,
    split: &str,
    progress: bool,
) -> Result<WorldEval> {
    let manifest = dataset::load_manifest(dir)?;
    let entries = manifest.split(split)?;
    let camera = manifest.camera_model();
    let scale = manifest.depth_scale_m();
    let check = Checker::new(robot)?;
    let bar = crate::progress::bar(progress, entries.len() as u64, "targets");
    let (mut outcomes, mut skipped) = (Vec::new(), 0);
    for entry in &entries {
        bar.inc(1);
        let (parts, record) = record_plan_input(dir, entry, scale, camera, ASKED_CLEARANCE_M)?;
        if parts.depth.is_none() || record.scene.intruders().is_empty() {
            skipped += 1;
            continue;
        }
        let truth = Scene::new(record.scene.obstacles())?;
        for world in WorldGiven::ALL {
            let target = Target {
                entry,
                parts: parts.clone(),
                record: &record,
            };
            outcomes.push(plan_one(model, robot, target, world, &truth, &check)?);
        }
    }
    bar.finish_and_clear();
    let rows = WorldGiven::ALL.iter().map(|w| row(*w, &outcomes)).collect();
    Ok(WorldEval {
        split: split.to_string(),
        targets: outcomes.len() / WorldGiven::ALL.len(),
        skipped,
        rows,
        outcomes,
    })
}

/// One target's plan inputs (the record's, as `dpmp plan --record` reads
/// them) and its record.
struct Target<'a> {
    entry: &'a TargetEntry,
    parts: PlanParts,
    record: &'a TargetRecord,
}

fn plan_one(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    target: Target,
    world: WorldGiven,
    truth: &Scene,
    check: &Checker,
) -> Result<WorldOutcome> {
    let Target {
        entry,
        mut parts,
        record,
    } = target;
    parts.task.obstacles = match world {
        WorldGiven::Oracle => record.scene.obstacles(),
        WorldGiven::None | WorldGiven::Depth => Vec::<Obstacle>::new(),
    };
    if world == WorldGiven::Depth {
        parts.world = WorldSource::Depth;
    }
    let request = PlanRequest::new(parts, &record_fields(entry))?;
    let started = Instant::now();
    let answer = predict_and_optimize(model, robot, request, &Default::default())?;
    let plan_ms = started.elapsed().as_secs_f64() * 1e3;
    Ok(WorldOutcome {
        target: entry.id.clone(),
        world,
        status: answer.result.status,
        true_clearance_m: check.true_clearance(truth, &answer.result.weights)?,
        sensed_points: answer.world.map(|w| w.points),
        plan_ms,
    })
}

/// The dense check against the true scene.
struct Checker {
    robot: Arc<Robot>,
    basis: Basis,
}

impl Checker {
    fn new(robot: &Arc<Robot>) -> Result<Checker> {
        let basis = Basis::new(&crate::promp::PrompConfig::default())?.resampled(CHECK_PHASES)?;
        Ok(Checker {
            robot: robot.clone(),
            basis,
        })
    }

    /// The least distance of the trajectory of joint-major `weights` to
    /// `truth` over the check phases.
    fn true_clearance(&self, truth: &Scene, weights: &[f64]) -> Result<f64> {
        let nb = self.basis.n_basis();
        let dof = self.robot.dof();
        if weights.len() != nb * dof {
            return Err(Error::Numerical(format!(
                "{} weights, expected {dof} joints x {nb}",
                weights.len()
            )));
        }
        let w = DMatrix::from_fn(nb, dof, |i, j| weights[j * nb + i]);
        let q = self.basis.matrix() * w;
        Ok((0..q.nrows())
            .filter_map(|t| {
                let row: Vec<f64> = q.row(t).iter().copied().collect();
                truth.min_clearance(&self.robot, &self.robot.fk(&row))
            })
            .map(|c| c.distance)
            .fold(f64::INFINITY, f64::min))
    }
}

fn row(world: WorldGiven, outcomes: &[WorldOutcome]) -> WorldRow {
    let mine: Vec<&WorldOutcome> = outcomes.iter().filter(|o| o.world == world).collect();
    let n = mine.len().max(1) as f64;
    let share = |f: &dyn Fn(&WorldOutcome) -> bool| mine.iter().filter(|o| f(o)).count() as f64 / n;
    let times = Percentiles::of(&mine.iter().map(|o| o.plan_ms).collect::<Vec<_>>());
    let points: Vec<f64> = mine
        .iter()
        .filter_map(|o| o.sensed_points.map(|p| p as f64))
        .collect();
    WorldRow {
        world,
        targets: mine.len(),
        collision_free: share(&|o| o.true_clearance_m >= MIN_TRUE_CLEARANCE_M),
        optimal: share(&|o| o.status == Status::Optimal),
        min_true_clearance_m: mine
            .iter()
            .map(|o| o.true_clearance_m)
            .fold(f64::INFINITY, f64::min),
        plan_ms_p50: times.p50,
        plan_ms_p95: times.p95,
        sensed_points_p50: (!points.is_empty()).then(|| Percentiles::of(&points).p50),
    }
}

/// The table as Markdown.
pub fn markdown(eval: &WorldEval) -> String {
    let mut out = format!(
        "| world given to the planner | collision-free vs the true scene (≥ {:.0} mm, {:.0} mm asked) | `optimal` | least true clearance | plan time p50 / p95 |\n|---|---|---|---|---|\n",
        MIN_TRUE_CLEARANCE_M * 1e3,
        ASKED_CLEARANCE_M * 1e3
    );
    for r in &eval.rows {
        out += &format!(
            "| {} | {:.1} % | {:.1} % | {:.1} mm | {:.0} / {:.0} ms |\n",
            r.world.name(),
            100.0 * r.collision_free,
            100.0 * r.optimal,
            r.min_true_clearance_m * 1e3,
            r.plan_ms_p50,
            r.plan_ms_p95
        );
    }
    out
}
