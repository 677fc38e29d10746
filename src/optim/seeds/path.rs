//! A seed from a collision-free path in configuration space, for what the
//! prior's neighbourhood cannot reach (a shelf, a cage, an obstacle across
//! the demonstrated path): [`super::global`] races it against the run from
//! the prior mean.
//!
//! When the problem fixes the start configuration and the end as a
//! configuration (`options.final_configuration`) or a goal position (then
//! a clear configuration of the goal region, [`super::goal_pose`]),
//! [`Problem::path_start`] runs RRT-Connect (Kuffner and LaValle, 2000): two trees grown from the ends
//! towards seeded uniform samples of the joint box, each extension a
//! straight joint-space step of at most [`PATH_STEP_RAD`] checked at
//! [`EDGE_RESOLUTION_RAD`], until the trees meet. The path is then
//! shortcut (random pairs of its nodes joined when the straight edge is
//! free) and becomes a seed: the prior conditioned to pass the path's
//! configurations at the optimisation grid's phases (the path traversed
//! at constant joint-space speed in the warped phase `s(τ)`), a ridge
//! least-squares fit in the whitened weights, so the seed is the
//! Mahalanobis-closest trajectory near the path. The SCP then pulls it to
//! the prior and certifies it; nothing here is part of the certificate.
//!
//! The planner checks configurations with the problem's own clearance
//! query (the robot's real collision geometry, culled by the broad phase
//! against the limit: a configuration clear of everything by more than
//! the limit costs a few bound tests) against the clearance asked plus
//! [`PATH_MARGIN_M`], so the smoothed trajectory has room between the
//! checked configurations; within [`END_ZONE_RAD`] of an end the clearance
//! alone, since a grasp or a placement begins and ends closer to its object
//! than the margin. Everything is seeded by
//! `options.seed` and single-threaded: the same problem gives the same
//! path. The deadline and the cancel flag stop it, and it gives up after
//! [`PATH_MAX_SAMPLES`] samples.

use crate::optim::problem::linear::LinearSet;
use crate::optim::problem::Problem;
use crate::optim::solution::SolveControl;
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::atomic::{AtomicBool, Ordering};

/// Longest extension step of the trees (rad, largest joint change).
pub const PATH_STEP_RAD: f64 = 0.15;
/// Spacing of the configurations checked along an edge (rad, largest
/// joint change).
pub const EDGE_RESOLUTION_RAD: f64 = 0.03;
/// Clearance (m) the path keeps beyond the clearance asked.
pub const PATH_MARGIN_M: f64 = 0.01;
/// Distance (rad, largest joint change) from an end within which a
/// configuration needs only the clearance asked, not the margin.
pub const END_ZONE_RAD: f64 = 0.3;
/// Samples RRT-Connect draws before it gives up.
pub const PATH_MAX_SAMPLES: usize = 3000;
/// Shortcut attempts on the found path.
const SHORTCUT_TRIES: usize = 150;
/// Ridge of the fit (whitened units², i.e. rad² per unit prior variance):
/// small, so the fit follows the path where the basis can.
const FIT_RIDGE: f64 = 1e-3;
/// Mixed into `options.seed` so the planner's samples are not the
/// restarts' draws.
const PATH_STREAM: u64 = 0x9a75_5eed;
/// Mixed into the planner's seed once per attempt.
const ATTEMPT_STRIDE: u64 = 0x5851_f42d_4c95_7f2d;

/// A tree of configurations, each with its parent's index.
struct Tree {
    nodes: Vec<Vec<f64>>,
    parent: Vec<usize>,
}

impl Tree {
    fn rooted_at(q: Vec<f64>) -> Tree {
        Tree {
            nodes: vec![q],
            parent: vec![0],
        }
    }

    /// Index of the node nearest `q` (max-norm; ties to the older node).
    fn nearest(&self, q: &[f64]) -> usize {
        let mut best = (f64::INFINITY, 0);
        for (i, n) in self.nodes.iter().enumerate() {
            let d = max_norm(n, q);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }

    /// The configurations from the root to node `i`.
    fn branch(&self, mut i: usize) -> Vec<Vec<f64>> {
        let mut out = vec![self.nodes[i].clone()];
        while i != 0 {
            i = self.parent[i];
            out.push(self.nodes[i].clone());
        }
        out.reverse();
        out
    }
}

/// What an extension towards a target did.
enum Extend {
    /// Reached the target (the new node's index).
    Reached(usize),
    /// Advanced a step (the new node's index).
    Advanced(usize),
    /// Blocked at once.
    Trapped,
}

fn max_norm(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn lerp(a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x + (y - x) * t).collect()
}

impl Problem {
    /// The whitened seed of a collision-free path between the start and
    /// the planner's goal ([`Problem::planner_goal`]: the final
    /// configuration, or one reaching the goal position), when both are
    /// clear of the obstacles by the clearance and RRT-Connect finds a path
    /// within its budget and `ctl` (see the module docs).
    /// `abandon` stops the search like `ctl` does (the run it would race
    /// has already ended).
    /// `attempt` picks the planner's random stream (0 for the global
    /// stage, 1 for the restarts).
    pub(in crate::optim) fn path_start(
        &self,
        ctl: &SolveControl,
        abandon: &AtomicBool,
        attempt: u64,
    ) -> Option<DVector<f64>> {
        let start = self.linear.start.clone()?;
        let stop = || ctl.should_stop() || abandon.load(Ordering::Relaxed);
        let goal = self.planner_goal(attempt, &stop)?;
        let planner = Planner {
            problem: self,
            ends: [start.clone(), goal.clone()],
            rng: ChaCha8Rng::seed_from_u64(
                self.options.seed ^ PATH_STREAM ^ attempt.wrapping_mul(ATTEMPT_STRIDE),
            ),
        };
        if !(self.clear_by(&start, self.clearance_m) && self.clear_by(&goal, self.clearance_m)) {
            return None;
        }
        let mut planner = planner;
        let path = planner.rrt_connect(start, goal, &stop)?;
        let path = planner.shortcut(path);
        self.fit_path(&path)
    }
}

/// RRT-Connect between two configurations of one problem: the ends, and
/// the seeded random stream of its samples and shortcuts.
struct Planner<'a> {
    problem: &'a Problem,
    ends: [Vec<f64>; 2],
    rng: ChaCha8Rng,
}

impl Planner<'_> {
    /// Whether `q` is free: clear by the clearance asked plus
    /// [`PATH_MARGIN_M`], or by the clearance alone within
    /// [`END_ZONE_RAD`] of an end (a grasp or a placement starts and ends
    /// closer to its object than the margin).
    fn is_free(&self, q: &[f64]) -> bool {
        let p = self.problem;
        let near_end = self.ends.iter().any(|e| max_norm(e, q) <= END_ZONE_RAD);
        let margin = if near_end { 0.0 } else { PATH_MARGIN_M };
        p.clear_by(q, p.clearance_m + margin)
    }

    /// Whether the straight edge from `a` to `b` is free at
    /// [`EDGE_RESOLUTION_RAD`] (`a` is taken as checked).
    fn edge_free(&self, a: &[f64], b: &[f64]) -> bool {
        let steps = (max_norm(a, b) / EDGE_RESOLUTION_RAD).ceil().max(1.0) as usize;
        (1..=steps).all(|k| self.is_free(&lerp(a, b, k as f64 / steps as f64)))
    }

    /// One step of `tree` towards `target`.
    fn extend(&self, tree: &mut Tree, target: &[f64]) -> Extend {
        let near = tree.nearest(target);
        let from = &tree.nodes[near];
        let distance = max_norm(from, target);
        let (to, reached) = if distance <= PATH_STEP_RAD {
            (target.to_vec(), true)
        } else {
            (lerp(from, target, PATH_STEP_RAD / distance), false)
        };
        if !self.edge_free(from, &to) {
            return Extend::Trapped;
        }
        tree.nodes.push(to);
        tree.parent.push(near);
        let i = tree.nodes.len() - 1;
        if reached {
            Extend::Reached(i)
        } else {
            Extend::Advanced(i)
        }
    }

    /// Steps of `tree` towards `target` until it is reached or blocked;
    /// the last node added, and whether it is the target.
    fn connect(&self, tree: &mut Tree, target: &[f64]) -> Option<(usize, bool)> {
        let mut last = None;
        loop {
            match self.extend(tree, target) {
                Extend::Reached(i) => return Some((i, true)),
                Extend::Advanced(i) => last = Some((i, false)),
                Extend::Trapped => return last,
            }
        }
    }

    /// A uniform sample of the joint box.
    fn sample(&mut self) -> Vec<f64> {
        uniform_configuration(&self.problem.linear, &mut self.rng)
    }

    /// RRT-Connect from `start` to `goal`: the configurations of a free
    /// path, or `None` after [`PATH_MAX_SAMPLES`] samples or once `stop`
    /// says so.
    fn rrt_connect(
        &mut self,
        start: Vec<f64>,
        goal: Vec<f64>,
        stop: &dyn Fn() -> bool,
    ) -> Option<Vec<Vec<f64>>> {
        if self.edge_free(&start, &goal) {
            return Some(vec![start, goal]);
        }
        let mut trees = [Tree::rooted_at(start), Tree::rooted_at(goal)];
        for sample in 0..PATH_MAX_SAMPLES {
            if stop() {
                return None;
            }
            let q = self.sample();
            let (grow, other) = if sample % 2 == 0 { (0, 1) } else { (1, 0) };
            let new = match self.extend(&mut trees[grow], &q) {
                Extend::Trapped => continue,
                Extend::Reached(i) | Extend::Advanced(i) => i,
            };
            let target = trees[grow].nodes[new].clone();
            if let Some((met, true)) = self.connect(&mut trees[other], &target) {
                let mut from_grow = trees[grow].branch(new);
                let mut from_other = trees[other].branch(met);
                from_other.pop();
                from_other.reverse();
                from_grow.extend(from_other);
                if grow == 1 {
                    from_grow.reverse();
                }
                return Some(from_grow);
            }
        }
        None
    }

    /// `path` with random pairs of its nodes joined where the straight edge
    /// between them is free.
    fn shortcut(&mut self, mut path: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
        for _ in 0..SHORTCUT_TRIES {
            if path.len() < 3 {
                break;
            }
            let i = self.rng.gen_range(0..path.len() - 2);
            let j = self.rng.gen_range(i + 2..path.len());
            if self.edge_free(&path[i], &path[j]) {
                path.drain(i + 1..j);
            }
        }
        path
    }
}

impl Problem {
    /// The whitened `z` whose trajectory passes `path` (traversed at
    /// constant joint-space speed in the warped phase) at every grid phase
    /// and the ends, in the ridge least-squares sense (see the module
    /// docs).
    fn fit_path(&self, path: &[Vec<f64>]) -> Option<DVector<f64>> {
        let rows = &self.grid;
        let n_joints = rows.n_joints();
        let dim = self.whitening.dim();
        let mean = self.whitening.weights(&DVector::zeros(dim));
        let n = rows.len();
        let mut a = DMatrix::zeros(n * n_joints, dim);
        let mut b = DVector::zeros(n * n_joints);
        for p in 0..n {
            let s = self.warp.at(rows.phases()[p])[0];
            let target = along(path, s);
            let at_mean = rows.position(p, &mean);
            let jacobian = rows.position_jacobian(p);
            for j in 0..n_joints {
                a.set_row(p * n_joints + j, &jacobian.row(j));
                b[p * n_joints + j] = target[j] - at_mean[j];
            }
        }
        let mut normal = a.transpose() * &a;
        for i in 0..dim {
            normal[(i, i)] += FIT_RIDGE;
        }
        let z = normal.cholesky()?.solve(&(a.transpose() * b));
        z.iter().all(|v| v.is_finite()).then_some(z)
    }
}

/// A uniform sample of the box of the problem's joint position bounds.
pub(super) fn uniform_configuration(linear: &LinearSet, rng: &mut impl Rng) -> Vec<f64> {
    linear
        .lower
        .iter()
        .zip(&linear.upper)
        .map(|(lo, hi)| rng.gen_range(*lo..=*hi))
        .collect()
}

/// The configuration a fraction `s` in [0, 1] of the way along `path`, by
/// joint-space length (max-norm).
fn along(path: &[Vec<f64>], s: f64) -> Vec<f64> {
    let lengths: Vec<f64> = path.windows(2).map(|w| max_norm(&w[0], &w[1])).collect();
    let total: f64 = lengths.iter().sum();
    if total <= 0.0 || path.len() < 2 {
        return path[0].clone();
    }
    let mut left = s.clamp(0.0, 1.0) * total;
    for (k, &l) in lengths.iter().enumerate() {
        if left <= l || k == lengths.len() - 1 {
            return lerp(
                &path[k],
                &path[k + 1],
                if l > 0.0 { (left / l).min(1.0) } else { 1.0 },
            );
        }
        left -= l;
    }
    path[path.len() - 1].clone()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::OptimizeRequest;
    use crate::robot::Robot;

    /// Joint 1 from -1 to +1 rad in the ready pose across a wall 75 cm
    /// tall in front of the robot (as `tests/integration/optim_global.rs`).
    fn swing_across_a_wall() -> OptimizeRequest {
        let text = r#"{
            "start": [-1.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785],
            "options": {"final_configuration": [1.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]},
            "boundary": "rest", "duration_s": 4.0, "clearance_m": 0.01,
            "obstacles": [{"type": "box", "id": "wall", "center": [0.55, 0.0, 0.375],
                "half_extents": [0.3, 0.01, 0.375], "rotation": [0.0, 0.0, 0.0, 1.0]}]
        }"#;
        serde_json::from_str(text).unwrap()
    }

    /// Every configuration the planner checked on its path (the nodes and
    /// the edges' points at [`EDGE_RESOLUTION_RAD`]) clears the wall by
    /// what it promises, measured by the unculled exact query over every
    /// pair ([`crate::scene::Scene::min_clearance`], not the culled one the
    /// planner uses); the path joins the two ends and its seed is finite.
    #[test]
    fn the_planned_path_clears_the_wall_where_it_was_checked() {
        let robot = Robot::panda().unwrap();
        let p = swing_across_a_wall().validate(&robot).unwrap();
        let start = p.linear.start.clone().unwrap();
        let goal = p.linear.final_configuration.clone().unwrap();
        let mut planner = Planner {
            problem: &p,
            ends: [start.clone(), goal.clone()],
            rng: ChaCha8Rng::seed_from_u64(p.options.seed ^ PATH_STREAM),
        };
        assert!(
            !planner.edge_free(&start, &goal),
            "the wall blocks the line"
        );
        let path = planner
            .rrt_connect(start.clone(), goal.clone(), &|| false)
            .expect("a path around the wall");
        let path = planner.shortcut(path);
        assert_eq!(path.first(), Some(&start));
        assert_eq!(path.last(), Some(&goal));
        let exact = |q: &[f64]| {
            p.scene
                .min_clearance(&p.robot, &p.robot.fk(q))
                .unwrap()
                .distance
        };
        let mut checked = 0;
        for edge in path.windows(2) {
            let steps = (max_norm(&edge[0], &edge[1]) / EDGE_RESOLUTION_RAD)
                .ceil()
                .max(1.0) as usize;
            for k in 0..=steps {
                let q = lerp(&edge[0], &edge[1], k as f64 / steps as f64);
                let near_end = planner.ends.iter().any(|e| max_norm(e, &q) <= END_ZONE_RAD);
                let promised = p.clearance_m + if near_end { 0.0 } else { PATH_MARGIN_M };
                assert!(exact(&q) >= promised, "{} < {promised}", exact(&q));
                checked += 1;
            }
        }
        assert!(checked > 10, "{checked}");
        let z = p.fit_path(&path).expect("a finite seed");
        assert!(z.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn along_walks_the_path_by_length() {
        let path = vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![1.0, 3.0]];
        assert_eq!(along(&path, 0.0), vec![0.0, 0.0]);
        assert_eq!(along(&path, 0.25), vec![1.0, 0.0]);
        assert_eq!(along(&path, 0.5), vec![1.0, 1.0]);
        assert_eq!(along(&path, 1.0), vec![1.0, 3.0]);
    }
}
