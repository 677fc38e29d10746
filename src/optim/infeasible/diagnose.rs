//! Infeasibility diagnosis before solving: conditions that no trajectory
//! can meet, each reported with the constraint it breaks.

use crate::optim::problem::Problem;
use crate::optim::report::Culprit;
use crate::optim::tolerances::FEASIBILITY_TOLERANCE;
use crate::robot::{IkOptions, IkTarget};
use nalgebra::Point3;

/// A proof before any solve that the problem is infeasible.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnosis {
    /// What cannot be met.
    pub culprit: Culprit,
    /// Why, in words naming the request field.
    pub reason: String,
}

impl Problem {
    /// Why the problem is infeasible before any solve, if it evidently is
    /// (the words of [`Problem::diagnosis`]).
    pub fn diagnose(&self) -> Option<String> {
        self.diagnosis().map(|d| d.reason)
    }

    /// What makes the problem infeasible before any solve, if anything
    /// evidently does: start (or final configuration, or a via point)
    /// outside the limits, start or final configuration in collision, goal
    /// buried deep in an obstacle, goal beyond the arm's reach, or inverse
    /// kinematics to the goal failing from several seeds.
    pub fn diagnosis(&self) -> Option<Diagnosis> {
        let found = |culprit| move |reason| Diagnosis { culprit, reason };
        if let Some(start) = &self.linear.start {
            if let Some(r) = self.outside_limits("start", start) {
                return Some(found(Culprit::StartOutsideLimits)(r));
            }
            if let Some(r) = self.in_collision("start", start) {
                return Some(found(Culprit::StartInCollision)(r));
            }
        }
        if let Some(q) = &self.linear.final_configuration {
            let field = "options.final_configuration";
            if let Some(r) = self.outside_limits(field, q) {
                return Some(found(Culprit::GoalOutsideLimits)(r));
            }
            if let Some(r) = self.in_collision(field, q) {
                return Some(found(Culprit::GoalInCollision)(r));
            }
        }
        for (p, q) in &self.linear.via {
            let field = format!("via_points[{}].configuration", p - 2);
            if let Some(r) = self.outside_limits(&field, q) {
                return Some(found(Culprit::ViaPointOutsideLimits)(r));
            }
        }
        self.goal_problem()
    }

    fn outside_limits(&self, field: &str, q: &[f64]) -> Option<String> {
        let lin = &self.linear;
        q.iter().enumerate().find_map(|(j, &v)| {
            (v < lin.lower[j] - FEASIBILITY_TOLERANCE || v > lin.upper[j] + FEASIBILITY_TOLERANCE)
                .then(|| {
                    format!(
                        "{field}[{j}] = {v:.4} rad is outside joint {} limits [{:.4}, {:.4}] (limits minus joint_limit_margin_rad)",
                        self.robot.joint_names()[j],
                        lin.lower[j],
                        lin.upper[j]
                    )
                })
        })
    }

    /// Why configuration `q` (the request's `field`) is closer to an
    /// obstacle than `clearance_m`, if it is.
    fn in_collision(&self, field: &str, q: &[f64]) -> Option<String> {
        let frames = self.robot.fk(q);
        let c = self.scene.min_clearance(&self.robot, &frames)?;
        (c.distance < self.clearance_m - FEASIBILITY_TOLERANCE).then(|| {
            format!(
                "{field} is in collision: {} (clearance_m {:.4})",
                c.describe(&self.robot, &self.scene),
                self.clearance_m
            )
        })
    }

    fn goal_problem(&self) -> Option<Diagnosis> {
        let goal = self.goal.as_ref()?;
        let p = Point3::from(goal.position);
        if let Some(reason) = self.goal_buried(&p, goal.tolerance_m) {
            return Some(Diagnosis {
                culprit: Culprit::GoalInCollision,
                reason,
            });
        }
        let bound = self.robot.reach();
        let (distance, reach) = (bound.distance(&goal.position), bound.radius);
        let unreachable = if !bound.holds(&goal.position, goal.tolerance_m) {
            Some(format!(
                "goal: out of reach, {distance:.3} m from the shoulder, the arm reaches at most {reach:.3} m"
            ))
        } else {
            self.ik_failure(&p, goal.tolerance_m)
        };
        unreachable.map(|reason| Diagnosis {
            culprit: Culprit::GoalUnreachable,
            reason,
        })
    }

    /// The goal is buried in an obstacle when no TCP position within the
    /// tolerance lets the gripper keep the clearance. Let `d` be the goal's
    /// depth in one convex part of the obstacle and `r` the distance from
    /// the TCP to its nearest robot collision shape (rigid with the TCP).
    /// Signed distance is 1-Lipschitz: a TCP within `tolerance` of the goal
    /// lies at signed distance ≤ tolerance - d from the part, so a point
    /// of that shape lies at ≤ tolerance - d + r, and the shape's clearance
    /// is at most that (negative when the point is inside). Hence
    /// `d > tolerance + r - clearance` (plus the verification tolerances)
    /// proves that every trajectory ending within the tolerance breaks the
    /// clearance at its last sample.
    fn goal_buried(&self, p: &Point3<f64>, tolerance: f64) -> Option<String> {
        let (i, depth) = self.scene.deepest_containing(p)?;
        let reach = self.tcp_to_robot_shapes().max(0.0);
        // Our own verification accepts the goal and the clearance each
        // within FEASIBILITY_TOLERANCE; the proof must beat both.
        let needed = tolerance + reach - self.clearance_m + 2.0 * FEASIBILITY_TOLERANCE + 1e-9;
        (depth > needed).then(|| {
            format!(
                "goal: the goal lies {depth:.4} m deep inside obstacle '{}': with tolerance_m {tolerance:.4} the gripper (whose nearest collision shape is {reach:.4} m from the TCP) cannot keep clearance_m {:.4}",
                self.scene.obstacles()[i].id,
                self.clearance_m
            )
        })
    }

    /// Signed distance from the TCP to the nearest robot collision shape
    /// (the same at every configuration: the hand is rigid with the TCP).
    fn tcp_to_robot_shapes(&self) -> f64 {
        let home = self.robot.home();
        let tcp = self.robot.tcp_pose(&home).translation.vector;
        let point = crate::scene::Obstacle {
            id: "tcp".into(),
            shape: crate::scene::ObstacleShape::Sphere(crate::geometry::Sphere {
                center: tcp.into(),
                radius: 1e-6,
            }),
        };
        crate::scene::Scene::new(vec![point])
            .ok()
            .and_then(|s| s.min_clearance(&self.robot, &self.robot.fk(&home)))
            .map_or(0.0, |c| c.distance)
    }

    /// Inverse kinematics from the prior mean's final configuration, the
    /// start, home and mid-range; a reason when none reaches the goal.
    fn ik_failure(&self, p: &Point3<f64>, tolerance: f64) -> Option<String> {
        let mut seeds = vec![self.ends.position(1, &self.prior.mean)];
        if let Some(s) = &self.linear.start {
            seeds.push(s.clone());
        }
        seeds.push(self.robot.home());
        seeds.push(
            self.linear
                .lower
                .iter()
                .zip(&self.linear.upper)
                .map(|(l, u)| 0.5 * (l + u))
                .collect(),
        );
        let target = IkTarget {
            position: *p,
            approach_axis: None,
        };
        let margin = self.linear.lower[0] - self.robot.limits()[0].lower;
        let options = IkOptions {
            tolerance_m: (0.5 * tolerance).min(1e-3),
            limit_margin_rad: margin,
            ..Default::default()
        };
        let mut best = f64::INFINITY;
        for seed in &seeds {
            if let Ok(sol) = self.robot.ik(&target, seed, &options) {
                if sol.position_error_m <= tolerance {
                    return None;
                }
                best = best.min(sol.position_error_m);
            }
        }
        Some(format!(
            "goal: out of reach, inverse kinematics found no configuration within the joint limits from {} seeds (best TCP error {best:.4} m)",
            seeds.len()
        ))
    }
}
