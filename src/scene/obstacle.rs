//! Obstacle types (the request schema of DESIGN.md) and their validation.
//!
//! ```json
//! {"id": "berry-2", "type": "sphere", "center": [x, y, z], "radius": 0.015}
//! {"id": "stem-2", "type": "capsule", "a": [x, y, z], "b": [x, y, z], "radius": 0.003}
//! {"id": "post", "type": "cylinder", "a": [x, y, z], "b": [x, y, z], "radius": 0.02}
//! {"id": "tray", "type": "box", "center": [x, y, z], "half_extents": [a, b, c], "rotation": [0, 0, 0, 1]}
//! {"id": "leaf", "type": "convex", "points": [[x, y, z], ...]}
//! {"id": "berry-3", "type": "berry", "center": [x, y, z], "radius": 0.014,
//!  "elongation": 0.006, "stem_top": [x, y, z], "stem_radius": 0.002}
//! {"id": "sensed", "type": "points", "points": [[x, y, z], ...], "radius": 0.005}
//! {"id": "sensed", "type": "points", "points_base64": "<x, y, z as little-endian f32>", "radius": 0.005}
//! ```
//!
//! Unknown fields are rejected; a box `rotation` defaults to identity. A
//! dataset's `"intruder": true` label is accepted and set aside (see
//! [`super::obstacle_read`]), so every scene dPMP writes posts as it is.

use crate::geometry::{midpoint, Capsule, OrientedBox, Primitive, Sphere};
use crate::{Error, Result};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Quaternions whose norm is further than this from 1 are rejected (closer
/// ones are normalised).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Largest accepted coordinate magnitude (m, base frame): a robot cell is a
/// few metres across; beyond this the distance arithmetic loses the
/// precision the certificate needs.
pub const MAX_COORDINATE_M: f64 = 100.0;

/// Largest accepted size (radius, half extent, elongation; m).
pub const MAX_SIZE_M: f64 = 100.0;

/// Largest number of points in one `points` obstacle (a 640 x 480 depth
/// image downsampled to 5 mm voxels gives a few thousand).
pub const MAX_CLOUD_POINTS: usize = 100_000;

/// Smallest accepted size (m): a nanometre, far below any real obstacle
/// and still a normal single-precision number for the narrow phase.
pub const MIN_SIZE_M: f64 = 1e-9;

/// A finite coordinate within ±[`MAX_COORDINATE_M`].
fn valid_coordinate(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_COORDINATE_M
}

/// One named obstacle.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Obstacle {
    /// Unique, non-empty name (reported as the closest obstacle).
    pub id: String,
    /// The geometry.
    #[serde(flatten)]
    pub shape: ObstacleShape,
}

/// Obstacle geometry, tagged by `"type"`; all convex (a berry is the union of
/// two convex parts).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ObstacleShape {
    /// A ball.
    Sphere(Sphere),
    /// Points within `radius` of the segment `a`–`b`.
    Capsule(Capsule),
    /// A flat-ended cylinder between `a` and `b`.
    Cylinder {
        /// Centre of the first end face.
        a: [f64; 3],
        /// Centre of the second end face (distinct from `a`).
        b: [f64; 3],
        /// Radius (m, > 0).
        radius: f64,
    },
    /// An oriented box (`rotation` defaults to identity).
    Box(OrientedBox),
    /// The convex hull of at least 4 non-coplanar points.
    Convex {
        /// Hull points.
        points: Vec<[f64; 3]>,
    },
    /// A strawberry with its stem ([`BerryShape`]).
    Berry(BerryShape),
    /// A point cloud (base frame): every point within `radius` of one of
    /// `points`, e.g. a depth camera's surface samples inflated by its
    /// noise. Not convex: clearance is to the closest point's ball.
    Points {
        /// The points (at least one, at most [`MAX_CLOUD_POINTS`]).
        points: Vec<[f64; 3]>,
        /// Radius of the ball around each point (m, > 0).
        radius: f64,
    },
}

/// A strawberry with its stem: the body is the set of points within
/// `radius` of the segment of half-length `elongation` through `center`
/// along the stem direction (a sphere when `elongation` is 0, an
/// ellipsoid-like capsule otherwise); the stem is a capsule of
/// `stem_radius` from the top of the body to `stem_top`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BerryShape {
    /// Centre of the body.
    pub center: [f64; 3],
    /// Body radius across the stem axis (m, > 0).
    pub radius: f64,
    /// Extra half-length of the body along the stem axis (m, >= 0).
    #[serde(default)]
    pub elongation: f64,
    /// Upper end of the stem (where it joins the plant); it sets the
    /// stem axis and must lie outside the body.
    pub stem_top: [f64; 3],
    /// Stem radius (m, > 0, at most `radius`).
    #[serde(default = "default_stem_radius")]
    pub stem_radius: f64,
}

/// The `--scene FILE.json` format: `{"obstacles": [...]}`.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// The obstacles, in the request schema.
    pub obstacles: Vec<Obstacle>,
}

fn default_stem_radius() -> f64 {
    0.002
}

impl ObstacleShape {
    /// The shared primitive, for a sphere, capsule or box.
    pub fn primitive(&self) -> Option<Primitive> {
        match self {
            ObstacleShape::Sphere(s) => Some((*s).into()),
            ObstacleShape::Capsule(c) => Some((*c).into()),
            ObstacleShape::Box(b) => Some((*b).into()),
            ObstacleShape::Cylinder { .. }
            | ObstacleShape::Convex { .. }
            | ObstacleShape::Berry(_)
            | ObstacleShape::Points { .. } => None,
        }
    }

    /// The number of cloud points (0 for every shape but `points`).
    pub fn point_count(&self) -> usize {
        match self {
            ObstacleShape::Points { points, .. } => points.len(),
            _ => 0,
        }
    }

    /// A representative point of the obstacle (its centre).
    pub fn center(&self) -> [f64; 3] {
        match self {
            ObstacleShape::Sphere(s) => s.center,
            ObstacleShape::Box(b) => b.center,
            ObstacleShape::Berry(berry) => berry.center,
            ObstacleShape::Capsule(Capsule { a, b, .. }) | ObstacleShape::Cylinder { a, b, .. } => {
                midpoint(a, b)
            }
            ObstacleShape::Convex { points } | ObstacleShape::Points { points, .. } => {
                let sum = points
                    .iter()
                    .fold(Vector3::zeros(), |s, p| s + Vector3::from(*p));
                (sum / points.len().max(1) as f64).into()
            }
        }
    }
}

impl Obstacle {
    /// Validate one obstacle; errors name `obstacles[index].<field>` and the id.
    pub fn validate(&self, index: usize) -> Result<()> {
        let check = Check {
            index,
            id: &self.id,
        };
        match &self.shape {
            ObstacleShape::Sphere(s) => check.sphere(s),
            ObstacleShape::Capsule(c) => check.capsule(c),
            ObstacleShape::Cylinder { a, b, radius } => check.cylinder(a, b, *radius),
            ObstacleShape::Box(b) => check.oriented_box(b),
            ObstacleShape::Convex { points } => check.convex(points),
            ObstacleShape::Berry(berry) => check.berry(berry),
            ObstacleShape::Points { points, radius } => check.cloud(points, *radius),
        }
    }
}

/// The validation of obstacle `index` (named `id`): errors name the field
/// `obstacles[index].<field>` and say `obstacle "<id>": <message>`.
struct Check<'a> {
    index: usize,
    id: &'a str,
}

impl Check<'_> {
    /// The error for `field`.
    fn fail(&self, field: &str, msg: impl std::fmt::Display) -> Error {
        Error::invalid(
            format!("obstacles[{}].{field}", self.index),
            format!("obstacle \"{}\": {msg}", self.id),
        )
    }

    /// Every value a coordinate within ±[`MAX_COORDINATE_M`]; the first
    /// that is not is named `field[i]`.
    fn finite(&self, field: &str, values: &[f64]) -> Result<()> {
        match values.iter().position(|&v| !valid_coordinate(v)) {
            None => Ok(()),
            Some(i) => Err(self.fail(
                &format!("{field}[{i}]"),
                format!(
                    "must be a finite coordinate within ±{MAX_COORDINATE_M} m, got {}",
                    values[i]
                ),
            )),
        }
    }

    /// A size in [[`MIN_SIZE_M`], [`MAX_SIZE_M`]].
    fn positive(&self, field: &str, v: f64) -> Result<()> {
        if v.is_finite() && (MIN_SIZE_M..=MAX_SIZE_M).contains(&v) {
            Ok(())
        } else {
            Err(self.fail(
                field,
                format!("must be a size in [{MIN_SIZE_M}, {MAX_SIZE_M}] m, got {v}"),
            ))
        }
    }

    /// Finite centre, radius > 0.
    fn sphere(&self, s: &Sphere) -> Result<()> {
        self.finite("center", &s.center)?;
        self.positive("radius", s.radius)
    }

    /// Finite ends, radius > 0.
    fn capsule(&self, c: &Capsule) -> Result<()> {
        self.finite("a", &c.a)?;
        self.finite("b", &c.b)?;
        self.positive("radius", c.radius)
    }

    /// Finite, distinct end-face centres, radius > 0.
    fn cylinder(&self, a: &[f64; 3], b: &[f64; 3], radius: f64) -> Result<()> {
        self.finite("a", a)?;
        self.finite("b", b)?;
        self.positive("radius", radius)?;
        if distance(a, b) < 1e-9 {
            return Err(self.fail("b", "must differ from a (zero-length cylinder)"));
        }
        Ok(())
    }

    /// Finite centre, half extents > 0, a unit quaternion.
    fn oriented_box(&self, b: &OrientedBox) -> Result<()> {
        self.finite("center", &b.center)?;
        for (i, h) in b.half_extents.iter().enumerate() {
            self.positive(&format!("half_extents[{i}]"), *h)?;
        }
        self.finite("rotation", &b.rotation)?;
        let norm = b.rotation.iter().map(|x| x * x).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(self.fail(
                "rotation",
                format!("must be a unit quaternion [x, y, z, w], norm is {norm}"),
            ));
        }
        Ok(())
    }

    /// At least 4 finite, non-coplanar points.
    fn convex(&self, points: &[[f64; 3]]) -> Result<()> {
        for (i, p) in points.iter().enumerate() {
            self.finite(&format!("points[{i}]"), p)?;
        }
        if points.len() < 4 {
            return Err(self.fail(
                "points",
                format!(
                    "a convex hull needs at least 4 points, got {}",
                    points.len()
                ),
            ));
        }
        if hull_thickness(points) < 1e-6 {
            return Err(self.fail("points", "the points are coplanar (the hull has no volume)"));
        }
        Ok(())
    }

    /// One to [`MAX_CLOUD_POINTS`] finite points, radius > 0.
    fn cloud(&self, points: &[[f64; 3]], radius: f64) -> Result<()> {
        if points.is_empty() || points.len() > MAX_CLOUD_POINTS {
            return Err(self.fail(
                "points",
                format!(
                    "a point cloud needs 1 to {MAX_CLOUD_POINTS} points, got {}",
                    points.len()
                ),
            ));
        }
        // The field name is formatted only for the first bad point.
        if let Some(i) = points
            .iter()
            .position(|p| !p.iter().copied().all(valid_coordinate))
        {
            self.finite(&format!("points[{i}]"), &points[i])?;
        }
        self.positive("radius", radius)
    }

    /// Finite centre and stem top outside the body; radius > 0, elongation
    /// >= 0, 0 < stem radius <= radius.
    fn berry(&self, b: &BerryShape) -> Result<()> {
        self.finite("center", &b.center)?;
        self.positive("radius", b.radius)?;
        if !(b.elongation.is_finite() && (0.0..=MAX_SIZE_M).contains(&b.elongation)) {
            return Err(self.fail(
                "elongation",
                format!("must be in [0, {MAX_SIZE_M}] m, got {}", b.elongation),
            ));
        }
        self.finite("stem_top", &b.stem_top)?;
        self.positive("stem_radius", b.stem_radius)?;
        if b.stem_radius > b.radius {
            return Err(self.fail(
                "stem_radius",
                format!(
                    "must not exceed the radius {}, got {}",
                    b.radius, b.stem_radius
                ),
            ));
        }
        if distance(&b.center, &b.stem_top) <= b.radius + b.elongation {
            return Err(self.fail("stem_top", "must lie outside the berry body"));
        }
        Ok(())
    }
}

/// Validate a list of obstacles: each one, plus unique non-empty ids.
pub fn validate_obstacles(obstacles: &[Obstacle]) -> Result<()> {
    let mut seen = std::collections::HashMap::new();
    for (i, obstacle) in obstacles.iter().enumerate() {
        if obstacle.id.trim().is_empty() {
            return Err(Error::invalid(
                format!("obstacles[{i}].id"),
                "obstacle id must not be empty",
            ));
        }
        if let Some(first) = seen.insert(obstacle.id.as_str(), i) {
            return Err(Error::invalid(
                format!("obstacles[{i}].id"),
                format!(
                    "obstacle \"{}\": id already used by obstacles[{first}]",
                    obstacle.id
                ),
            ));
        }
        obstacle.validate(i)?;
    }
    Ok(())
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
}

/// Largest distance of any point from the plane through three well-spread
/// points (0 for coplanar or collinear sets).
fn hull_thickness(points: &[[f64; 3]]) -> f64 {
    let v: Vec<Vector3<f64>> = points.iter().map(|p| Vector3::from(*p)).collect();
    let p0 = v[0];
    let Some(p1) = v
        .iter()
        .copied()
        .max_by(|a, b| (a - p0).norm().total_cmp(&(b - p0).norm()))
    else {
        return 0.0;
    };
    let line = p1 - p0;
    if line.norm() < 1e-12 {
        return 0.0;
    }
    let dir = line.normalize();
    let off_line = |p: &Vector3<f64>| ((p - p0) - dir * (p - p0).dot(&dir)).norm();
    let Some(p2) = v
        .iter()
        .copied()
        .max_by(|a, b| off_line(a).total_cmp(&off_line(b)))
    else {
        return 0.0;
    };
    let normal = line.cross(&(p2 - p0));
    if normal.norm() < 1e-12 {
        return 0.0;
    }
    let normal = normal.normalize();
    v.iter()
        .map(|p| (p - p0).dot(&normal).abs())
        .fold(0.0, f64::max)
}
