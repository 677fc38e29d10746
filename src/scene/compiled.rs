//! The [`Scene`]: validated obstacles compiled once into parry shapes and
//! bounds, plus the point query used to diagnose goals inside obstacles.

use super::broadphase::Bounds;
use super::distance::{point_distance, point_signed_distance};
use super::obstacle::{validate_obstacles, Obstacle};
use super::shape::{compile_obstacle, CompiledObstacle};
use crate::{Error, Result};
use nalgebra::Point3;

/// Validated obstacles compiled to parry shapes with a bounds broad phase.
/// Immutable, `Send + Sync`, cheap to share.
#[derive(Clone, Debug)]
pub struct Scene {
    pub(crate) obstacles: Vec<Obstacle>,
    pub(crate) compiled: Vec<CompiledObstacle>,
    pub(crate) bounds: Option<Bounds>,
}

impl Scene {
    /// Validate and compile `obstacles`. Errors name the field
    /// (`obstacles[2].radius`) and mention the id; duplicate or empty ids,
    /// non-finite numbers, non-positive radii, degenerate boxes and hulls of
    /// fewer than 4 non-coplanar points are rejected.
    pub fn new(obstacles: Vec<Obstacle>) -> Result<Scene> {
        validate_obstacles(&obstacles)?;
        let compiled = obstacles
            .iter()
            .enumerate()
            .map(|(i, o)| {
                compile_obstacle(&o.shape).ok_or_else(|| {
                    Error::invalid(
                        format!("obstacles[{i}].points"),
                        format!(
                            "obstacle \"{}\": no convex hull can be built from these points",
                            o.id
                        ),
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let bounds = compiled
            .iter()
            .map(|c| c.bounds)
            .reduce(|a, b| a.merged(&b));
        Ok(Scene {
            obstacles,
            compiled,
            bounds,
        })
    }

    /// A scene without obstacles.
    pub fn empty() -> Scene {
        Scene {
            obstacles: Vec::new(),
            compiled: Vec::new(),
            bounds: None,
        }
    }

    /// Load a `{"obstacles": [...]}` JSON file; errors name the file.
    pub fn from_file(path: &std::path::Path) -> Result<Scene> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        let file: super::SceneFile = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("malformed scene JSON: {e}")))?;
        Scene::new(file.obstacles)
    }

    /// The obstacles, as given.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// Whether there are no obstacles.
    pub fn is_empty(&self) -> bool {
        self.obstacles.is_empty()
    }

    /// Index of the obstacle closest to `p` among those within `margin`
    /// (m) of it (inside counts as 0); `None` when none is that close.
    pub fn obstacle_containing(&self, p: &Point3<f64>, margin: f64) -> Option<usize> {
        self.compiled
            .iter()
            .enumerate()
            .filter(|(_, c)| c.bounds.point_gap(&p.coords) <= margin)
            .map(|(i, c)| {
                let d = c
                    .parts
                    .iter()
                    .map(|part| point_distance(part, &p.coords))
                    .fold(f64::INFINITY, f64::min);
                (i, d)
            })
            .filter(|(_, d)| *d <= margin)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }

    /// The obstacle `p` lies deepest inside and that depth (m, > 0), from
    /// the convex parts (a lower bound on the depth in their union).
    pub fn deepest_containing(&self, p: &Point3<f64>) -> Option<(usize, f64)> {
        self.compiled
            .iter()
            .enumerate()
            .filter(|(_, c)| c.bounds.point_gap(&p.coords) <= 0.0)
            .filter_map(|(i, c)| {
                let depth = c
                    .parts
                    .iter()
                    .map(|part| -point_signed_distance(part, &p.coords))
                    .fold(f64::NEG_INFINITY, f64::max);
                (depth > 0.0).then_some((i, depth))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Diagonal of the box around every obstacle (0 when empty).
    pub(crate) fn bounds_diameter(&self) -> f64 {
        self.bounds.map_or(0.0, |b| (b.max - b.min).norm())
    }
}
