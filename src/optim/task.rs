//! What a request asks of the trajectory besides its prior: the [`Goal`],
//! the [`Boundary`] conditions, the [`SolverOptions`], and the bounds their
//! fields are checked against. The solver reads these types; the request
//! ([`super::request`]) carries them in its JSON.

use serde::{Deserialize, Serialize};

/// Default distance beyond `clearance_m` within which pairs are linearised.
pub const DEFAULT_ACTIVATION_MARGIN_M: f64 = 0.01;
/// Largest accepted `options.restarts`.
pub const MAX_RESTARTS: usize = 32;
/// Largest accepted `options.max_iterations` (of the run from the prior
/// mean; each restart adds at most `restart::RESTART_MAX_ITERATIONS`).
pub const MAX_ITERATIONS: usize = 1000;
/// Largest accepted `duration_s`.
pub const MAX_DURATION_S: f64 = 600.0;
/// Largest accepted number of `via_points`.
pub const MAX_VIA_POINTS: usize = 32;

/// Most joints a request may describe (prior annotation entries, the length
/// of every joint vector), checked while it is read.
pub const MAX_JOINTS: usize = 64;

/// A point the trajectory passes at a given time: a configuration
/// (exactly by default: ProMP via-point conditioning, an equality of the
/// optimisation, so with nothing else binding the answer is the prior
/// conditioned on it and on the start, in closed form; or every joint
/// within `tolerance_rad`, linear rows) or a TCP position (within
/// `tolerance_m`, linearised like the goal).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Waypoint {
    /// When, as a fraction of the motion's duration, in (0, 1); give this
    /// or `time_s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase: Option<f64>,
    /// When, in seconds from the start, in (0, `duration_s`); give this or
    /// `phase`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
    /// The joint positions (rad) at that time, one per joint; give this or
    /// `position`.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "crate::strict_json::option_vec_at_most::<_, _, MAX_JOINTS>"
    )]
    pub configuration: Option<Vec<f64>>,
    /// The TCP position (m, base frame) at that time; give this or
    /// `configuration`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 3]>,
    /// Allowed distance (m) from `position` (default
    /// [`DEFAULT_WAYPOINT_TOLERANCE_M`]); only with `position`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_m: Option<f64>,
    /// Allowed difference (rad) of every joint from `configuration`
    /// (default 0: exactly, by conditioning); only with `configuration`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_rad: Option<f64>,
}

impl Waypoint {
    /// Whether the waypoint is a configuration met exactly (an equality).
    pub fn is_exact_configuration(&self) -> bool {
        self.configuration.is_some() && self.tolerance_rad.is_none_or(|t| t == 0.0)
    }
}

/// Default `via_points[i].tolerance_m` of a position (m).
pub const DEFAULT_WAYPOINT_TOLERANCE_M: f64 = 0.005;

impl Waypoint {
    /// The waypoint's phase for a motion of `duration_s` (`phase`, else
    /// `time_s / duration_s`; NaN when neither is given).
    pub fn phase_for(&self, duration_s: f64) -> f64 {
        self.phase
            .or(self.time_s.map(|t| t / duration_s))
            .unwrap_or(f64::NAN)
    }
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

impl Goal {
    /// This goal approached along `approach` (none: as it is).
    pub fn with_approach(mut self, approach: Option<&GoalApproach>) -> Goal {
        if let Some(a) = approach {
            self.approach_axis = Some(a.approach_axis);
            self.approach_tolerance_rad = a.approach_tolerance_rad;
        }
        self
    }

    /// The goal's approach direction, if it has one.
    pub fn approach(&self) -> Option<GoalApproach> {
        self.approach_axis.map(|approach_axis| GoalApproach {
            approach_axis,
            approach_tolerance_rad: self.approach_tolerance_rad,
        })
    }
}

/// The direction a [`Goal`] is approached from: the gripper's z axis at the
/// end within `approach_tolerance_rad` of `approach_axis` (a goal's own two
/// fields). `/v1/plan` and `dpmp plan` take it alone when the goal's
/// position is derived from the 3-D target (a `goal` without `position`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalApproach {
    /// Unit vector in the base frame.
    pub approach_axis: [f64; 3],
    /// Allowed angle (rad).
    #[serde(default = "default_approach_tolerance")]
    pub approach_tolerance_rad: f64,
}

/// Default `goal.approach_tolerance_rad`: 10°.
pub const DEFAULT_APPROACH_TOLERANCE_RAD: f64 = std::f64::consts::PI / 18.0;

fn default_approach_tolerance() -> f64 {
    DEFAULT_APPROACH_TOLERANCE_RAD
}
fn is_default_approach_tolerance(v: &f64) -> bool {
    *v == DEFAULT_APPROACH_TOLERANCE_RAD
}

/// Default `goal.tolerance_m` (m).
pub const DEFAULT_GOAL_TOLERANCE_M: f64 = 0.01;

fn default_tolerance() -> f64 {
    DEFAULT_GOAL_TOLERANCE_M
}

/// Solver knobs; every field is optional in JSON.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SolverOptions {
    /// Whitening regularisation `λ` in `Σ + λI` (default: 0 for a
    /// well-conditioned prior, else 1e-6 x the mean prior variance; see
    /// [`Whitening::default_lambda`](crate::optim::problem::whiten::Whitening::default_lambda)).
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
    #[serde(deserialize_with = "crate::strict_json::option_vec_at_most::<_, _, MAX_JOINTS>")]
    pub final_configuration: Option<Vec<f64>>,
    /// Which solver takes the intermediate SCP iterations; the final QP
    /// of an `optimal` answer is Clarabel's either way.
    pub inner_solver: InnerSolver,
    /// With the smoothness prior on its default basis: when the solve
    /// finds no certified answer, solve again on finer bases
    /// ([`crate::optim::finer_basis`]; default true, written only when
    /// false).
    #[serde(skip_serializing_if = "is_true")]
    pub refine_basis: bool,
}

fn is_true(v: &bool) -> bool {
    *v
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
            refine_basis: true,
        }
    }
}
