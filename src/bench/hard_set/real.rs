//! The real-prior hard set behind `dpmp bench make-problems --set hard-real
//! --annotations DIR`: the hard set's intruders beside the demonstrated
//! path, on the paper's real annotation priors (25 targets, 10 kinesthetic
//! demonstrations each) instead of the generator's.
//!
//! Real priors are narrower, near-singular and elbow-branched where the
//! synthetic ones are not, so the optimiser's success on them is measured
//! on its own set. Problem `i` takes target `i mod n` of the `n` targets
//! read, its rounded annotation embedded in the request (the files need
//! nothing outside themselves), starts at the prior mean's start, and has
//! its goal at the mean's final TCP position (the pre-grasp point, 1 cm
//! tolerance, 1.5 cm clearance). The goal is a position, so the prior
//! mean's final pose need not clear the intruders (another wrist pose may
//! reach the goal; the long search decides); its start pose and the goal
//! point must. Its family is `(i / n) mod 4`:
//!
//! | family | intruders | radius (cm) | offset from the mean TCP path (cm) | phase |
//! |---|---|---|---|---|
//! | `near` | 1 | 1.2–2.5 | 3–4.5 | 0.3–0.7 |
//! | `wide` | 1 | 1.2–2.5 | 4.5–6.5 | 0.2–0.8 |
//! | `pair` | 2 | 1.2–2.0 | 3–5.5 | 0.2–0.8 |
//! | `plant` | 1 + the plant's other berries | 1.2–2.5 | 3–5.5 | 0.3–0.7 |
//!
//! `plant` adds the other targets of the same plant configuration as
//! berries (1.5 cm radius at their prior mean's final TCP) when they keep
//! the mean's ends and goal clear. A draw is kept when the obstacles block
//! the prior mean with its ends clear ([`super::with_intruders`]), and
//! labelled by the same long search as the hard set
//! ([`super::long_search_label`]).

use super::{
    hard_file, keeps_ends_clear, make_set, mean_path, with_intruders, HardSettings, IntruderRanges,
    MeanPath, HARD_CLEARANCE_M, HARD_GOAL_TOLERANCE_M,
};
use crate::bench::make_problems::round_significant;
use crate::bench::problem_file::{Meta, ProblemFile, HARD_CATEGORY};
use crate::geometry::Sphere;
use crate::optim::OptimizeRequest;
use crate::promp::annotation::{read_joints, JointAnnotation};
use crate::robot::Robot;
use crate::scene::{Obstacle, ObstacleShape};
use crate::{Error, Result};
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};
use std::path::Path;

/// Generator name written into every file's `meta.generator`.
pub const REAL_GENERATOR: &str = "dpmp bench make-problems --set hard-real v1";
/// Duration of every motion (s).
pub const REAL_DURATION_S: f64 = 4.0;
/// Radius of the plant's other berries in the `plant` family (m).
pub const NEIGHBOUR_RADIUS_M: f64 = 0.015;
/// Targets per plant configuration in the paper's annotations.
pub const TARGETS_PER_CONFIGURATION: usize = 5;
/// Draws tried per problem before its seed is given up.
const ATTEMPTS: u64 = 64;

/// One family of the set: how many intruders, drawn where, and whether the
/// plant's other berries stand too.
#[derive(Clone, Copy, Debug)]
pub struct Family {
    /// Name written into the file's description.
    pub name: &'static str,
    /// Number of intruders.
    pub intruders: usize,
    /// Where they are drawn.
    pub ranges: IntruderRanges,
    /// Whether the plant configuration's other berries are obstacles too.
    pub neighbours: bool,
}

/// The set's families, in the order problems cycle through them.
pub const FAMILIES: [Family; 4] = [
    Family {
        name: "near",
        intruders: 1,
        ranges: IntruderRanges {
            radius_m: (0.012, 0.025),
            offset_m: (0.03, 0.045),
            phases: (0.3, 0.7),
            final_pose_clear: false,
        },
        neighbours: false,
    },
    Family {
        name: "wide",
        intruders: 1,
        ranges: IntruderRanges {
            radius_m: (0.012, 0.025),
            offset_m: (0.045, 0.065),
            phases: (0.2, 0.8),
            final_pose_clear: false,
        },
        neighbours: false,
    },
    Family {
        name: "pair",
        intruders: 2,
        ranges: IntruderRanges {
            radius_m: (0.012, 0.02),
            offset_m: (0.03, 0.055),
            phases: (0.2, 0.8),
            final_pose_clear: false,
        },
        neighbours: false,
    },
    Family {
        name: "plant",
        intruders: 1,
        ranges: IntruderRanges {
            radius_m: (0.012, 0.025),
            offset_m: (0.03, 0.055),
            phases: (0.3, 0.7),
            final_pose_clear: false,
        },
        neighbours: true,
    },
];

/// The annotations of every target in `dir` (`J1/0.json`, `J1/1.json`, ...
/// up to the first index missing), each number rounded as the problem
/// files store it, so that a set regenerated from its own files is the
/// same set.
pub fn load_targets(dir: &Path) -> Result<Vec<Vec<JointAnnotation>>> {
    let targets: Vec<Vec<JointAnnotation>> = (0..)
        .take_while(|k| dir.join("J1").join(format!("{k}.json")).is_file())
        .map(|k| read_joints(dir, k).map(|joints| round_joints(&joints)))
        .collect::<Result<_>>()?;
    if targets.is_empty() {
        return Err(Error::file(dir, "no annotation J1/0.json found"));
    }
    Ok(targets)
}

/// `joints` with every number rounded to the problem files' precision.
pub fn round_joints(joints: &[JointAnnotation]) -> Vec<JointAnnotation> {
    let round = |v: &[f64]| v.iter().map(|&x| round_significant(x)).collect();
    joints
        .iter()
        .map(|j| JointAnnotation {
            mean_weights: round(&j.mean_weights),
            l: round(&j.l),
        })
        .collect()
}

/// Generate `settings.count` real-prior hard problems on the rayon pool,
/// deterministic in `settings.seed`, as the module docs say.
pub fn make_real_set(
    robot: &Robot,
    targets: &[Vec<JointAnnotation>],
    settings: &HardSettings,
) -> Result<Vec<ProblemFile>> {
    make_set(settings, "real-prior problems", |i, seed| {
        make_real_one(robot, targets, i, seed, settings.label)
    })
}

/// Problem `i` of the real-prior set from its own `seed`.
pub fn make_real_one(
    robot: &Robot,
    targets: &[Vec<JointAnnotation>],
    i: usize,
    seed: u64,
    label: bool,
) -> Result<ProblemFile> {
    let target = i % targets.len();
    let family = FAMILIES[(i / targets.len()) % FAMILIES.len()];
    let base = base_request(robot, targets, target, family.neighbours)?;
    for attempt in 0..ATTEMPTS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(6151).wrapping_add(attempt));
        let Some(request) = with_intruders(
            robot,
            base.clone(),
            family.intruders,
            &family.ranges,
            &mut rng,
        )?
        else {
            continue;
        };
        let meta = Meta {
            generator: REAL_GENERATOR.to_string(),
            seed,
            category: HARD_CATEGORY.to_string(),
            description: format!(
                "real prior #{target} ({}) + {} intruder(s) beside the mean path",
                family.name, family.intruders
            ),
            reference_final_tcp: None,
        };
        return hard_file(format!("real-{i:03}"), &request, label, robot, meta);
    }
    Err(Error::Numerical(format!(
        "real-prior problem {i} (seed {seed}): no draw blocked the prior mean in {ATTEMPTS} attempts"
    )))
}

/// Target `target`'s request before its intruders: its annotation prior,
/// the mean's start, the goal at the mean's final TCP, and with
/// `neighbours` the plant's other berries.
fn base_request(
    robot: &Robot,
    targets: &[Vec<JointAnnotation>],
    target: usize,
    neighbours: bool,
) -> Result<Value> {
    let bare = json!({
        "prior": {"annotation": targets[target]},
        "duration_s": REAL_DURATION_S,
        "clearance_m": HARD_CLEARANCE_M,
        "boundary": "rest",
    });
    let own = target_mean_path(robot, &bare)?;
    let goal = *own.tcp.last().ok_or_else(|| {
        Error::Numerical(format!("target {target}: the prior mean has no samples"))
    })?;
    let obstacles = if neighbours {
        neighbour_berries(robot, targets, target, &bare, &own, goal)?
    } else {
        Vec::new()
    };
    let mut request = bare;
    request["start"] = json!(own.start);
    request["goal"] =
        json!({"position": [goal.x, goal.y, goal.z], "tolerance_m": HARD_GOAL_TOLERANCE_M});
    request["obstacles"] = serde_json::to_value(obstacles)
        .map_err(|e| Error::Numerical(format!("cannot serialise obstacles: {e}")))?;
    Ok(request)
}

/// The other targets of `target`'s plant configuration as berries at their
/// prior mean's final TCP, each kept when it leaves `target`'s mean ends
/// and goal clear.
fn neighbour_berries(
    robot: &Robot,
    targets: &[Vec<JointAnnotation>],
    target: usize,
    bare: &Value,
    own: &MeanPath,
    goal: Vector3<f64>,
) -> Result<Vec<Obstacle>> {
    let configuration = target / TARGETS_PER_CONFIGURATION;
    let mut berries = Vec::new();
    for other in (0..targets.len())
        .filter(|&k| k != target && k / TARGETS_PER_CONFIGURATION == configuration)
    {
        let mut request = bare.clone();
        request["prior"] = json!({"annotation": targets[other]});
        let Some(&centre) = target_mean_path(robot, &request)?.tcp.last() else {
            continue;
        };
        let berry = Obstacle {
            id: format!("berry-{other}"),
            shape: ObstacleShape::Sphere(Sphere {
                center: centre.into(),
                radius: NEIGHBOUR_RADIUS_M,
            }),
        };
        if keeps_ends_clear(
            robot,
            own,
            Some(goal),
            &berry,
            (centre, NEIGHBOUR_RADIUS_M),
            true,
        )? {
            berries.push(berry);
        }
    }
    Ok(berries)
}

/// The prior mean's path of `request`.
fn target_mean_path(robot: &Robot, request: &Value) -> Result<MeanPath> {
    let parsed: OptimizeRequest = serde_json::from_value(request.clone())
        .map_err(|e| Error::invalid("request", format!("does not parse: {e}")))?;
    let problem = parsed.validate(robot)?;
    Ok(mean_path(robot, problem.basis(), problem.prior()))
}
