//! A plant as obstacles in the optimise-request schema, so that a dataset
//! record's scene doubles as a benchmark scene.
//!
//! Berries become `berry` obstacles (DESIGN.md): a body of the shoulder
//! radius around the segment between the shoulder and tip sphere centres
//! (which contains the round-cone berry) plus a short calyx stem along the
//! berry axis; stems, peduncles and petioles are capsules, leaflets thin
//! convex slabs, the tray a box.

use crate::geometry::{Capsule, OrientedBox};
use crate::scene::{BerryShape, Obstacle, ObstacleShape, SceneFile};
use crate::synth::plant::{Berry, Leaflet, Plant, StemSegment};

/// Rim points per leaflet hull (each on both faces of the slab).
const LEAF_HULL_POINTS: usize = 8;

fn arr(p: &nalgebra::Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// Length of the calyx stem stub of a berry obstacle beyond the body (m).
pub const CALYX_STEM_M: f64 = 0.008;

/// One berry as a `berry` obstacle with a calyx stem of `stem_radius`
/// (capped at the body radius).
pub fn berry_obstacle(b: &Berry, stem_radius: f64) -> Obstacle {
    let center = nalgebra::center(&b.top, &b.tip);
    let stem_top = b.calyx() - b.axis().into_inner() * CALYX_STEM_M;
    Obstacle {
        id: b.id.clone(),
        shape: ObstacleShape::Berry(BerryShape {
            center: arr(&center),
            radius: b.r_top,
            elongation: 0.5 * (b.tip - b.top).norm(),
            stem_top: arr(&stem_top),
            stem_radius: stem_radius.min(b.r_top),
        }),
    }
}

/// Radius of the stem reaching berry `i`'s calyx (`stem-<i>b`), or a tenth
/// of the berry radius when the plant has none.
fn calyx_stem_radius(plant: &Plant, i: usize, b: &Berry) -> f64 {
    let id = format!("stem-{i}b");
    plant
        .stems
        .iter()
        .find(|s| s.id == id)
        .map_or(0.1 * b.r_top, |s| s.radius)
}

/// A stem segment as a `capsule` obstacle.
pub fn stem_obstacle(s: &StemSegment) -> Obstacle {
    Obstacle {
        id: s.id.clone(),
        shape: ObstacleShape::Capsule(Capsule {
            a: arr(&s.a),
            b: arr(&s.b),
            radius: s.radius,
        }),
    }
}

/// A leaflet as a thin `convex` slab.
pub fn leaflet_obstacle(l: &Leaflet) -> Obstacle {
    Obstacle {
        id: l.id.clone(),
        shape: ObstacleShape::Convex {
            points: l.hull_points(LEAF_HULL_POINTS).iter().map(arr).collect(),
        },
    }
}

/// Every obstacle of the plant (berries first, in berry order).
pub fn plant_obstacles(plant: &Plant) -> Vec<Obstacle> {
    let berries = plant
        .berries
        .iter()
        .enumerate()
        .map(|(i, b)| berry_obstacle(b, calyx_stem_radius(plant, i, b)));
    let stems = plant.stems.iter().map(stem_obstacle);
    let leaves = plant.leaflets.iter().map(leaflet_obstacle);
    let tray = plant.tray.iter().map(|t| Obstacle {
        id: "tray".to_string(),
        shape: ObstacleShape::Box(OrientedBox {
            center: arr(&t.center),
            half_extents: [t.half_extents.x, t.half_extents.y, t.half_extents.z],
            rotation: crate::geometry::quaternion::IDENTITY_XYZW,
        }),
    });
    berries.chain(stems).chain(leaves).chain(tray).collect()
}

/// The plant as a scene file.
pub fn plant_scene_file(plant: &Plant) -> SceneFile {
    SceneFile {
        obstacles: plant_obstacles(plant),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use crate::synth::camera::Camera;
    use crate::synth::plant::{sample_plant, Placement};
    use crate::synth::settings::{CameraSettings, PlantSettings};
    use rand::SeedableRng;

    #[test]
    fn berries_are_berry_obstacles_that_contain_the_berry_surface() {
        let cam = Camera::reference_home(&CameraSettings::default().model).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let plant = sample_plant(
            &PlantSettings::default(),
            &cam,
            4.0,
            5,
            &Placement::at_points(),
            &mut rng,
        )
        .unwrap();
        let obstacles = plant_obstacles(&plant);
        Scene::new(obstacles.clone()).unwrap();
        for (b, o) in plant.berries.iter().zip(&obstacles) {
            let ObstacleShape::Berry(BerryShape {
                center,
                radius,
                elongation,
                ..
            }) = o.shape
            else {
                panic!("{} is not a berry obstacle", o.id);
            };
            // Every silhouette point of the round-cone berry lies within the body.
            let (c, axis) = (nalgebra::Point3::from(center), b.axis().into_inner());
            for p in b.silhouette_points() {
                let t = (p - c).dot(&axis).clamp(-elongation, elongation);
                assert!((p - (c + axis * t)).norm() <= radius + 1e-9, "{}", o.id);
            }
        }
        let kinds: Vec<&str> = obstacles
            .iter()
            .map(|o| match o.shape {
                ObstacleShape::Berry(_) => "berry",
                ObstacleShape::Capsule(_) => "capsule",
                ObstacleShape::Convex { .. } => "convex",
                ObstacleShape::Box(_) => "box",
                _ => "other",
            })
            .collect();
        assert_eq!(kinds.iter().filter(|k| **k == "berry").count(), 5);
        assert!(kinds.contains(&"capsule") && kinds.contains(&"convex"));
        assert_eq!(kinds.contains(&"box"), plant.tray.is_some());
    }
}
