//! Lever arms: how fast any point of the robot's collision geometry can
//! move per unit speed of each joint. The continuous clearance certificate
//! and the duration bound turn joint motion into Cartesian motion with
//! them, so each is an upper bound, never an estimate.
//!
//! - [`Robot::lever_arms`] holds in every configuration: a point `p`
//!   carried by revolute joint `j` moves at `|q̇_j| · dist(p, axis_j)`,
//!   and `dist(p, axis_j) ≤ |p − o_j|` is at most the summed lengths of the
//!   fixed joint offsets from `o_j` to `p`'s link (plus prismatic travel)
//!   plus the link geometry's reach from its frame origin (triangle
//!   inequality).
//! - [`Robot::lever_arms_at`] holds at one configuration: the largest
//!   distance from joint `j`'s axis of any link origin beyond it, plus that
//!   link's reach. On the Panda in a picking pose it is about half the
//!   configuration-free bound for the base joints, whose motion dominates.
//!   Over an interval of motion it stays a bound once the motion of the
//!   joints beyond `j` is added ([`lever_arms_over`]): only they move a
//!   point relative to joint `j`'s axis.

use super::chain::{ChainStep, Motion};
use super::fk::Frames;
use super::{JointLimit, Robot};
use nalgebra::Vector3;

impl Robot {
    /// Per actuated joint, an upper bound (m/rad) on the speed of any point
    /// of the collision geometry per unit joint speed, valid in every
    /// configuration (see the module docs). Prismatic joints: 1.
    pub fn lever_arms(&self) -> &[f64] {
        &self.lever_arms
    }

    /// Per actuated joint, an upper bound (m/rad) on the speed of any point
    /// of the collision geometry per unit joint speed at the configuration
    /// whose link poses are `frames`: the largest distance from the joint's
    /// axis of a link frame origin beyond it plus that link's geometry
    /// reach, and never more than [`Robot::lever_arms`]. Prismatic joints: 1.
    pub fn lever_arms_at(&self, frames: &Frames) -> Vec<f64> {
        self.dof_step
            .iter()
            .zip(&self.lever_arms)
            .map(|(&step, &free)| match self.steps[step].motion {
                Motion::Revolute { axis, .. } => {
                    let joint = &frames.poses[step + 1];
                    let origin = joint.translation.vector;
                    let direction = joint.rotation * axis.into_inner();
                    let reach = (step + 1..frames.poses.len())
                        .map(|link| {
                            let offset = frames.poses[link].translation.vector - origin;
                            off_axis(&offset, &direction) + self.link_reach[link]
                        })
                        .fold(0.0, f64::max);
                    reach.min(free)
                }
                _ => free,
            })
            .collect()
    }

    /// Compute [`Robot::lever_arms`] and each link's reach from the chain
    /// and the shapes.
    pub(crate) fn with_lever_arms(mut self) -> Robot {
        let n_links = self.link_names.len();
        let mut reach = vec![0.0f64; n_links];
        for s in &self.shapes {
            reach[s.link] = reach[s.link].max(s.geometry.reach_from(&[0.0; 3]));
        }
        self.lever_arms = self
            .dof_step
            .iter()
            .map(|&step| match self.steps[step].motion {
                Motion::Prismatic { .. } => 1.0,
                _ => {
                    let mut chain = 0.0;
                    let mut best: f64 = reach[step + 1];
                    for k in step + 1..self.steps.len() {
                        chain += step_length(&self.steps[k], &self.limits);
                        best = best.max(chain + reach[k + 1]);
                    }
                    best
                }
            })
            .collect();
        self.link_reach = reach;
        self
    }
}

/// Lever arms valid over a whole interval of motion, from those at either
/// end (`at_a`, `at_b`: [`Robot::lever_arms_at`]), the configuration-free
/// ones (`free`) and each joint's path length over the interval (`path`,
/// rad): a point's distance from joint `j`'s axis changes only by what the
/// joints beyond `j` move it, at most `Σ_{i>j} arm_i · path_i` with the
/// interval's own arms of those joints (computed outermost first).
pub fn lever_arms_over(at_a: &[f64], at_b: &[f64], free: &[f64], path: &[f64]) -> Vec<f64> {
    let n = free.len();
    let mut beyond = 0.0;
    let mut out = vec![0.0; n];
    for j in (0..n).rev() {
        out[j] = (at_a[j].min(at_b[j]) + beyond).min(free[j]);
        beyond += out[j] * path[j];
    }
    out
}

/// Distance of the point at `offset` from a line through the origin along
/// the unit `direction`.
fn off_axis(offset: &Vector3<f64>, direction: &Vector3<f64>) -> f64 {
    (offset - direction * direction.dot(offset)).norm()
}

/// The length a chain step adds to the configuration-free reach: its fixed
/// offset, plus the largest travel of a prismatic joint.
fn step_length(step: &ChainStep, limits: &[JointLimit]) -> f64 {
    let offset = step.origin.translation.vector.norm();
    match step.motion {
        Motion::Prismatic { dof, .. } => {
            offset + limits[dof].lower.abs().max(limits[dof].upper.abs())
        }
        _ => offset,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::ShapeGeometry;
    use nalgebra::Point3;
    use rand::{Rng, SeedableRng};

    /// Every hull vertex of every link, as (link, point in the link frame).
    fn hull_vertices(robot: &Robot) -> Vec<(usize, Point3<f64>)> {
        robot
            .collision_shapes()
            .iter()
            .filter_map(|s| match &s.geometry {
                ShapeGeometry::Convex(h) => Some((s.link, h)),
                _ => None,
            })
            .flat_map(|(link, h)| {
                h.vertices()
                    .iter()
                    .map(move |v| (link, Point3::new(v[0], v[1], v[2])))
            })
            .collect()
    }

    /// The largest speed of any hull vertex when joint `j` moves at unit
    /// speed, by central finite differences of forward kinematics.
    fn vertex_speed(robot: &Robot, q: &[f64], j: usize, vertices: &[(usize, Point3<f64>)]) -> f64 {
        let h = 1e-6;
        let (mut lo, mut hi) = (q.to_vec(), q.to_vec());
        lo[j] -= h;
        hi[j] += h;
        let (a, b) = (robot.fk(&lo), robot.fk(&hi));
        vertices
            .iter()
            .map(|(link, v)| (b.poses[*link] * v - a.poses[*link] * v).norm() / (2.0 * h))
            .fold(0.0, f64::max)
    }

    /// At random configurations within the limits, no hull vertex moves
    /// faster per unit joint speed than the configuration's lever arm
    /// (finite differences of forward kinematics), the configuration's arms
    /// never exceed the configuration-free ones, and on the base joints
    /// they are markedly tighter.
    #[test]
    fn lever_arms_at_a_configuration_bound_every_vertex_speed() {
        let robot = Robot::panda().unwrap();
        let vertices = hull_vertices(&robot);
        assert!(vertices.len() > 100);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut ratio = [0.0f64; 7];
        for _ in 0..40 {
            let q: Vec<f64> = robot
                .limits()
                .iter()
                .map(|l| rng.gen_range(l.lower..l.upper))
                .collect();
            let at = robot.lever_arms_at(&robot.fk(&q));
            for j in 0..robot.dof() {
                let speed = vertex_speed(&robot, &q, j, &vertices);
                assert!(speed <= at[j] + 1e-6, "joint {j}: {speed} > {}", at[j]);
                assert!(at[j] <= robot.lever_arms()[j]);
                ratio[j] = ratio[j].max(at[j] / robot.lever_arms()[j]);
            }
        }
        // Joint 1's axis is vertical through the base: no pose reaches its
        // configuration-free (straight-chain) bound.
        assert!(ratio[0] < 0.9, "{ratio:?}");
    }

    /// Over an interval, the arms from either end plus the motion of the
    /// joints beyond bound the vertex speeds at every configuration in it.
    #[test]
    fn lever_arms_over_an_interval_bound_every_configuration_in_it() {
        let robot = Robot::panda().unwrap();
        let vertices = hull_vertices(&robot);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..20 {
            let qa: Vec<f64> = robot
                .limits()
                .iter()
                .map(|l| rng.gen_range(0.8 * l.lower..0.8 * l.upper))
                .collect();
            let qb: Vec<f64> = qa.iter().map(|v| v + rng.gen_range(-0.2..0.2)).collect();
            let path: Vec<f64> = qa.iter().zip(&qb).map(|(a, b)| (b - a).abs()).collect();
            let over = lever_arms_over(
                &robot.lever_arms_at(&robot.fk(&qa)),
                &robot.lever_arms_at(&robot.fk(&qb)),
                robot.lever_arms(),
                &path,
            );
            for s in 0..=10 {
                let t = s as f64 / 10.0;
                let q: Vec<f64> = qa.iter().zip(&qb).map(|(a, b)| a + t * (b - a)).collect();
                for (j, arm) in over.iter().enumerate() {
                    let speed = vertex_speed(&robot, &q, j, &vertices);
                    assert!(speed <= arm + 1e-6, "t {t} joint {j}: {speed} > {arm}");
                }
            }
        }
    }
}
