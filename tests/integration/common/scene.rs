//! Obstacle builders of the scene and optimiser tests.

use dpmp::geometry::Sphere;
use dpmp::scene::{Obstacle, ObstacleShape};

/// The obstacle `id` with `shape`.
pub fn obstacle(id: &str, shape: ObstacleShape) -> Obstacle {
    Obstacle {
        id: id.into(),
        shape,
    }
}

/// The sphere obstacle `id` at `center` with `radius`.
pub fn sphere(id: &str, center: [f64; 3], radius: f64) -> Obstacle {
    obstacle(id, ObstacleShape::Sphere(Sphere { center, radius }))
}
