//! A joint goal with MoveIt's tolerances → the one configuration planned to.
//!
//! A `JointConstraint` accepts every position in `[position −
//! tolerance_below, position + tolerance_above]`; a goal is the box of its
//! joints' intervals. dPMP plans to one configuration of that box (the
//! optimiser ends exactly there, so every tolerance is met):
//!
//! 1. the box's point nearest its centre within the joint limits (the
//!    centre itself when it is within them; none when the box misses the
//!    limits: `INVALID_GOAL_CONSTRAINTS`);
//! 2. when that point is closer to an obstacle than the clearance asked,
//!    the box's clear configuration nearest the centre among
//!    [`GOAL_SAMPLES`] deterministic samples (the corners' directions and
//!    seeded uniform draws), as MoveIt's planners sample goal states from
//!    the constraint region; when none is clear, the point of step 1 stays
//!    and the diagnosis answers `GOAL_IN_COLLISION`.

use crate::robot::Robot;
use crate::scene::{Obstacle, Scene};
use crate::Result;
use rand::{Rng, SeedableRng};

/// Configurations of a tolerance box tried when its centre is not clear.
pub const GOAL_SAMPLES: usize = 512;

/// A joint goal: each joint's target and its tolerances (rad, ≥ 0).
#[derive(Clone, Debug, PartialEq)]
pub struct JointGoal {
    /// The constraints' positions, one per robot joint.
    pub position: Vec<f64>,
    /// `tolerance_below` per joint.
    pub below: Vec<f64>,
    /// `tolerance_above` per joint.
    pub above: Vec<f64>,
}

/// The configuration a [`JointGoal`] is planned to, and why when it is not
/// the constraints' positions.
#[derive(Clone, Debug, PartialEq)]
pub struct ChosenGoal {
    /// One value per robot joint, within the goal's tolerances.
    pub configuration: Vec<f64>,
    /// Said in the answer's warnings when the configuration moved.
    pub note: Option<String>,
}

impl JointGoal {
    /// A goal met exactly.
    pub fn exact(position: Vec<f64>) -> JointGoal {
        let zeros = vec![0.0; position.len()];
        JointGoal {
            position,
            below: zeros.clone(),
            above: zeros,
        }
    }

    /// Each joint's accepted interval.
    fn interval(&self, j: usize) -> (f64, f64) {
        (
            self.position[j] - self.below[j],
            self.position[j] + self.above[j],
        )
    }

    /// The box's point nearest its centre within `robot`'s limits, or the
    /// first joint whose interval misses its limits.
    pub fn within_limits(&self, robot: &Robot) -> std::result::Result<Vec<f64>, usize> {
        (0..self.position.len())
            .map(|j| {
                let (lo, hi) = self.interval(j);
                let limit = &robot.limits()[j];
                let (lo, hi) = (lo.max(limit.lower), hi.min(limit.upper));
                if lo > hi {
                    return Err(j);
                }
                Ok(self.position[j].clamp(lo, hi))
            })
            .collect()
    }

    /// The configuration to plan to among `obstacles` with `clearance_m`
    /// (see the module docs); `robot` has its fingers posed.
    pub fn choose(
        &self,
        robot: &Robot,
        obstacles: &[Obstacle],
        clearance_m: f64,
    ) -> Result<ChosenGoal> {
        let centre = self.within_limits(robot).unwrap_or(self.position.clone());
        let moved = |configuration: Vec<f64>, why: &str| {
            ChosenGoal {
            note: (configuration != self.position).then(|| {
                format!("the goal is planned at {configuration:.4?}, within the joint constraints' tolerances: {why}")
            }),
            configuration,
        }
        };
        let has_room = (0..self.position.len()).any(|j| {
            let (lo, hi) = self.interval(j);
            hi > lo
        });
        if !has_room || obstacles.is_empty() {
            return Ok(moved(centre, "the nearest within the joint limits"));
        }
        let scene = Scene::new(obstacles.to_vec())?;
        let is_clear = |q: &[f64]| {
            scene
                .min_clearance(robot, &robot.fk(q))
                .is_none_or(|c| c.distance >= clearance_m)
        };
        if is_clear(&centre) {
            return Ok(moved(centre, "the nearest within the joint limits"));
        }
        let mut candidates = self.samples(robot);
        candidates
            .sort_by(|a, b| distance(a, &self.position).total_cmp(&distance(b, &self.position)));
        Ok(match candidates.into_iter().find(|q| is_clear(q)) {
            Some(q) => moved(
                q,
                "the constraints' positions are closer to an obstacle than clearance_m",
            ),
            None => moved(centre, "the nearest within the joint limits"),
        })
    }

    /// [`GOAL_SAMPLES`] configurations of the box within the limits: the
    /// box's corners (clamped to the limits) first, then seeded uniform
    /// draws; the same every call.
    fn samples(&self, robot: &Robot) -> Vec<Vec<f64>> {
        let n = self.position.len();
        let bounds: Vec<(f64, f64)> = (0..n)
            .map(|j| {
                let (lo, hi) = self.interval(j);
                let limit = &robot.limits()[j];
                (
                    lo.max(limit.lower),
                    hi.min(limit.upper).max(lo.max(limit.lower)),
                )
            })
            .collect();
        let corners = if n < 10 { 1usize << n } else { 0 };
        let mut out: Vec<Vec<f64>> = (0..corners.min(GOAL_SAMPLES))
            .map(|bits| {
                bounds
                    .iter()
                    .enumerate()
                    .map(|(j, &(lo, hi))| if bits >> j & 1 == 1 { hi } else { lo })
                    .collect()
            })
            .collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x6a6f_696e_745f_676f);
        while out.len() < GOAL_SAMPLES {
            out.push(
                bounds
                    .iter()
                    .map(|&(lo, hi)| lo + (hi - lo) * rng.gen::<f64>())
                    .collect(),
            );
        }
        out
    }
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOAL: [f64; 7] = [0.5, -0.3, 0.2, -2.0, 0.1, 1.8, 0.6];

    fn goal(tolerance: f64) -> JointGoal {
        JointGoal {
            position: GOAL.to_vec(),
            below: vec![tolerance; 7],
            above: vec![tolerance; 7],
        }
    }

    /// A ball of `radius` on the TCP of `q`.
    fn ball_on_tcp(robot: &Robot, q: &[f64], radius: f64) -> Obstacle {
        let p = robot.tcp_pose(q).translation.vector;
        serde_json::from_value(serde_json::json!({
            "type": "sphere", "id": "ball", "center": [p.x, p.y, p.z], "radius": radius
        }))
        .unwrap()
    }

    #[test]
    fn a_clear_centre_is_kept_and_the_limits_clip_the_box() {
        let robot = Robot::panda().unwrap();
        let chosen = goal(0.1).choose(&robot, &[], 0.005).unwrap();
        assert_eq!((chosen.configuration, chosen.note), (GOAL.to_vec(), None));
        let mut beyond = goal(0.0);
        let upper = robot.limits()[3].upper;
        beyond.position[3] = upper + 0.05;
        assert_eq!(beyond.within_limits(&robot), Err(3));
        beyond.below[3] = 0.1;
        let q = beyond.within_limits(&robot).unwrap();
        assert_eq!(q[3], upper);
    }

    #[test]
    fn a_blocked_centre_moves_to_the_nearest_clear_configuration_in_the_box() {
        let robot = Robot::panda().unwrap();
        let ball = ball_on_tcp(&robot, &GOAL, 0.06);
        let obstacles = vec![ball];
        let scene = Scene::new(obstacles.clone()).unwrap();
        let clearance = |q: &[f64]| scene.min_clearance(&robot, &robot.fk(q)).unwrap().distance;
        assert!(clearance(&GOAL) < 0.0, "{}", clearance(&GOAL));
        // Exact: nothing to choose; the diagnosis will refuse it.
        let exact = goal(0.0).choose(&robot, &obstacles, 0.005).unwrap();
        assert_eq!(exact.configuration, GOAL.to_vec());
        // A 0.3 rad box holds clear configurations: the chosen one is clear,
        // within the box, and no sample nearer the centre is clear.
        let wide = goal(0.3);
        let chosen = wide.choose(&robot, &obstacles, 0.005).unwrap();
        assert!(clearance(&chosen.configuration) >= 0.005);
        for (j, q) in chosen.configuration.iter().enumerate() {
            assert!((q - GOAL[j]).abs() <= 0.3 + 1e-12);
        }
        let d = distance(&chosen.configuration, &GOAL);
        for q in wide.samples(&robot) {
            if distance(&q, &GOAL) < d {
                assert!(clearance(&q) < 0.005);
            }
        }
        assert!(chosen.note.unwrap().contains("closer to an obstacle"));
    }
}
