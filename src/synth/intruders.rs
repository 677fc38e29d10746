//! Intruders: objects the demonstrations never met, placed across a
//! target's demonstrated mean path after its demonstrations are made
//! (`dpmp data generate --intruders N`), so that the prior and the goal
//! alone run into them and only a planner that knows the world clears them.
//!
//! Each intruder is an unripe berry hanging on its stem (two in three) or
//! a leaflet. It stands at a random phase in [`INTRUDER_PHASES`] of the
//! mean motion, its centre within its own size plus [`OFFSET_M`] of the
//! mean TCP path, on it or beside it where the wrist and forearm pass (a
//! leaflet faces along the path). A draw is kept only when:
//!
//! - the mean trajectory's clearance to it is below [`BLOCKING_M`] (it is
//!   in the way);
//! - the mean's start and final poses keep [`ENDS_CLEAR_M`] from it (the
//!   goal stays reachable);
//! - it stays [`TARGET_GAP_M`] clear of the target berry and outside the
//!   target's box in the image (it does not hide the target the planner
//!   must locate), wholly in view and beyond the camera's near range.
//!
//! The intruders are rendered into the target's colour and depth images
//! and written into its record's scene with `"intruder": true`; the
//! demonstrations are not changed.

use super::obstacles::{berry_obstacle, leaflet_obstacle, stem_obstacle};
use super::plant::{Berry, Leaflet, Plant, Ripeness, StemKind, StemSegment};
use crate::geometry::random_unit;
use crate::perception::Camera;
use crate::robot::Robot;
use crate::scene::{Obstacle, Scene};
use crate::Result;
use nalgebra::{DMatrix, Point3, Vector3};
use rand::Rng;

/// Share of intruders that are berries (the rest are leaflets).
pub const BERRY_FRACTION: f64 = 2.0 / 3.0;
/// Fraction of the motion where intruders stand.
pub const INTRUDER_PHASES: (f64, f64) = (0.3, 0.8);
/// Radius of an intruding berry (m).
pub const BERRY_RADIUS_M: (f64, f64) = (0.01, 0.02);
/// Half length of an intruding leaflet (m).
pub const LEAF_HALF_LENGTH_M: (f64, f64) = (0.025, 0.04);
/// How far beyond its own size an intruder's centre may stand from the
/// mean TCP path (m): the arm's wrist and forearm sweep beside the TCP.
pub const OFFSET_M: f64 = 0.05;
/// The mean trajectory must come closer than this to a kept intruder (m).
pub const BLOCKING_M: f64 = 0.015;
/// The mean's start and final poses keep this much from it (m).
pub const ENDS_CLEAR_M: f64 = 0.02;
/// Gap (m) between an intruder and the target berry's centre beyond both
/// radii.
pub const TARGET_GAP_M: f64 = 0.04;
/// Pixels around the target box an intruder's image must keep out of.
const BOX_MARGIN_PX: f64 = 6.0;
/// Nearest camera depth of an intruder's centre (m): the depth camera sees
/// nothing nearer than about 0.1 m.
const MIN_CAMERA_DEPTH_M: f64 = 0.15;
/// Draws per intruder before the target is given up.
const ATTEMPTS: usize = 600;

/// One intruder: its parts to render and its obstacles.
#[derive(Clone, Debug)]
pub enum Intruder {
    /// An unripe berry and the stem it hangs on.
    Berry(Berry, StemSegment),
    /// A leaflet.
    Leaf(Leaflet),
}

impl Intruder {
    /// Its obstacles (request schema).
    pub fn obstacles(&self) -> Vec<Obstacle> {
        match self {
            Intruder::Berry(b, stem) => vec![berry_obstacle(b, stem.radius), stem_obstacle(stem)],
            Intruder::Leaf(l) => vec![leaflet_obstacle(l)],
        }
    }

    /// Add its parts to `plant` (for rendering).
    pub fn add_to(&self, plant: &mut Plant) {
        match self {
            Intruder::Berry(b, stem) => {
                plant.berries.push(b.clone());
                plant.stems.push(stem.clone());
            }
            Intruder::Leaf(l) => plant.leaflets.push(l.clone()),
        }
    }

    /// Points on its surface's extent (for the image check).
    fn outline(&self) -> Vec<Point3<f64>> {
        match self {
            Intruder::Berry(b, stem) => {
                let mut pts = b.silhouette_points();
                pts.extend([stem.a, stem.b]);
                pts
            }
            Intruder::Leaf(l) => l.hull_points(16),
        }
    }

    fn centre(&self) -> Point3<f64> {
        match self {
            Intruder::Berry(b, _) => b.center,
            Intruder::Leaf(l) => l.center,
        }
    }

    fn size(&self) -> f64 {
        match self {
            Intruder::Berry(b, _) => b.r_top,
            Intruder::Leaf(l) => l.half_length,
        }
    }
}

/// What the placement needs to know about one target.
pub struct TargetView<'a> {
    /// The arm.
    pub robot: &'a Robot,
    /// The camera that takes the images.
    pub camera: &'a Camera,
    /// The target berry.
    pub target: &'a Berry,
    /// Its box in the image (px).
    pub target_box: [f64; 4],
    /// The demonstrations' mean trajectory (`T x dof`).
    pub mean: &'a DMatrix<f64>,
}

/// `n` intruders across the mean path of `view`, or `None` when one of
/// them finds no place within its draws.
pub fn place_intruders(
    view: &TargetView,
    n: usize,
    rng: &mut impl Rng,
) -> Result<Option<Vec<Intruder>>> {
    let tcp = view.robot.tcp_path(view.mean);
    let mut placed = Vec::with_capacity(n);
    for k in 0..n {
        let found = (0..ATTEMPTS)
            .map(|_| draw(&tcp, k, rng))
            .find_map(|candidate| match candidate {
                Some(c) => acceptable(view, &c).map(|ok| ok.then_some(c)).transpose(),
                None => None,
            })
            .transpose()?;
        match found {
            Some(intruder) => placed.push(intruder),
            None => return Ok(None),
        }
    }
    Ok(Some(placed))
}

/// One candidate: intruder `k` (a berry or a leaflet) across the TCP path
/// at a random phase.
fn draw(tcp: &[Vector3<f64>], k: usize, rng: &mut impl Rng) -> Option<Intruder> {
    let n = tcp.len();
    let lo = ((n as f64 * INTRUDER_PHASES.0) as usize).max(1);
    let hi = ((n as f64 * INTRUDER_PHASES.1) as usize).min(n.saturating_sub(2));
    if lo > hi {
        return None;
    }
    let t = rng.gen_range(lo..=hi);
    let tangent = (tcp[t + 1] - tcp[t - 1]).try_normalize(1e-9)?;
    let across = {
        let u = random_unit(rng);
        (u - tangent * u.dot(&tangent)).try_normalize(1e-6)?
    };
    let on_path = Point3::from(tcp[t]);
    let id = format!("intruder-{k}");
    Some(if rng.gen_bool(BERRY_FRACTION) {
        let r = rng.gen_range(BERRY_RADIUS_M.0..BERRY_RADIUS_M.1);
        unripe_berry(
            id,
            on_path + across * rng.gen_range(0.0..r + OFFSET_M),
            r,
            rng,
        )
    } else {
        let half_length = rng.gen_range(LEAF_HALF_LENGTH_M.0..LEAF_HALF_LENGTH_M.1);
        let centre = on_path + across * rng.gen_range(0.0..half_length + OFFSET_M);
        Intruder::Leaf(leaflet_facing(id, centre, &tangent, half_length, rng))
    })
}

/// An unripe berry of shoulder radius `r` centred at `centre`, hanging
/// from a stem 3-6 cm long.
fn unripe_berry(id: String, centre: Point3<f64>, r: f64, rng: &mut impl Rng) -> Intruder {
    let tilt = random_unit(rng) * 0.25;
    let axis = (-Vector3::z() + tilt).normalize();
    let berry = Berry {
        id: id.clone(),
        center: centre,
        top: centre - axis * (0.2 * r),
        tip: centre + axis * (0.6 * r),
        r_top: r,
        r_tip: 0.55 * r,
        ripeness: Ripeness::Unripe(rng.gen_range(0.0..0.6)),
    };
    let calyx = berry.calyx();
    let stem = StemSegment {
        id: format!("{id}-stem"),
        a: calyx,
        b: calyx - axis * rng.gen_range(0.03..0.06),
        radius: rng.gen_range(0.0015..0.0025),
        kind: StemKind::Stem,
    };
    Intruder::Berry(berry, stem)
}

/// A leaflet at `centre` whose plane faces along `tangent` (within ~30°).
fn leaflet_facing(
    id: String,
    centre: Point3<f64>,
    tangent: &Vector3<f64>,
    half_length: f64,
    rng: &mut impl Rng,
) -> Leaflet {
    let normal = (tangent + random_unit(rng) * 0.5).normalize();
    let seed = random_unit(rng);
    let u = (seed - normal * seed.dot(&normal))
        .try_normalize(1e-6)
        .unwrap_or_else(|| normal.cross(&Vector3::x()).normalize());
    Leaflet {
        id,
        center: centre,
        u,
        v: normal.cross(&u),
        half_length,
        half_width: half_length * rng.gen_range(0.5..0.7),
        shade: rng.gen_range(0.3..0.8),
    }
}

/// Whether `c` blocks the mean, leaves its ends and the target clear, and
/// is seen without hiding the target.
fn acceptable(view: &TargetView, c: &Intruder) -> Result<bool> {
    if (c.centre() - view.target.center).norm() < c.size() + view.target.r_top + TARGET_GAP_M {
        return Ok(false);
    }
    if !in_view_beside_the_target(view, c) {
        return Ok(false);
    }
    let scene = Scene::new(c.obstacles())?;
    let clearance = |q: &[f64]| {
        scene
            .min_clearance(view.robot, &view.robot.fk(q))
            .map_or(f64::INFINITY, |x| x.distance)
    };
    let row = |t: usize| -> Vec<f64> { view.mean.row(t).iter().copied().collect() };
    let last = view.mean.nrows() - 1;
    if clearance(&row(0)) < ENDS_CLEAR_M || clearance(&row(last)) < ENDS_CLEAR_M {
        return Ok(false);
    }
    Ok((1..last).any(|t| clearance(&row(t)) < BLOCKING_M))
}

/// Every outline point projects into the image, outside the target box
/// (with a margin), and the centre lies beyond the near range.
fn in_view_beside_the_target(view: &TargetView, c: &Intruder) -> bool {
    let near_enough = view
        .camera
        .project(&c.centre())
        .is_some_and(|(_, z)| z >= MIN_CAMERA_DEPTH_M);
    if !near_enough {
        return false;
    }
    let b = &view.target_box;
    let (w, h) = (
        f64::from(view.camera.intrinsics.width),
        f64::from(view.camera.intrinsics.height),
    );
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in c.outline() {
        let Some(([u, v], _)) = view.camera.project(&p) else {
            return false;
        };
        if !(0.0..w).contains(&u) || !(0.0..h).contains(&v) {
            return false;
        }
        lo = [lo[0].min(u), lo[1].min(v)];
        hi = [hi[0].max(u), hi[1].max(v)];
    }
    let m = BOX_MARGIN_PX;
    hi[0] < b[0] - m || lo[0] > b[2] + m || hi[1] < b[1] - m || lo[1] > b[3] + m
}
