//! The goal a 3-D target implies: the pre-grasp point `goal_standoff_m`
//! short of the berry on the line from the home TCP (the way the synthetic
//! demonstrations were made), its approach direction, the report of where
//! the target came from, and the network's prior conditioned on reaching
//! the goal.

use super::request::TargetInput;
use crate::optim::{Goal, GoalApproach};
use crate::perception::{locate_target, Camera};
use crate::promp::{Basis, FinalPointObservation, WeightDistribution};
use crate::robot::Robot;
use crate::{Error, Result};
use nalgebra::{DMatrix, Point3, Vector3};
use serde::Serialize;

/// Pre-grasp standoff (m) of a goal derived from the target: the synthetic
/// demonstrations end this far short of the berry centre.
pub const DEFAULT_GOAL_STANDOFF_M: f64 = 0.10;

/// Tolerance (m) of a goal derived from the target.
pub const GOAL_TOLERANCE_M: f64 = 0.005;

/// Where the 3-D target came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetSource {
    /// Back-projected from the depth image.
    Depth,
    /// Sent by the client (`target_position`).
    Client,
}

/// The 3-D target and the goal derived from it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetReport {
    /// Berry centre (m, base frame).
    pub position: [f64; 3],
    /// Depth of the centre along the camera's optical axis (m), when
    /// measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_m: Option<f64>,
    /// Where it came from.
    pub source: TargetSource,
    /// The pre-grasp goal handed to the optimiser (m, base frame).
    pub goal: [f64; 3],
    /// The goal's tolerance (m).
    pub goal_tolerance_m: f64,
}

impl TargetReport {
    /// The optimiser's goal: the derived position within its tolerance,
    /// approached along `approach` when one is given.
    pub fn goal(&self, approach: Option<&GoalApproach>) -> Goal {
        Goal::at(self.goal, self.goal_tolerance_m).with_approach(approach)
    }
}

/// Standard deviation of the goal observation the prior is conditioned on
/// (m): well inside the optimiser's goal tolerance, loose enough that the
/// update stays a small, well-conditioned correction.
pub const GOAL_PRIOR_STD_M: f64 = 0.001;

/// The network's prior conditioned on its final TCP reaching the goal
/// ([`WeightDistribution::condition_final_point`]): the network keeps the
/// posture and timing it learnt from the demonstrations, the kinematics
/// move the hand to the 3-D target, and the optimiser starts next to the
/// goal instead of pulling the whole trajectory there.
pub fn prior_towards_goal(
    prior: &WeightDistribution,
    robot: &Robot,
    basis: &Basis,
    target: &TargetReport,
) -> Result<WeightDistribution> {
    let kinematics = |q: &[f64]| {
        let position = robot.tcp_pose(q).translation.vector;
        let jacobian = robot.tcp_jacobian(q);
        let rows = jacobian.fixed_rows::<3>(0);
        (
            position,
            DMatrix::from_fn(3, rows.ncols(), |r, c| rows[(r, c)]),
        )
    };
    let observation = FinalPointObservation::new(Vector3::from(target.goal), GOAL_PRIOR_STD_M);
    Ok(prior
        .condition_final_point(basis, &observation, &kinematics)?
        .distribution)
}

/// A berry centre, its measured depth and where it came from.
pub(super) struct Located {
    pub(super) position: [f64; 3],
    depth_m: Option<f64>,
    /// Depth of the centre along the camera's optical axis: measured, or
    /// that of the client's position (what a depth-conditioned model reads).
    pub(super) camera_depth_m: f64,
    source: TargetSource,
}

/// The berry centre, if the input has one, seen through `camera` (posed).
pub(super) fn locate(
    camera: &Camera,
    target: &TargetInput,
    target_box: &[f64; 4],
) -> Result<Option<Located>> {
    if let TargetInput::None = target {
        return Ok(None);
    }
    match target {
        TargetInput::None => Ok(None),
        TargetInput::Position(p) => Ok(Some(Located {
            position: *p,
            depth_m: None,
            camera_depth_m: camera.to_camera(&Point3::from(*p)).z,
            source: TargetSource::Client,
        })),
        TargetInput::Depth(depth, field) => {
            let t = locate_target(depth, target_box, camera, field)?;
            Ok(Some(Located {
                position: t.position,
                depth_m: Some(t.depth_m),
                camera_depth_m: t.depth_m,
                source: TargetSource::Depth,
            }))
        }
    }
}

/// The pre-grasp goal `standoff` short of `position` on the line from the
/// home TCP (see the module docs). A berry, or a goal, beyond the arm's
/// reach is refused naming `field` (where the target came from).
pub(super) fn goal_from_target(
    robot: &Robot,
    target: Located,
    standoff: Option<f64>,
    field: &str,
) -> Result<TargetReport> {
    let Located {
        position,
        depth_m,
        source,
        ..
    } = target;
    let standoff = standoff.unwrap_or(DEFAULT_GOAL_STANDOFF_M);
    let home = robot.tcp_pose(&robot.home()).translation.vector;
    let berry = Vector3::from(position);
    let reach = robot.reach();
    let from_depth = |e: Error| {
        match (depth_m, e) {
        (Some(d), Error::Invalid { field, message }) => Error::invalid(
            field,
            format!(
                "{message}; the depth image reads {d:.2} m at the target box: check it and its scale (metres per unit)"
            ),
        ),
        (_, e) => e,
    }
    };
    reach
        .check(field, "the berry", &position, standoff + GOAL_TOLERANCE_M)
        .map_err(from_depth)?;
    let axis = (berry - home)
        .try_normalize(1e-9)
        .ok_or_else(|| Error::invalid(field, "coincides with the home TCP position"))?;
    let goal = berry - axis * standoff;
    let goal_array = [goal.x, goal.y, goal.z];
    reach
        .check(field, "the pre-grasp goal", &goal_array, GOAL_TOLERANCE_M)
        .map_err(from_depth)?;
    Ok(TargetReport {
        position,
        depth_m,
        source,
        goal: goal_array,
        goal_tolerance_m: GOAL_TOLERANCE_M,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::example_distribution;
    use crate::promp::PrompConfig;

    #[test]
    fn the_conditioned_prior_ends_at_the_goal_with_the_real_kinematics() {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let prior = example_distribution(&basis, 20, 3).unwrap();
        let mean = prior.trajectory_mean(&basis);
        let last: Vec<f64> = mean.row(mean.nrows() - 1).iter().copied().collect();
        // A goal 4 cm from where the prior's mean ends, through the Panda's
        // real kinematics.
        let goal = robot.tcp_pose(&last).translation.vector + Vector3::new(0.02, -0.03, 0.015);
        let report = TargetReport {
            position: (goal + Vector3::new(0.1, 0.0, 0.0)).into(),
            depth_m: None,
            source: TargetSource::Client,
            goal: goal.into(),
            goal_tolerance_m: 0.005,
        };
        let posterior = prior_towards_goal(&prior, &robot, &basis, &report).unwrap();
        let m = posterior.trajectory_mean(&basis);
        let end: Vec<f64> = m.row(m.nrows() - 1).iter().copied().collect();
        let reached = (robot.tcp_pose(&end).translation.vector - goal).norm();
        assert!(reached < 2e-3, "final TCP {reached} m from the goal");
        // The start barely moves (the basis functions at the two ends
        // hardly overlap) and conditioning only removes uncertainty.
        for (a, b) in m.row(0).iter().zip(mean.row(0).iter()) {
            assert!((a - b).abs() < 0.02, "start moved from {b} to {a}");
        }
        let shrink = (&prior.cov - &posterior.cov).symmetric_eigenvalues().min();
        assert!(shrink > -1e-9, "{shrink}");
    }
}
