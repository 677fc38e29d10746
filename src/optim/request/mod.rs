//! The optimise request (DESIGN.md's JSON contract): the prior and the task
//! ([`super::task`]'s goal, boundary and solver knobs), the request's size
//! limits, and (`validate`) its validation into a [`Problem`](super::Problem).

mod prior;
mod validate;

pub use prior::MAX_WEIGHTS;

pub use validate::check_prior;
pub(crate) use validate::validate_spec;

pub use super::report::TrajectoryFormat;
use super::task::{Boundary, Goal, SolverOptions, Waypoint, MAX_JOINTS, MAX_VIA_POINTS};
use crate::promp::annotation::JointAnnotation;
use crate::promp::PrompConfig;
use crate::scene::Obstacle;
use serde::{Deserialize, Serialize};

/// Largest accepted number of obstacles.
pub const MAX_OBSTACLES: usize = 1000;
/// Largest number of cloud points (`points` obstacles) in one request.
pub const MAX_REQUEST_POINTS: usize = 200_000;
/// Largest accepted `samples`.
pub const MAX_EXTRA_SAMPLES: usize = 100;
/// Largest accepted `promp.n_samples`.
pub const MAX_PHASE_SAMPLES: usize = 2000;
/// An optimise request (`POST /v1/optimize`, `dpmp optimize`): the prior
/// beside the [`Task`]'s fields, one flat JSON object on the wire.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(from = "WireRequest")]
pub struct OptimizeRequest {
    /// The prior over the weights.
    pub prior: PriorSpec,
    /// Everything else: scene, limits, start, goal, boundary, options.
    #[serde(flatten)]
    pub task: Task,
}

/// Declares [`Task`] and the private `WireRequest` (`prior` beside the
/// same fields) from one field list: the wire request is derived, so every
/// field error keeps its JSON path, and `deny_unknown_fields` holds (serde's
/// `flatten` would lose both).
macro_rules! task_and_wire_request {
    (
        $(#[$meta:meta])*
        pub struct Task { $( $(#[$fmeta:meta])* pub $field:ident : $ty:ty, )* }
    ) => {
        $(#[$meta])*
        pub struct Task {
            /// Basis settings (`n_basis` must match the prior; default: the
            /// paper's, or with the smooth prior
            /// [`smooth_basis_config`](crate::promp::smooth::smooth_basis_config)).
            #[serde(default)]
            pub promp: PrompConfig,
            $( $(#[$fmeta])* pub $field: $ty, )*
        }

        /// An [`OptimizeRequest`] as it is on the wire: without a `prior`
        /// the smooth one, and without `promp` the basis that suits the
        /// prior ([`PriorSpec::default_basis`]).
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct WireRequest {
            #[serde(default)]
            prior: PriorSpec,
            #[serde(default)]
            promp: Option<PrompConfig>,
            $( $(#[$fmeta])* $field: $ty, )*
        }

        impl From<WireRequest> for OptimizeRequest {
            fn from(w: WireRequest) -> Self {
                let promp = w.promp.unwrap_or_else(|| w.prior.default_basis());
                OptimizeRequest {
                    prior: w.prior,
                    task: Task { promp, $( $field: w.$field, )* },
                }
            }
        }
    };
}

task_and_wire_request! {
    /// What to plan, apart from the prior: the request without its `prior`
    /// (`dpmp plan --task FILE`, and the fields of `/v1/plan` the optimiser
    /// reads). Every field is optional in JSON.
    #[derive(Clone, Debug, Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Task {
        /// Duration of the motion (s), for the velocity limits and timestamps.
        #[serde(default = "default_duration")]
        pub duration_s: f64,
        /// Required configuration at t = 0.
        #[serde(default, deserialize_with = "crate::strict_json::option_vec_at_most::<_, _, MAX_JOINTS>")]
        pub start: Option<Vec<f64>>,
        /// Required TCP position at the end.
        #[serde(default)]
        pub goal: Option<Goal>,
        /// Configurations the trajectory passes through (exactly) on its way.
        #[serde(
            default,
            skip_serializing_if = "Vec::is_empty",
            deserialize_with = "crate::strict_json::vec_at_most::<_, _, MAX_VIA_POINTS>"
        )]
        pub via_points: Vec<Waypoint>,
        /// The scene.
        #[serde(
            default,
            deserialize_with = "crate::strict_json::vec_at_most::<_, _, MAX_OBSTACLES>"
        )]
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
        #[serde(
            default,
            skip_serializing_if = "Option::is_none",
            deserialize_with = "crate::strict_json::option_vec_at_most::<_, _, MAX_JOINTS>"
        )]
        pub acceleration_limits: Option<Vec<f64>>,
        /// Per-joint jerk limits (rad/s³); default: the robot's.
        #[serde(
            default,
            skip_serializing_if = "Option::is_none",
            deserialize_with = "crate::strict_json::option_vec_at_most::<_, _, MAX_JOINTS>"
        )]
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
}

impl Default for Task {
    /// The task of a JSON object without fields (`{}`).
    fn default() -> Self {
        Task {
            promp: PrompConfig::default(),
            duration_s: default_duration(),
            start: None,
            goal: None,
            via_points: Vec::new(),
            obstacles: Vec::new(),
            clearance_m: default_clearance(),
            joint_limit_margin_rad: 0.0,
            samples: 0,
            options: SolverOptions::default(),
            trajectory_format: TrajectoryFormat::default(),
            boundary: Boundary::default(),
            acceleration_limits: None,
            jerk_limits: None,
            velocity_scaling: one(),
            acceleration_scaling: one(),
        }
    }
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
/// The prior: a full Gaussian, the paper's per-joint annotation (read
/// by `prior`: exactly one form, lengths capped), or the smoothness prior
/// (`"smooth"`, also what a request without a prior gets).
#[derive(Clone, Debug, Default, Serialize)]
#[serde(untagged)]
pub enum PriorSpec {
    /// `"smooth"`: the integrated squared acceleration, conditioned on the
    /// start, the final configuration (when given) and the boundary
    /// ([`crate::promp::smooth`]).
    #[default]
    #[serde(serialize_with = "serialize_smooth")]
    Smooth,
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

/// The smooth prior's wire name.
pub const SMOOTH_PRIOR: &str = "smooth";

fn serialize_smooth<S: serde::Serializer>(serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(SMOOTH_PRIOR)
}

impl PriorSpec {
    /// The basis a request with this prior and no `promp` uses: the
    /// paper's, or for the smooth prior one that can bend more
    /// ([`crate::promp::smooth::smooth_basis_config`]).
    pub fn default_basis(&self) -> PrompConfig {
        match self {
            PriorSpec::Smooth => crate::promp::smooth::smooth_basis_config(),
            _ => PrompConfig::default(),
        }
    }
}

impl From<&crate::promp::WeightDistribution> for PriorSpec {
    /// The full Gaussian of a weight distribution (joint-major).
    fn from(dist: &crate::promp::WeightDistribution) -> Self {
        let crate::promp::distribution::DistributionJson { mean, cov } = dist.into();
        PriorSpec::Full { mean, cov }
    }
}
