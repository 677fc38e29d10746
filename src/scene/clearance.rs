//! Robot-versus-scene clearance queries: the minimum signed distance over
//! every (robot primitive, obstacle) pair, the pairs within an activation
//! distance, and the gradient of a pair's distance with respect to the
//! joint angles.
//!
//! The broad phase is a bounds check: each robot primitive's axis-aligned
//! box (after forward kinematics) against each obstacle's (precomputed);
//! pairs whose boxes are further apart than the current best (or the
//! activation distance) never reach parry.

use super::broadphase::{Bounds, Core};
use super::contact::PairContact;
use super::distance::pair_contact;
use super::part_tree::PartTree;
use super::shape::{CompiledObstacle, RobotPart};
use super::Scene;
use crate::geometry::Slabs;
use crate::robot::{Frames, Robot, ShapeGeometry};
use nalgebra::{DVector, Point3};
use serde::Serialize;
use std::cell::{OnceCell, RefCell};

/// The signed distance between one robot primitive and one obstacle.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Clearance {
    /// Signed distance (m), negative when penetrating.
    pub distance: f64,
    /// Index into `robot.collision_shapes()`.
    pub shape: usize,
    /// Index of the primitive's link in `robot.link_names()`
    /// ([`Clearance::link_name`] reads its name).
    pub link: usize,
    /// Index of the obstacle in `scene.obstacles()`
    /// ([`Clearance::obstacle_id`] reads its id).
    pub obstacle: usize,
    /// Witness point on the robot (base frame).
    pub point_robot: [f64; 3],
    /// Witness point on the obstacle (base frame).
    pub point_obstacle: [f64; 3],
    /// Unit normal from the obstacle towards the robot: moving the robot
    /// witness point along it increases the distance.
    pub normal: [f64; 3],
}

impl Clearance {
    /// Name of the robot link, from the robot the query ran on.
    pub fn link_name<'r>(&self, robot: &'r Robot) -> &'r str {
        &robot.link_names()[self.link]
    }

    /// Id of the obstacle, from the scene the query ran on.
    pub fn obstacle_id<'s>(&self, scene: &'s Scene) -> &'s str {
        &scene.obstacles()[self.obstacle].id
    }

    /// `link L is D m from obstacle 'O'`, for messages.
    pub fn describe(&self, robot: &Robot, scene: &Scene) -> String {
        format!(
            "link {} is {:.4} m from obstacle '{}'",
            self.link_name(robot),
            self.distance,
            self.obstacle_id(scene)
        )
    }
}

/// A robot primitive placed by forward kinematics.
pub(crate) struct PlacedShape {
    pub index: usize,
    pub part: RobotPart,
    pub bounds: Bounds,
    pub core: Core,
    /// A mesh link's k-DOP at the link's pose, placed on first use.
    slabs: OnceCell<Option<Slabs>>,
}

impl PlacedShape {
    fn new(index: usize, part: RobotPart, bounds: Bounds, core: Core) -> PlacedShape {
        PlacedShape {
            index,
            part,
            bounds,
            core,
            slabs: OnceCell::new(),
        }
    }

    /// The hull's k-DOP in the base frame (mesh links only).
    fn slabs(&self) -> Option<&Slabs> {
        self.slabs
            .get_or_init(|| match &self.part {
                RobotPart::Convex(hull, link_pose, _) => Some(hull.slabs().placed(link_pose)),
                RobotPart::Primitive(..) => None,
            })
            .as_ref()
    }

    /// Whether the lower bounds rule out a distance below `limit` to a part
    /// inside `core`: the cores' gap, then (mesh links) the k-DOP's gap less
    /// the hull's allowance, a bound within millimetres of the hull where
    /// the bounding capsule is centimetres off.
    fn rules_out(&self, core: &Core, limit: f64) -> bool {
        if ruled_out(self.core.gap(core), limit) {
            return true;
        }
        self.slabs().is_some_and(|s| {
            let gap = s.segment_gap(&core.a, &core.b) - core.radius - self.part.allowance();
            ruled_out(gap, limit)
        })
    }

    /// A lower bound on the distance to anything in the box `b`: the boxes'
    /// gap, and (mesh links, when that gap does not already rule out
    /// `limit`) the k-DOP's gap less the hull's allowance.
    fn box_gap(&self, b: &Bounds, limit: f64) -> f64 {
        let gap = b.gap(&self.bounds);
        match self.slabs() {
            Some(s) if !ruled_out(gap, limit) => {
                gap.max(s.box_gap(&b.min, &b.max) - self.part.allowance())
            }
            _ => gap,
        }
    }
}

/// Every robot primitive in the base frame for `frames`.
pub(crate) fn place_robot(robot: &Robot, frames: &Frames) -> Vec<PlacedShape> {
    (0..robot.collision_shapes().len())
        .map(|index| place_shape(robot, frames, index))
        .collect()
}

/// Robot primitive `index` in the base frame for `frames`.
fn place_shape(robot: &Robot, frames: &Frames, index: usize) -> PlacedShape {
    let s = &robot.collision_shapes()[index];
    let pose = &frames.poses[s.link];
    match &s.geometry {
        // A hull stays in its link frame: only its bounding capsule moves.
        ShapeGeometry::Convex(hull) => {
            let (a, b, r) = hull.bound();
            let (a, b) = (
                (pose * Point3::from(a)).coords,
                (pose * Point3::from(b)).coords,
            );
            PlacedShape::new(
                index,
                RobotPart::convex(hull, pose),
                Bounds::capsule(&a, &b, r),
                Core::new(a, b, r),
            )
        }
        ShapeGeometry::Primitive(p) => {
            let world = p.transformed(pose);
            PlacedShape::new(
                index,
                RobotPart::primitive(&world),
                Bounds::of_primitive(&world),
                Core::of_primitive(&world),
            )
        }
    }
}

/// Prediction beyond the first estimate with which the seed pair is
/// measured again when its obstacle is long (m).
const RESEED_MARGIN_M: f64 = 0.05;

/// Whether a lower bound `gap` rules out a distance below `limit`: when
/// `gap >= limit` and the shapes do not touch (a penetration can be deeper
/// than any negative limit only while the bounds overlap).
#[inline]
fn ruled_out(gap: f64, limit: f64) -> bool {
    gap >= limit && gap > 0.0
}

/// Closest contact between a placed primitive and every part of an
/// obstacle, below `prediction`; parts whose cores are too far are skipped.
/// (An obstacle of a few parts is scanned with the cores' gap alone: the
/// k-DOP's bound saves no time there, measured on the typical and hard
/// sets; it pays in a cloud's tree, [`tree_contact`].)
fn obstacle_contact(
    shape: &PlacedShape,
    obstacle: &CompiledObstacle,
    prediction: f64,
) -> Option<PairContact> {
    if let Some(tree) = &obstacle.tree {
        return tree_contact(shape, obstacle, tree, prediction);
    }
    obstacle
        .parts
        .iter()
        .filter(|part| !ruled_out(shape.core.gap(&part.core), prediction))
        .filter_map(|part| pair_contact(&shape.part, part, prediction))
        .min_by(|a, b| a.distance.total_cmp(&b.distance))
}

/// [`obstacle_contact`] through the obstacle's part tree: only the parts
/// whose boxes come within the closest contact found so far (at first
/// `prediction`) are measured; the first of equally close parts wins.
///
/// Beside the k-DOP, each contact found with a hull adds its supporting
/// plane ([`SupportPlanes`]): a cloud's points crowd around the closest one,
/// and the plane through the hull's witness point bounds their distance to
/// within what their offset along it is, so most of them never reach the
/// exact query.
fn tree_contact(
    shape: &PlacedShape,
    obstacle: &CompiledObstacle,
    tree: &PartTree,
    prediction: f64,
) -> Option<PairContact> {
    let mut best: Option<PairContact> = None;
    let mut limit = prediction;
    let planes = RefCell::new(SupportPlanes::new());
    // The limit only falls below `prediction`, so a box the cheap bounds
    // put beyond `prediction` needs no finer one.
    let node_gap = |b: &Bounds| {
        let gap = shape.box_gap(b, prediction);
        if ruled_out(gap, prediction) {
            return gap;
        }
        gap.max(planes.borrow().box_gap(b))
    };
    tree.visit(node_gap, prediction, |i| {
        let part = &obstacle.parts[i];
        if ruled_out(planes.borrow().core_gap(&part.core), limit)
            || shape.rules_out(&part.core, limit)
        {
            return limit;
        }
        if let Some(c) = pair_contact(&shape.part, part, limit) {
            if matches!(shape.part, RobotPart::Convex(..)) {
                planes.borrow_mut().add(&c);
            }
            if best.is_none_or(|b| c.distance < b.distance) {
                limit = c.distance.min(prediction);
                best = Some(c);
            }
        }
        limit
    });
    best
}

/// Slack (m) added to a supporting plane's offset: the hull's vertices were
/// measured up to 2e-9 m beyond the plane through an `f64` witness (the
/// rounding of the witness on its triangle), far below the hull's
/// allowance.
const SUPPORT_SLACK_M: f64 = 1e-7;

/// Supporting planes of a hull from contacts found in one query, at most
/// [`SupportPlanes::CAPACITY`]: for a contact at positive distance the
/// hull's witness point is the closest point of a convex set, so the hull
/// lies behind the plane through it normal to the contact, and `u·(y − p)`
/// (`u` from the hull towards the obstacle, `p` the reported robot witness,
/// already moved out by the hull's allowance) is a lower bound on the
/// reported distance of anything `y`: the planes make a polytope around the
/// hull whose gaps are [`Slabs`]' gaps.
struct SupportPlanes(Slabs);

impl SupportPlanes {
    const CAPACITY: usize = 4;

    fn new() -> SupportPlanes {
        SupportPlanes(Slabs::unbounded())
    }

    /// Keep the plane of `contact` when it is a separated one.
    fn add(&mut self, contact: &PairContact) {
        if contact.distance > 0.0 && self.0.len() < Self::CAPACITY {
            let u = -contact.normal;
            self.0
                .add_plane(u, u.dot(&contact.point_robot) + SUPPORT_SLACK_M);
        }
    }

    /// Lower bound on the distance to a part inside `core` (−∞ with no plane).
    #[inline]
    fn core_gap(&self, core: &Core) -> f64 {
        self.0.segment_gap(&core.a, &core.b) - core.radius
    }

    /// Lower bound on the distance to anything in the box `b`.
    #[inline]
    fn box_gap(&self, b: &Bounds) -> f64 {
        self.0.box_gap(&b.min, &b.max)
    }
}

impl Scene {
    /// The minimum signed distance between the robot at `frames` and the
    /// scene, with the responsible primitive, link and obstacle; `None` when
    /// the scene is empty.
    pub fn min_clearance(&self, robot: &Robot, frames: &Frames) -> Option<Clearance> {
        let (shape, obstacle, contact) = self.closest_pair(robot, &place_robot(robot, frames))?;
        Some(self.clearance(robot, shape, obstacle, &contact))
    }

    /// Every (robot primitive, obstacle) pair closer than `activation_m`
    /// (signed), in primitive-then-obstacle order.
    pub fn clearances_within(
        &self,
        robot: &Robot,
        frames: &Frames,
        activation_m: f64,
    ) -> Vec<Clearance> {
        let mut out = Vec::new();
        self.visit_contacts(robot, frames, activation_m, |shape, k, contact| {
            out.push(self.clearance(robot, shape, k, &contact));
            activation_m
        });
        out
    }

    /// The closest (robot primitive, obstacle) pair closer than
    /// `activation_m` (signed): the minimum of [`Scene::clearances_within`]
    /// (first in its order on ties), found by branch and bound — each pair
    /// is computed only while its lower bounds do not rule it out against
    /// the closest pair found so far.
    pub fn closest_within(
        &self,
        robot: &Robot,
        frames: &Frames,
        activation_m: f64,
    ) -> Option<Clearance> {
        let mut best = None;
        self.visit_contacts(robot, frames, activation_m, |shape, k, contact| {
            let distance = contact.distance;
            best = Some((shape, k, contact));
            distance
        });
        best.map(|(shape, k, contact)| self.clearance(robot, shape, k, &contact))
    }

    /// Visit, in primitive-then-obstacle order, every pair whose contact is
    /// closer than the current limit (starting at `limit`; pairs the broad
    /// phase rules out against it are skipped). `visit` gets (primitive,
    /// obstacle, contact) and returns the limit for the rest.
    fn visit_contacts(
        &self,
        robot: &Robot,
        frames: &Frames,
        mut limit: f64,
        mut visit: impl FnMut(usize, usize, PairContact) -> f64,
    ) {
        if self.is_empty() || !limit.is_finite() {
            return;
        }
        let Some(all) = self.bounds else {
            return;
        };
        for index in 0..robot.collision_shapes().len() {
            let shape = place_shape(robot, frames, index);
            if ruled_out(shape.bounds.gap(&all), limit) {
                continue;
            }
            for (k, obstacle) in self.compiled.iter().enumerate() {
                if ruled_out(shape.bounds.gap(&obstacle.bounds), limit) {
                    continue;
                }
                if let Some(contact) = obstacle_contact(&shape, obstacle, limit) {
                    if contact.distance < limit {
                        limit = visit(shape.index, k, contact);
                    }
                }
            }
        }
    }

    /// The signed distance of one (robot primitive, obstacle) pair at
    /// `frames`, however far apart; `None` for an index out of range.
    pub fn pair_clearance(
        &self,
        robot: &Robot,
        frames: &Frames,
        shape: usize,
        obstacle: usize,
    ) -> Option<Clearance> {
        if shape >= robot.collision_shapes().len() {
            return None;
        }
        let compiled = self.compiled.get(obstacle)?;
        let placed = place_shape(robot, frames, shape);
        let far = placed.bounds.gap(&compiled.bounds).max(0.0) + self.bounds_diameter() + 1.0;
        let contact = obstacle_contact(&placed, compiled, far)?;
        Some(self.clearance(robot, shape, obstacle, &contact))
    }

    /// The signed distance of one (robot primitive, obstacle) pair at
    /// `frames` when it is below `limit`, else `limit`: a lower bound on the
    /// pair's distance either way, from one placed primitive and one exact
    /// query (the continuous certificate's bisection follows only the pairs
    /// it has not certified yet). `limit` for an index out of range.
    pub fn pair_distance_below(
        &self,
        robot: &Robot,
        frames: &Frames,
        shape: usize,
        obstacle: usize,
        limit: f64,
    ) -> f64 {
        let Some(compiled) = self.compiled.get(obstacle) else {
            return limit;
        };
        if shape >= robot.collision_shapes().len() {
            return limit;
        }
        let placed = place_shape(robot, frames, shape);
        if ruled_out(placed.bounds.gap(&compiled.bounds), limit) {
            return limit;
        }
        obstacle_contact(&placed, compiled, limit).map_or(limit, |c| c.distance.min(limit))
    }

    /// `d(c.distance)/dq` at configuration `q` (whose forward kinematics is
    /// `frames`): the normal times the Jacobian of the robot witness point on
    /// its link. `dof` entries.
    pub fn clearance_gradient(
        &self,
        robot: &Robot,
        q: &[f64],
        frames: &Frames,
        c: &Clearance,
    ) -> DVector<f64> {
        debug_assert_eq!(q.len(), robot.dof());
        let point = Point3::from(c.point_robot);
        let normal = nalgebra::Vector3::from(c.normal);
        robot.point_velocity_along(frames, c.link, &point, &normal)
    }

    /// The minimum clearance at `q` and its gradient (one forward kinematics).
    pub fn min_clearance_with_gradient(
        &self,
        robot: &Robot,
        q: &[f64],
    ) -> Option<(Clearance, DVector<f64>)> {
        let frames = robot.fk(q);
        let c = self.min_clearance(robot, &frames)?;
        let g = self.clearance_gradient(robot, q, &frames, &c);
        Some((c, g))
    }

    /// The closest (primitive index, obstacle index, contact): the pair
    /// with the smallest bounds gap first, then every pair whose bounds gap
    /// is below the best distance so far.
    fn closest_pair(
        &self,
        robot: &Robot,
        placed: &[PlacedShape],
    ) -> Option<(usize, usize, PairContact)> {
        if self.is_empty() || placed.is_empty() || robot.collision_shapes().is_empty() {
            return None;
        }
        let mut seed = (0, 0, f64::INFINITY);
        for (s, shape) in placed.iter().enumerate() {
            for (k, obstacle) in self.compiled.iter().enumerate() {
                let gap = shape.bounds.gap(&obstacle.bounds);
                if gap < seed.2 {
                    seed = (s, k, gap);
                }
            }
        }
        let far = seed.2 + self.bounds_diameter() + 1.0;
        let mut first = obstacle_contact(&placed[seed.0], &self.compiled[seed.1], far)?;
        if self.compiled[seed.1].parts.iter().any(|p| p.long.is_some()) {
            // At the first, scene-sized prediction a long part is hardly cut
            // ([`super::clip`]): measure the seed pair again near its result.
            let near = first.distance.max(0.0) + RESEED_MARGIN_M;
            if let Some(again) = obstacle_contact(&placed[seed.0], &self.compiled[seed.1], near) {
                first = again;
            }
        }
        let mut best = (placed[seed.0].index, seed.1, first);
        let all = self.bounds?;
        for (s, shape) in placed.iter().enumerate() {
            if ruled_out(shape.bounds.gap(&all), best.2.distance) {
                continue;
            }
            for (k, obstacle) in self.compiled.iter().enumerate() {
                if (s, k) == (seed.0, seed.1)
                    || ruled_out(shape.bounds.gap(&obstacle.bounds), best.2.distance)
                {
                    continue;
                }
                if let Some(contact) = obstacle_contact(shape, obstacle, best.2.distance) {
                    if contact.distance < best.2.distance {
                        best = (shape.index, k, contact);
                    }
                }
            }
        }
        Some(best)
    }

    fn clearance(
        &self,
        robot: &Robot,
        shape: usize,
        obstacle: usize,
        contact: &PairContact,
    ) -> Clearance {
        let link_shape = &robot.collision_shapes()[shape];
        Clearance {
            distance: contact.distance,
            shape,
            link: link_shape.link,
            obstacle,
            point_robot: contact.point_robot.into(),
            point_obstacle: contact.point_obstacle.into(),
            normal: contact.normal.into(),
        }
    }
}
