//! What the optimiser answers: the response, its ROS-shaped trajectory and
//! the dense-verification report (field names are DESIGN.md's contract).

use super::qp::ClarabelInfo;
use serde::Serialize;

/// Outcome of a solve.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Every constraint holds under dense verification and the SCP converged.
    Optimal,
    /// A constraint cannot be met (see `reason`).
    Infeasible,
    /// Stopped by the iteration limit, the deadline or a cancel request
    /// before converging (see `reason` and the warnings).
    MaxIterations,
}

impl Status {
    /// The name as the JSON writes it (`optimal`, `infeasible`,
    /// `max_iterations`).
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Optimal => "optimal",
            Status::Infeasible => "infeasible",
            Status::MaxIterations => "max_iterations",
        }
    }
}

/// How a trajectory is written in JSON (the request's `trajectory_format`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrajectoryFormat {
    /// `{joint_names, points: [{positions, velocities, time_from_start: s}]}`.
    #[default]
    Dpmp,
    /// Exactly as ROS 2 serialises `trajectory_msgs/msg/JointTrajectory`:
    /// `header`, `joint_names`, points with `positions`, `velocities`,
    /// `accelerations`, `effort: []` and `time_from_start: {sec, nanosec}`.
    Ros2,
}

impl TrajectoryFormat {
    /// Whether this is the default (`dpmp`), which requests leave out.
    pub fn is_default(&self) -> bool {
        *self == TrajectoryFormat::Dpmp
    }
}

/// A joint trajectory, shaped like ROS `trajectory_msgs/JointTrajectory`;
/// written as [`TrajectoryFormat`] says.
#[derive(Clone, Debug, PartialEq)]
pub struct JointTrajectory {
    /// Actuated joints, base to tip.
    pub joint_names: Vec<String>,
    /// One point per phase of the request's sampling.
    pub points: Vec<TrajectoryPoint>,
    /// How it is written.
    pub format: TrajectoryFormat,
}

/// One point of a [`JointTrajectory`].
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryPoint {
    /// Joint positions (rad).
    pub positions: Vec<f64>,
    /// Joint velocities (rad/s).
    pub velocities: Vec<f64>,
    /// Joint accelerations (rad/s²); computed and written for the ROS 2
    /// format only (empty otherwise).
    pub accelerations: Vec<f64>,
    /// Seconds from the start of the motion.
    pub time_from_start: f64,
}

/// `builtin_interfaces/Duration` (and `Time`): whole seconds and the
/// nanoseconds beyond them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct RosDuration {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds, `0..1e9`.
    pub nanosec: u32,
}

impl RosDuration {
    /// The duration of `seconds` (>= 0), rounded to the nanosecond.
    pub fn from_seconds(seconds: f64) -> RosDuration {
        let total = (seconds.max(0.0) * 1e9).round() as u64;
        RosDuration {
            sec: (total / 1_000_000_000) as i32,
            nanosec: (total % 1_000_000_000) as u32,
        }
    }
}

#[derive(Serialize)]
struct DpmpPoint<'a> {
    positions: &'a [f64],
    velocities: &'a [f64],
    time_from_start: f64,
}

#[derive(Serialize)]
struct DpmpTrajectory<'a> {
    joint_names: &'a [String],
    points: Vec<DpmpPoint<'a>>,
}

#[derive(Serialize)]
struct Ros2Header {
    stamp: RosDuration,
    frame_id: &'static str,
}

#[derive(Serialize)]
struct Ros2Point<'a> {
    positions: &'a [f64],
    velocities: &'a [f64],
    accelerations: &'a [f64],
    effort: [f64; 0],
    time_from_start: RosDuration,
}

#[derive(Serialize)]
struct Ros2Trajectory<'a> {
    header: Ros2Header,
    joint_names: &'a [String],
    points: Vec<Ros2Point<'a>>,
}

impl Serialize for JointTrajectory {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self.format {
            TrajectoryFormat::Dpmp => DpmpTrajectory {
                joint_names: &self.joint_names,
                points: self
                    .points
                    .iter()
                    .map(|p| DpmpPoint {
                        positions: &p.positions,
                        velocities: &p.velocities,
                        time_from_start: p.time_from_start,
                    })
                    .collect(),
            }
            .serialize(serializer),
            TrajectoryFormat::Ros2 => Ros2Trajectory {
                // A zero stamp: "start when received" for ROS 2 controllers.
                header: Ros2Header {
                    stamp: RosDuration { sec: 0, nanosec: 0 },
                    frame_id: "",
                },
                joint_names: &self.joint_names,
                points: self
                    .points
                    .iter()
                    .map(|p| Ros2Point {
                        positions: &p.positions,
                        velocities: &p.velocities,
                        accelerations: &p.accelerations,
                        effort: [],
                        time_from_start: RosDuration::from_seconds(p.time_from_start),
                    })
                    .collect(),
            }
            .serialize(serializer),
        }
    }
}

/// The closest robot-obstacle pair over the verified trajectory.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Closest {
    /// Robot link name.
    pub link: String,
    /// Obstacle id.
    pub obstacle: String,
    /// Time of the closest approach (s).
    pub time_s: f64,
}

/// Dense verification of one trajectory.
///
/// `solve_ms` is wall-clock time and is the only field that may differ
/// between two runs of the same request.
#[derive(Clone, Debug, Serialize, PartialEq, Default)]
pub struct TrajectoryReport {
    /// Smallest signed robot-obstacle distance (m); `None` without obstacles.
    pub min_clearance_m: Option<f64>,
    /// Where that distance occurs.
    pub closest: Option<Closest>,
    /// Lower bound (m) on the clearance over the whole continuous motion,
    /// between the verification samples too ([`super::verify::continuous`]);
    /// `None` without obstacles. `optimal` requires it to meet
    /// `clearance_m`.
    pub continuous_clearance_m: Option<f64>,
    /// Largest bound (m) on how far the robot can approach an obstacle
    /// between two accepted samples (half their displacement bound).
    pub continuous_margin_m: Option<f64>,
    /// Largest excursion beyond the joint limits minus the requested margin
    /// (rad, 0 when inside), at the dense samples and at every joint's
    /// peaks and troughs between them ([`crate::optim::verify::limits`]).
    pub max_joint_limit_violation_rad: f64,
    /// Largest `|dq/dt| / v_max` over joints and time (`v_max` scaled by
    /// `velocity_scaling`).
    pub max_velocity_ratio: f64,
    /// Largest `|d²q/dt²| / a_max` over joints and time (`a_max` scaled by
    /// `acceleration_scaling`); `None` without acceleration limits.
    pub max_acceleration_ratio: Option<f64>,
    /// Largest `|d³q/dt³| / j_max` over joints and time; `None` without
    /// jerk limits.
    pub max_jerk_ratio: Option<f64>,
    /// TCP distance to the goal at the end (m); `None` without a goal.
    pub goal_error_m: Option<f64>,
    /// Angle (rad) between the gripper's z axis at the end and
    /// `goal.approach_axis`; `None` without an approach axis.
    pub goal_angle_error_rad: Option<f64>,
    /// Largest distance (m) of the TCP from a position waypoint beyond its
    /// `tolerance_m` (≤ 0 when every one is met); `None` without position
    /// waypoints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub via_position_excess_m: Option<f64>,
    /// Largest joint difference (rad) from a configuration waypoint with a
    /// `tolerance_rad`, beyond that tolerance (≤ 0 when every one is met);
    /// `None` without such waypoints (exact ones are in
    /// `equality_error_rad`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub via_configuration_excess_rad: Option<f64>,
    /// SCP iterations (QPs solved) that produced this trajectory.
    pub iterations: usize,
    /// Wall-clock solve time (ms); not deterministic.
    pub solve_ms: f64,
    /// Number of phases checked.
    pub verified_samples: usize,
    /// Non-fatal notes (repairs, stops, screening).
    pub warnings: Vec<String>,
    /// The final QP behind an `optimal` answer, solved by Clarabel at the
    /// converged point; absent for other statuses.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_qp: Option<FinalQp>,
    /// Largest end-condition error: start / final configuration (rad) and,
    /// rest-to-rest, end velocity (rad/s) and acceleration (rad/s²); not
    /// serialised (the contract has no such field) but checked by
    /// `is_feasible`.
    #[serde(skip)]
    pub equality_error_rad: f64,
    /// Largest opt-in weight-bound excess; not serialised.
    #[serde(skip)]
    pub weight_bound_excess: f64,
}

/// The certifying QP of an `optimal` answer: Clarabel (the solver of
/// record) at the converged point, exact goal cone and constraint
/// generation. With the trust region free, the answer is a KKT point of the
/// problem linearised there (the optimum, on a convex problem).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FinalQp {
    /// Clarabel's status (`Solved`, `AlmostSolved`); `not_needed` when the
    /// prior mean itself is feasible (cost 0: no QP).
    pub status: String,
    /// Clarabel's interior-point iterations.
    pub iterations: u32,
    /// Clarabel's primal residual.
    pub primal_residual: f64,
    /// Clarabel's dual residual.
    pub dual_residual: f64,
    /// Clarabel's relative duality gap.
    pub gap: f64,
    /// Whether the trust region limited the final step (then the point is
    /// the best the line search could reach, not certified as a KKT point).
    pub trust_region_active: bool,
}

impl FinalQp {
    /// The prior mean is feasible: no QP was needed.
    pub fn not_needed() -> FinalQp {
        FinalQp {
            status: "not_needed".into(),
            iterations: 0,
            primal_residual: 0.0,
            dual_residual: 0.0,
            gap: 0.0,
            trust_region_active: false,
        }
    }

    /// From Clarabel's account of the final solve.
    pub fn from(info: &ClarabelInfo, trust_region_active: bool) -> FinalQp {
        FinalQp {
            status: info.status.clone(),
            iterations: info.iterations,
            primal_residual: info.primal_residual,
            dual_residual: info.dual_residual,
            gap: info.gap,
            trust_region_active,
        }
    }

    /// The final step was held by the trust region (or its line search).
    pub fn held_by_ball(info: Option<&ClarabelInfo>) -> FinalQp {
        match info {
            Some(info) => FinalQp::from(info, true),
            None => FinalQp {
                trust_region_active: true,
                ..FinalQp::not_needed()
            },
        }
    }
}

/// One extra feasible trajectory (`samples: N`).
#[derive(Clone, Debug, Serialize)]
pub struct SampleResult {
    /// Status of the projection of this draw.
    pub status: Status,
    /// Projected weights.
    pub weights: Vec<f64>,
    /// Mahalanobis distance of the projected weights to the prior.
    pub mahalanobis: f64,
    /// Mahalanobis distance between the draw and its projection.
    pub distance_to_draw: f64,
    /// The projected trajectory.
    pub trajectory: JointTrajectory,
    /// Its dense verification.
    pub report: TrajectoryReport,
}

/// The answer to an optimise request.
#[derive(Clone, Debug, Serialize)]
pub struct OptimizeResponse {
    /// Outcome.
    pub status: Status,
    /// Why the solve ended where it did (`status` is
    /// `stop_reason.status()`).
    pub stop_reason: super::StopReason,
    /// The motion's duration (s): the request's `duration_s`, or the one
    /// `duration: auto` chose.
    pub duration_s: f64,
    /// Optimised weights, joint-major (the prior mean when infeasible
    /// before solving).
    pub weights: Vec<f64>,
    /// Mahalanobis distance of `weights` to the prior.
    pub mahalanobis: f64,
    /// The trajectory of `weights`.
    pub trajectory: JointTrajectory,
    /// Dense verification of `weights`.
    pub report: TrajectoryReport,
    /// Dense verification of the prior mean.
    pub prior_mean_report: TrajectoryReport,
    /// Extra feasible trajectories (`samples: N`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub samples: Vec<SampleResult>,
    /// Why the status is not `optimal`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// With status `infeasible` because `duration_s` is too short: a
    /// duration (s) at which a verified solve of this same request reached
    /// `optimal` (searched upwards from `duration_lower_bound_s` within a
    /// budget and the deadline; not necessarily the shortest). Absent when
    /// the search found none in time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_duration_s: Option<f64>,
    /// With status `infeasible` because `duration_s` is too short: a proven
    /// lower bound (s) on any feasible duration, from the velocity,
    /// acceleration and jerk limits and the distance the motion must cover
    /// ([`super::infeasible::duration`]); durations above it may still be infeasible.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duration_lower_bound_s: Option<f64>,
    /// With `stop_reason: proven_infeasible`: which part of the request the
    /// diagnosis found impossible (not serialised: `reason` says it in
    /// words; MoveIt's error codes map it).
    #[serde(skip)]
    pub culprit: Option<Culprit>,
    /// The basis `weights` are on when it is not the request's: the
    /// smoothness prior's default basis left no certified answer and a
    /// finer one found it ([`super::finer_basis`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub promp: Option<crate::promp::PrompConfig>,
}

impl OptimizeResponse {
    /// The response as JSON with every `solve_ms` set to 0: identical bytes
    /// for identical requests (used by the determinism tests).
    pub fn deterministic_json(&self) -> String {
        let mut copy = self.clone();
        copy.report.solve_ms = 0.0;
        copy.prior_mean_report.solve_ms = 0.0;
        for s in &mut copy.samples {
            s.report.solve_ms = 0.0;
        }
        serde_json::to_string(&copy).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_names_are_the_json_names() {
        for s in [Status::Optimal, Status::Infeasible, Status::MaxIterations] {
            assert_eq!(serde_json::to_value(s).unwrap(), s.as_str());
        }
    }
}

/// What the diagnosis before a solve (`Problem::diagnosis`) found: which part of the request no
/// trajectory can meet (for callers that map it, e.g. MoveIt's error
/// codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Culprit {
    /// `start` is outside the joint limits.
    StartOutsideLimits,
    /// `start` is closer to an obstacle than `clearance_m`.
    StartInCollision,
    /// `options.final_configuration` is outside the joint limits.
    GoalOutsideLimits,
    /// The goal (`options.final_configuration`, or `goal.position` buried
    /// deep in an obstacle) is closer to an obstacle than `clearance_m`.
    GoalInCollision,
    /// `goal.position` is out of reach, or inverse kinematics to it fails.
    GoalUnreachable,
    /// A configuration via point is outside the joint limits.
    ViaPointOutsideLimits,
}
