//! A plant as obstacles in the optimise-request schema, so that a dataset
//! record's scene doubles as a benchmark scene.
//!
//! Berries become capsules between their shoulder and tip sphere centres
//! with the shoulder radius (which contains the round-cone berry), stems
//! and petioles capsules, leaflets thin convex slabs, the tray a box.

use crate::scene::{Obstacle, ObstacleShape, SceneFile};
use crate::synth::plant::Plant;

/// Rim points per leaflet hull (each on both faces of the slab).
const LEAF_HULL_POINTS: usize = 8;

fn arr(p: &nalgebra::Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// Every obstacle of the plant (berries first, in berry order).
pub fn plant_obstacles(plant: &Plant) -> Vec<Obstacle> {
    let berries = plant.berries.iter().map(|b| Obstacle {
        id: b.id.clone(),
        shape: ObstacleShape::Capsule {
            a: arr(&b.top),
            b: arr(&b.tip),
            radius: b.r_top,
        },
    });
    let stems = plant.stems.iter().map(|s| Obstacle {
        id: s.id.clone(),
        shape: ObstacleShape::Capsule {
            a: arr(&s.a),
            b: arr(&s.b),
            radius: s.radius,
        },
    });
    let leaves = plant.leaflets.iter().map(|l| Obstacle {
        id: l.id.clone(),
        shape: ObstacleShape::Convex {
            points: l.hull_points(LEAF_HULL_POINTS).iter().map(arr).collect(),
        },
    });
    let tray = plant.tray.iter().map(|t| Obstacle {
        id: "tray".to_string(),
        shape: ObstacleShape::Box {
            center: arr(&t.center),
            half_extents: [t.half_extents.x, t.half_extents.y, t.half_extents.z],
            rotation: [0.0, 0.0, 0.0, 1.0],
        },
    });
    berries.chain(stems).chain(leaves).chain(tray).collect()
}

/// The plant as a scene file.
pub fn plant_scene_file(plant: &Plant) -> SceneFile {
    SceneFile {
        obstacles: plant_obstacles(plant),
    }
}
