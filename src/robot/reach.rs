//! How far the tool can reach: a ball that holds the TCP in every
//! configuration, from the chain's geometry alone.
//!
//! Nothing before the first moving joint moves, and a joint does not move
//! its own origin, so the first moving joint's origin (the *shoulder*) is
//! fixed in the base frame. Every later joint origin, and the TCP, lies
//! within the sum of the link offsets after it (each offset keeps its
//! length under any rotation), plus each prismatic joint's largest travel.
//! The bound is exact for a straight chain and conservative otherwise (the
//! Panda: 1.09 m from its shoulder; 0.86 m is Franka's figure to the
//! flange), so a target it refuses is out of reach for certain.

use super::chain::Motion;
use super::Robot;
use nalgebra::{Isometry3, Point3};

/// A ball holding the TCP in every configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reach {
    /// The fixed origin of the first moving joint (m, base frame).
    pub shoulder: [f64; 3],
    /// Radius (m).
    pub radius: f64,
}

impl Reach {
    /// How far `point` lies from the shoulder (m).
    pub fn distance(&self, point: &[f64; 3]) -> f64 {
        (Point3::from(*point) - Point3::from(self.shoulder)).norm()
    }

    /// Whether the TCP could be at `point` (within `slack` m).
    pub fn holds(&self, point: &[f64; 3], slack: f64) -> bool {
        self.distance(point) <= self.radius + slack
    }

    /// `Ok` when the TCP could be at `point` (within `slack` m), else an
    /// invalid-input error naming `field` and saying what (`what`: "the
    /// goal") lies how far beyond the reach.
    pub fn check(
        &self,
        field: &str,
        what: &str,
        point: &[f64; 3],
        slack: f64,
    ) -> crate::Result<()> {
        if self.holds(point, slack) {
            return Ok(());
        }
        let from_base = Point3::from(*point).coords.norm();
        Err(crate::Error::invalid(
            field,
            format!(
                "{what} at [{:.3}, {:.3}, {:.3}] ({from_base:.2} m from the base) is {:.2} m from the arm's shoulder, beyond its reach ({:.2} m)",
                point[0],
                point[1],
                point[2],
                self.distance(point),
                self.radius
            ),
        ))
    }
}

impl Robot {
    /// The ball the TCP never leaves (see the module docs).
    pub fn reach(&self) -> Reach {
        let first_moving = self
            .steps
            .iter()
            .position(|s| !matches!(s.motion, Motion::Fixed))
            .unwrap_or(self.steps.len());
        let mut fixed = Isometry3::identity();
        for step in self.steps.iter().take(first_moving + 1) {
            fixed *= step.origin;
        }
        let offsets: f64 = self
            .steps
            .iter()
            .skip(first_moving + 1)
            .map(|s| s.origin.translation.vector.norm())
            .sum();
        let travel: f64 = self
            .steps
            .iter()
            .filter_map(|s| match s.motion {
                Motion::Prismatic { dof, .. } => {
                    let l = &self.limits[dof];
                    Some(l.lower.abs().max(l.upper.abs()))
                }
                _ => None,
            })
            .sum();
        let shoulder = fixed.translation.vector;
        Reach {
            shoulder: [shoulder.x, shoulder.y, shoulder.z],
            radius: offsets + travel,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_tcp_never_leaves_the_ball_and_the_ball_is_not_loose() {
        let robot = Robot::panda().unwrap();
        let reach = robot.reach();
        assert!((reach.shoulder[2] - 0.333).abs() < 1e-9, "{reach:?}");
        assert!(reach.shoulder[0].abs() < 1e-9 && reach.shoulder[1].abs() < 1e-9);
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut farthest = 0.0f64;
        for _ in 0..20_000 {
            let q: Vec<f64> = robot
                .limits()
                .iter()
                .map(|l| rng.gen_range(l.lower..=l.upper))
                .collect();
            let p = robot.tcp_pose(&q).translation.vector;
            let d = reach.distance(&[p.x, p.y, p.z]);
            assert!(d <= reach.radius + 1e-12, "{d} > {}", reach.radius);
            farthest = farthest.max(d);
        }
        // Sampled configurations come within 15 % of the bound.
        assert!(
            farthest > 0.85 * reach.radius,
            "{farthest} vs {}",
            reach.radius
        );
        assert!(reach.holds(&[0.5, 0.0, 0.5], 0.0));
        assert!(!reach.holds(&[4.0, 0.0, 0.3], 0.0));
        let e = reach
            .check("target_position", "the berry", &[4.0, 0.0, 0.333], 0.0)
            .unwrap_err();
        assert_eq!(e.field(), Some("target_position"));
        assert!(
            e.to_string()
                .contains("4.00 m from the arm's shoulder, beyond its reach (1.09 m)"),
            "{e}"
        );
    }
}
