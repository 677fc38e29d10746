//! Side links: links fixed to a chain link off the base-to-tip chain (the
//! Panda's fingers), where each sits and which collision shapes it
//! carries, and moving one with its shapes (a gripper opened or closed).
//!
//! The loader ([`super::urdf`]) folds every side link's shapes into its
//! chain link's frame; a [`SideLink`] remembers which shapes those are and
//! where the side link's frame is, so [`Robot::with_side_link_moved`] can
//! move them rigidly. The moved robot is a new, equally immutable `Robot`
//! whose lever arms and link reaches are recomputed from the moved shapes,
//! so every bound built on them (the continuous certificate, the duration
//! bound) holds for it as it does for the loaded one.

use super::Robot;
use crate::{Error, Result};
use nalgebra::{Isometry3, Translation3, Vector3};

/// A link hanging off a chain link through fixed joints, and its shapes.
#[derive(Clone, Debug, PartialEq)]
pub struct SideLink {
    /// The link's URDF name (the first link off the chain).
    pub name: String,
    /// Index into `robot.link_names()` of the chain link it hangs from.
    pub chain_link: usize,
    /// Its frame in the chain link's frame.
    pub pose: Isometry3<f64>,
    /// Indices into `robot.collision_shapes()` of its shapes and those of
    /// the links fixed below it.
    pub shapes: Vec<usize>,
}

impl SideLink {
    /// How far the side link's frame sits along its own `axis` (a unit
    /// vector in its frame) from the chain link's origin: for a finger
    /// moving along its y axis, its opening.
    pub fn offset_along(&self, axis: &Vector3<f64>) -> f64 {
        self.pose
            .translation
            .vector
            .dot(&(self.pose.rotation * axis))
    }
}

impl Robot {
    /// The side links, in the order the loader met them.
    pub fn side_links(&self) -> &[SideLink] {
        &self.side_links
    }

    /// The side link named `name`, if the robot has one.
    pub fn side_link(&self, name: &str) -> Option<&SideLink> {
        self.side_links.iter().find(|s| s.name == name)
    }

    /// The robot with side link `name` (and everything fixed below it)
    /// moved by `translation` (m, in the side link's own frame); lever arms
    /// and link reaches are recomputed. Errors name the link when the robot
    /// has no such side link or the translation is not finite.
    pub fn with_side_link_moved(&self, name: &str, translation: &Vector3<f64>) -> Result<Robot> {
        let field = format!("link[{name}]");
        if !translation.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid(field, "the translation must be finite"));
        }
        let Some(index) = self.side_links.iter().position(|s| s.name == name) else {
            return Err(Error::invalid(
                field,
                "no such side link (a link fixed off the base-to-tip chain)",
            ));
        };
        let mut moved = self.clone();
        let side = &mut moved.side_links[index];
        let shifted = side.pose * Translation3::from(*translation);
        let motion: Isometry3<f64> = shifted * side.pose.inverse();
        side.pose = shifted;
        for &s in &side.shapes {
            let shape = &mut moved.shapes[s];
            shape.geometry = shape.geometry.transformed(&motion);
        }
        Ok(moved.with_lever_arms())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{urdf, MeshFiles, Robot, ShapeGeometry, PANDA_MESHES, PANDA_URDF};

    /// The Panda with both fixed finger joints written at `opening` (m)
    /// instead of the shipped 0.04: an independent robot to compare with.
    fn panda_written_open_at(opening: f64) -> Robot {
        let xml = PANDA_URDF
            .replace(
                r#"<origin xyz="0 0.04 0.0584" rpy="0 0 0"/>"#,
                &format!(r#"<origin xyz="0 {opening} 0.0584" rpy="0 0 0"/>"#),
            )
            .replace(
                r#"<origin xyz="0 -0.04 0.0584" rpy="0 0 3.141592653589793"/>"#,
                &format!(r#"<origin xyz="0 -{opening} 0.0584" rpy="0 0 3.141592653589793"/>"#),
            );
        let files = MeshFiles::Embedded(PANDA_MESHES);
        let robot = urdf::robot_from_str(&xml, "panda_link0", "panda_tcp", &files).unwrap();
        for side in robot.side_links() {
            let written = side.offset_along(&Vector3::y());
            assert!((written - opening).abs() < 1e-12, "rewritten: {written}");
        }
        robot
    }

    /// Signed distances from probe points around the hand (its frame).
    fn probe(g: &ShapeGeometry) -> Vec<f64> {
        let mut out = Vec::new();
        for i in 0..7 {
            for j in 0..9 {
                for k in 0..7 {
                    let p = [
                        -0.06 + 0.02 * i as f64,
                        -0.08 + 0.02 * j as f64,
                        0.025 * k as f64,
                    ];
                    out.push(g.signed_distance(&p));
                }
            }
        }
        out
    }

    #[test]
    fn moving_the_fingers_equals_loading_them_there() {
        let panda = Robot::panda().unwrap();
        let names: Vec<&str> = panda.side_links().iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["panda_leftfinger", "panda_rightfinger"]);
        for opening in [0.0, 0.013, 0.04] {
            let mut moved = panda.clone();
            for name in names.iter() {
                let side = moved.side_link(name).unwrap();
                let delta = opening - side.offset_along(&Vector3::y());
                moved = moved
                    .with_side_link_moved(name, &(delta * Vector3::y()))
                    .unwrap();
                assert!(
                    (moved.side_link(name).unwrap().offset_along(&Vector3::y()) - opening).abs()
                        < 1e-12
                );
            }
            let written = panda_written_open_at(opening);
            assert_eq!(
                moved.collision_shapes().len(),
                written.collision_shapes().len()
            );
            for (a, b) in moved
                .collision_shapes()
                .iter()
                .zip(written.collision_shapes())
            {
                assert_eq!(a.link, b.link);
                let (da, db) = (probe(&a.geometry), probe(&b.geometry));
                let worst = da
                    .iter()
                    .zip(&db)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f64::max);
                assert!(worst < 1e-9, "{} differs by {worst}", a.describe());
            }
            for (a, b) in moved.lever_arms().iter().zip(written.lever_arms()) {
                assert!((a - b).abs() < 1e-9, "lever arm {a} vs {b}");
            }
        }
    }

    #[test]
    fn an_unknown_side_link_or_a_bad_translation_is_named() {
        let panda = Robot::panda().unwrap();
        let e = panda
            .with_side_link_moved("panda_link3", &Vector3::x())
            .unwrap_err();
        assert!(e.to_string().contains("link[panda_link3]"), "{e}");
        let e = panda
            .with_side_link_moved("panda_leftfinger", &Vector3::new(f64::NAN, 0.0, 0.0))
            .unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
    }
}
