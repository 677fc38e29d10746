//! The optimise request (DESIGN.md's JSON contract), its solver knobs and
//! limits, and (`validate`) its validation into a [`Problem`](super::Problem).

mod validate;

pub use validate::check_prior;

pub use super::report::TrajectoryFormat;
use crate::promp::annotation::JointAnnotation;
use crate::promp::PrompConfig;
use crate::scene::Obstacle;
use serde::{Deserialize, Serialize};

/// Largest accepted number of obstacles.
pub const MAX_OBSTACLES: usize = 1000;
/// Largest accepted `samples`.
pub const MAX_EXTRA_SAMPLES: usize = 100;
/// Largest accepted `promp.n_samples`.
pub const MAX_PHASE_SAMPLES: usize = 2000;
/// Default distance beyond `clearance_m` within which pairs are linearised.
pub const DEFAULT_ACTIVATION_MARGIN_M: f64 = 0.01;
/// Largest accepted `options.restarts`.
pub const MAX_RESTARTS: usize = 32;
/// Largest accepted `options.max_iterations` (of the run from the prior
/// mean; each restart adds at most `restart::RESTART_MAX_ITERATIONS`).
pub const MAX_ITERATIONS: usize = 1000;
/// Largest accepted `duration_s`.
pub const MAX_DURATION_S: f64 = 600.0;

/// An optimise request (`POST /v1/optimize`, `dpmp optimize`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizeRequest {
    /// The prior over the weights.
    pub prior: PriorSpec,
    /// Basis settings (`n_basis` must match the prior).
    #[serde(default)]
    pub promp: PrompConfig,
    /// Duration of the motion (s), for the velocity limits and timestamps.
    #[serde(default = "default_duration")]
    pub duration_s: f64,
    /// Required configuration at t = 0.
    #[serde(default)]
    pub start: Option<Vec<f64>>,
    /// Required TCP position at the end.
    #[serde(default)]
    pub goal: Option<Goal>,
    /// The scene.
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// Required robot-obstacle clearance (m).
    #[serde(default = "default_clearance")]
    pub clearance_m: f64,
    /// Margin kept inside each joint limit (rad).
    #[serde(default)]
    pub joint_limit_margin_rad: f64,
    /// Number of extra feasible trajectories to return.
    #[serde(default)]
    pub samples: usize,
    /// Solver knobs.
    #[serde(default)]
    pub options: SolverOptions,
    /// How the answer writes the trajectory (`dpmp` or `ros2`).
    #[serde(default, skip_serializing_if = "TrajectoryFormat::is_default")]
    pub trajectory_format: TrajectoryFormat,
    /// Velocity and acceleration at both ends: `rest` (zero; the default,
    /// what a Franka needs) or `free`.
    #[serde(default)]
    pub boundary: Boundary,
    /// Per-joint acceleration limits (rad/s²); default: the robot's
    /// (`joint_limits.yaml` beside its URDF).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceleration_limits: Option<Vec<f64>>,
    /// Per-joint jerk limits (rad/s³); default: the robot's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jerk_limits: Option<Vec<f64>>,
    /// Factor in (0, 1] on every velocity limit (MoveIt's
    /// `max_velocity_scaling_factor`).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub velocity_scaling: f64,
    /// Factor in (0, 1] on every acceleration limit (MoveIt's
    /// `max_acceleration_scaling_factor`); jerk limits are not scaled.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub acceleration_scaling: f64,
}

/// Velocity and acceleration at the start and the end of the motion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Boundary {
    /// Zero velocity and acceleration at both ends: the motion starts from
    /// and comes to a standstill, as libfranka and ros2_control require of
    /// a commanded motion.
    #[default]
    Rest,
    /// Whatever velocity and acceleration the weights give.
    Free,
}

fn one() -> f64 {
    1.0
}
fn is_one(v: &f64) -> bool {
    *v == 1.0
}

fn default_duration() -> f64 {
    4.0
}
fn default_clearance() -> f64 {
    0.02
}
fn default_tolerance() -> f64 {
    0.01
}

/// The prior: a full Gaussian or the paper's per-joint annotation.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PriorSpec {
    /// `{"mean": [...], "cov": [[...]]}`, joint-major.
    Full {
        /// Mean weights.
        mean: Vec<f64>,
        /// Covariance rows.
        cov: Vec<Vec<f64>>,
    },
    /// `{"annotation": [7 x {"mean_weights", "L"}]}`.
    Annotation {
        /// One entry per joint.
        annotation: Vec<JointAnnotation>,
    },
}

impl From<&crate::promp::WeightDistribution> for PriorSpec {
    /// The full Gaussian of a weight distribution (joint-major).
    fn from(dist: &crate::promp::WeightDistribution) -> Self {
        let crate::promp::distribution::DistributionJson { mean, cov } = dist.into();
        PriorSpec::Full { mean, cov }
    }
}

/// Goal: TCP position at the end of the motion and, optionally, the
/// direction the gripper approaches from.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Goal {
    /// Target TCP position in the base frame (m).
    pub position: [f64; 3],
    /// Allowed distance (m).
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
    /// Unit vector in the base frame: the gripper's z axis (the direction
    /// the fingers point) at the end must lie within
    /// `approach_tolerance_rad` of it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach_axis: Option<[f64; 3]>,
    /// Allowed angle (rad) between the gripper's z axis and
    /// `approach_axis`, in (0, π].
    #[serde(
        default = "default_approach_tolerance",
        skip_serializing_if = "is_default_approach_tolerance"
    )]
    pub approach_tolerance_rad: f64,
}

impl Goal {
    /// A position goal within `tolerance_m`, no approach direction.
    pub fn at(position: [f64; 3], tolerance_m: f64) -> Goal {
        Goal {
            position,
            tolerance_m,
            approach_axis: None,
            approach_tolerance_rad: DEFAULT_APPROACH_TOLERANCE_RAD,
        }
    }
}

/// Default `goal.approach_tolerance_rad`: 10°.
pub const DEFAULT_APPROACH_TOLERANCE_RAD: f64 = std::f64::consts::PI / 18.0;

fn default_approach_tolerance() -> f64 {
    DEFAULT_APPROACH_TOLERANCE_RAD
}
fn is_default_approach_tolerance(v: &f64) -> bool {
    *v == DEFAULT_APPROACH_TOLERANCE_RAD
}

/// Solver knobs; every field is optional in JSON.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SolverOptions {
    /// Whitening regularisation `λ` in `Σ + λI` (default: 1e-6 x the mean
    /// prior variance).
    pub lambda: Option<f64>,
    /// Largest number of SCP iterations (QPs).
    pub max_iterations: usize,
    /// Robot-obstacle pairs closer than this (m) are linearised (default:
    /// `clearance_m + 0.01`); must be >= `clearance_m`.
    pub activation_distance_m: Option<f64>,
    /// Dense verification samples per optimisation sample (>= 4).
    pub verify_factor: usize,
    /// Seed of the prior draws for `samples` and for `restarts`.
    pub seed: u64,
    /// Restarts from seeded prior draws when the run from the prior mean
    /// ends without a feasible solution (0..=32; 0 disables them).
    pub restarts: usize,
    /// Opt-in: also bound every weight by its joint's limits (guarantees
    /// the limits at every phase, but real priors' weights lie far outside
    /// the limits, so this usually makes them infeasible).
    pub bound_weights: bool,
    /// Initial trust-region half-width on the whitened weights.
    pub trust_region: f64,
    /// Initial L1 penalty on constraint slacks.
    pub penalty: f64,
    /// Clarabel's tolerances.
    pub qp_tolerance: f64,
    /// Optional final configuration as an equality (for conditioning-style
    /// requests and tests).
    pub final_configuration: Option<Vec<f64>>,
    /// Which solver takes the intermediate SCP iterations; the final QP
    /// of an `optimal` answer is Clarabel's either way.
    pub inner_solver: InnerSolver,
}

/// The solver of the intermediate SCP iterations.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum InnerSolver {
    /// The warm-started dual active-set method (default; about 100x
    /// cheaper per QP).
    #[default]
    ActiveSet,
    /// Clarabel for every QP (the reference the benchmark compares with).
    Clarabel,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            lambda: None,
            max_iterations: 100,
            activation_distance_m: None,
            verify_factor: 4,
            seed: 0,
            restarts: 4,
            bound_weights: false,
            trust_region: 1.0,
            penalty: 1e3,
            qp_tolerance: 1e-8,
            final_configuration: None,
            inner_solver: InnerSolver::default(),
        }
    }
}
