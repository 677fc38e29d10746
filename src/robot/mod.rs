//! The robot: a serial kinematic chain read from URDF, with forward
//! kinematics, point Jacobians, damped-least-squares inverse kinematics and
//! the convex collision primitives attached to every link.
//!
//! - [`urdf`]: loading with urdf-rs, choosing the base→tip chain, validation;
//! - [`chain`]: the compiled chain (fixed origins + joint motions);
//! - [`fk`]: forward kinematics of every link frame ([`Frames`]);
//! - [`jacobian`]: Jacobians of points attached to links and of the TCP;
//! - [`ik`]: inverse kinematics for a TCP position and approach axis;
//! - [`limits_file`]: acceleration and jerk limits from a MoveIt-style
//!   `joint_limits.yaml` beside the URDF;
//! - [`collision`]: the link collision geometry ([`LinkShape`]);
//! - [`side_link`]: links fixed off the chain (the fingers), moved with
//!   their shapes ([`Robot::with_side_link_moved`]);
//! - [`mesh`], [`mesh_files`] and [`hull`]: collision meshes (STL, OBJ),
//!   where their files are found, and the convex hull that contains each
//!   one (the conservative geometry every clearance is measured against);
//! - [`hull_query`] and [`hull_topology`]: the exact hull-versus-segment
//!   distance (a certified local walk over the hull's faces, the full scan
//!   as fallback and reference).
//!
//! The Franka Panda ([`Robot::panda`]) is the default; its collision
//! geometry is Franka's published collision meshes (embedded in the binary
//! from `models/panda/meshes/collision/`). Any URDF serial arm with
//! revolute, prismatic and fixed joints and mesh or primitive collision
//! geometry loads the same way.

pub mod chain;
pub mod collision;
pub mod fk;
pub mod hull;
pub mod hull_query;
pub mod hull_topology;
pub mod ik;
pub mod jacobian;
pub mod lever;
pub mod limits_file;
pub mod mesh;
pub mod mesh_files;
pub mod reach;
pub mod side_link;
pub mod urdf;

pub use collision::{LinkShape, ShapeGeometry};
pub use fk::Frames;
pub use ik::{IkOptions, IkSolution, IkTarget};
pub use mesh_files::MeshFiles;
pub use side_link::SideLink;

use crate::{Error, Result};
use chain::ChainStep;
use serde::Serialize;

/// The shipped Panda description (see the comment at its top).
pub const PANDA_URDF: &str = include_str!("../../models/panda/panda.urdf");

/// Franka's collision meshes (Apache-2.0, see `models/panda/NOTICE`), by the
/// names `models/panda/panda.urdf` gives them.
pub const PANDA_MESHES: &[(&str, &[u8])] = &[
    (
        "meshes/collision/link0.stl",
        include_bytes!("../../models/panda/meshes/collision/link0.stl"),
    ),
    (
        "meshes/collision/link1.stl",
        include_bytes!("../../models/panda/meshes/collision/link1.stl"),
    ),
    (
        "meshes/collision/link2.stl",
        include_bytes!("../../models/panda/meshes/collision/link2.stl"),
    ),
    (
        "meshes/collision/link3.stl",
        include_bytes!("../../models/panda/meshes/collision/link3.stl"),
    ),
    (
        "meshes/collision/link4.stl",
        include_bytes!("../../models/panda/meshes/collision/link4.stl"),
    ),
    (
        "meshes/collision/link5.stl",
        include_bytes!("../../models/panda/meshes/collision/link5.stl"),
    ),
    (
        "meshes/collision/link6.stl",
        include_bytes!("../../models/panda/meshes/collision/link6.stl"),
    ),
    (
        "meshes/collision/link7.stl",
        include_bytes!("../../models/panda/meshes/collision/link7.stl"),
    ),
    (
        "meshes/collision/hand.stl",
        include_bytes!("../../models/panda/meshes/collision/hand.stl"),
    ),
];

/// The paper's home configuration of the Panda (rad), shared by all 25
/// annotated demonstrations.
pub const PANDA_HOME: [f64; 7] = [0.0348, -1.0102, -0.1525, -2.5334, -0.1583, 2.8798, 0.0543];

/// Limits of one actuated joint (rad, rad/s, rad/s², rad/s³; metres for
/// prismatic joints). Positions and velocity come from the URDF,
/// acceleration and jerk from the [`limits_file`] (none without one).
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct JointLimit {
    /// Lowest position.
    pub lower: f64,
    /// Highest position.
    pub upper: f64,
    /// Largest speed (absolute).
    pub velocity: f64,
    /// Largest acceleration (absolute), if the limits file gives one.
    pub acceleration: Option<f64>,
    /// Largest jerk (absolute), if the limits file gives one.
    pub jerk: Option<f64>,
}

impl JointLimit {
    /// Whether `q` lies within `[lower, upper]`.
    pub fn contains(&self, q: f64) -> bool {
        q >= self.lower && q <= self.upper
    }

    /// Middle of the range.
    pub fn mid(&self) -> f64 {
        0.5 * (self.lower + self.upper)
    }
}

/// A serial-chain robot: links from the base to the tip, the actuated joints
/// between them, limits and collision primitives. Cheap to clone, `Send +
/// Sync`, immutable after loading.
#[derive(Clone, Debug)]
pub struct Robot {
    pub(crate) name: String,
    /// SHA-256 of the URDF text the robot was loaded from.
    pub(crate) urdf_sha256: String,
    pub(crate) joint_names: Vec<String>,
    pub(crate) limits: Vec<JointLimit>,
    pub(crate) link_names: Vec<String>,
    /// `steps[k]` moves from link `k` to link `k + 1`.
    pub(crate) steps: Vec<ChainStep>,
    /// The step of each actuated joint (its child link is `step + 1`).
    pub(crate) dof_step: Vec<usize>,
    pub(crate) shapes: Vec<LinkShape>,
    /// Links fixed off the chain (the fingers) and their shapes.
    pub(crate) side_links: Vec<SideLink>,
    pub(crate) home: Vec<f64>,
    /// Loading remarks that are not errors (open meshes).
    pub(crate) warnings: Vec<String>,
    /// Per actuated joint: an upper bound on how far any point of the
    /// collision geometry moves per unit of that joint (m/rad; 1 for a
    /// prismatic joint). See [`Robot::lever_arms`].
    pub(crate) lever_arms: Vec<f64>,
    /// Per link: how far its collision geometry reaches from the link's
    /// frame origin (m; 0 for a link without geometry).
    pub(crate) link_reach: Vec<f64>,
}

/// A robot model's identity: its name, chain and joints, and the SHA-256
/// of its URDF text. A trained model records the identity of the robot its
/// demonstrations were recorded on; planning with another robot is refused.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotIdentity {
    /// The URDF's robot name.
    pub name: String,
    /// Base link of the chain.
    pub base: String,
    /// Tip link of the chain.
    pub tip: String,
    /// Actuated joints, base to tip (the order of the weights).
    pub joint_names: Vec<String>,
    /// Hex SHA-256 of the URDF text.
    pub urdf_sha256: String,
}

impl RobotIdentity {
    /// `Ok` when `robot` is this robot; otherwise an error (field `robot`)
    /// saying what differs, for `what` (e.g. `model 'cvae-depth'`).
    pub fn check(&self, robot: &Robot, what: &str) -> Result<()> {
        let other = robot.identity();
        let differs = if self.joint_names != other.joint_names {
            format!("joints {:?}, not {:?}", self.joint_names, other.joint_names)
        } else if (&self.name, &self.base, &self.tip) != (&other.name, &other.base, &other.tip) {
            format!(
                "robot '{}' from {} to {}, not '{}' from {} to {}",
                self.name, self.base, self.tip, other.name, other.base, other.tip
            )
        } else if self.urdf_sha256 != other.urdf_sha256 {
            format!(
                "a URDF with SHA-256 {}, not {}",
                short(&self.urdf_sha256),
                short(&other.urdf_sha256)
            )
        } else {
            return Ok(());
        };
        Err(Error::invalid(
            "robot",
            format!("{what} is for another robot: {differs}; load that robot (--robot) or use one made for this robot"),
        ))
    }
}

fn short(hash: &str) -> &str {
    &hash[..hash.len().min(12)]
}

impl Robot {
    /// The shipped Franka Panda (`models/panda/panda.urdf`, embedded), from
    /// `panda_link0` to `panda_tcp`, with the paper's home configuration.
    /// The meshes are embedded; the robot is built once per process and
    /// cloned (the hulls are shared).
    pub fn panda() -> Result<Robot> {
        static PANDA: std::sync::OnceLock<std::result::Result<Robot, String>> =
            std::sync::OnceLock::new();
        PANDA
            .get_or_init(|| {
                urdf::robot_from_str(
                    PANDA_URDF,
                    "panda_link0",
                    "panda_tcp",
                    &MeshFiles::Embedded(PANDA_MESHES),
                )
                .and_then(|r| r.with_home(&PANDA_HOME))
                .and_then(|r| r.with_limits_yaml(limits_file::PANDA_JOINT_LIMITS))
                .map_err(|e| e.to_string())
            })
            .clone()
            .map_err(|m| Error::invalid("robot", m))
    }

    /// Load the chain from `base` to `tip` out of URDF text. The home
    /// configuration is the middle of every joint range. Mesh collision
    /// geometry needs a file to resolve against: use
    /// [`Robot::from_urdf_file`].
    pub fn from_urdf_str(xml: &str, base: &str, tip: &str) -> Result<Robot> {
        urdf::robot_from_str(xml, base, tip, &MeshFiles::None)
    }

    /// Load the chain from `base` to `tip` out of a URDF file; mesh names
    /// resolve against its folder ([`mesh_files`]), and the acceleration and
    /// jerk limits come from the [`limits_file`] there (without one the
    /// robot has none, and says so in [`Robot::warnings`]); errors name the
    /// file.
    pub fn from_urdf_file(path: &std::path::Path, base: &str, tip: &str) -> Result<Robot> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        let dir = path
            .parent()
            .map(std::path::Path::to_path_buf)
            .unwrap_or_default();
        let mut robot = urdf::robot_from_str(&text, base, tip, &MeshFiles::Folder(dir.clone()))
            .map_err(|e| Error::file(path, e.to_string()))?;
        let limits = dir.join(limits_file::LIMITS_FILE_NAME);
        if limits.is_file() {
            let text = std::fs::read_to_string(&limits)
                .map_err(|e| Error::file(&limits, e.to_string()))?;
            robot = robot
                .with_limits_yaml(&text)
                .map_err(|e| Error::file(&limits, e.to_string()))?;
        } else {
            robot.warnings.push(format!(
                "no {} beside the URDF: no acceleration or jerk limits unless a request gives them",
                limits_file::LIMITS_FILE_NAME
            ));
        }
        Ok(robot)
    }

    /// Remarks from loading that are not errors (e.g. a mesh that is not
    /// closed), one sentence each naming the URDF element.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// For every mesh shape: its link, the mesh's triangle count and open
    /// edges, the hull's vertex count, and [`hull::tightness`] at `spacing`;
    /// `progress` shows a bar over the meshes.
    pub fn hull_tightness(&self, spacing: f64, progress: bool) -> Vec<serde_json::Value> {
        let meshes = self
            .shapes
            .iter()
            .filter(|s| matches!(&s.geometry, ShapeGeometry::Convex(h) if h.source().is_some()))
            .count();
        let bar = crate::progress::bar(progress, meshes as u64, "link meshes checked");
        let links = self
            .shapes
            .iter()
            .filter_map(|s| match &s.geometry {
                ShapeGeometry::Convex(h) => h.source().map(|mesh| {
                    let tightness = hull::tightness(h, mesh, spacing);
                    bar.inc(1);
                    serde_json::json!({
                        "link": s.link_name,
                        "triangles": mesh.triangles.len(),
                        "open_edges": mesh.open_edges(),
                        "hull_vertices": h.vertices().len(),
                        "allowance_m": h.allowance(),
                        "tightness": tightness,
                    })
                }),
                _ => None,
            })
            .collect();
        bar.finish_and_clear();
        links
    }

    /// Replace the home configuration (validated: length, finite, within
    /// limits).
    pub fn with_home(mut self, home: &[f64]) -> Result<Robot> {
        self.validate_configuration("home", home)?;
        self.validate_within_limits("home", home)?;
        self.home = home.to_vec();
        Ok(self)
    }

    /// The robot's name from the URDF.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// What identifies this robot in a trained model's config.
    pub fn identity(&self) -> RobotIdentity {
        RobotIdentity {
            name: self.name.clone(),
            base: self.link_names[0].clone(),
            tip: self.link_names[self.tcp_link()].clone(),
            joint_names: self.joint_names.clone(),
            urdf_sha256: self.urdf_sha256.clone(),
        }
    }

    /// Number of actuated joints (7 for the Panda).
    pub fn dof(&self) -> usize {
        self.joint_names.len()
    }

    /// Names of the actuated joints, base to tip.
    pub fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    /// Limits of the actuated joints, base to tip.
    pub fn limits(&self) -> &[JointLimit] {
        &self.limits
    }

    /// The home configuration (Panda: the paper's; otherwise mid-range).
    pub fn home(&self) -> Vec<f64> {
        self.home.clone()
    }

    /// Every link along the chain, base first, fixed ones included.
    pub fn link_names(&self) -> &[String] {
        &self.link_names
    }

    /// Index of the link called `name` in [`Robot::link_names`].
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.link_names.iter().position(|n| n == name)
    }

    /// Index of the tip link (the TCP for the Panda).
    pub fn tcp_link(&self) -> usize {
        self.link_names.len() - 1
    }

    /// Every collision primitive, attached to a link of [`Robot::link_names`]
    /// (shapes of fixed side links such as the fingers are moved onto the
    /// chain link they hang from).
    pub fn collision_shapes(&self) -> &[LinkShape] {
        &self.shapes
    }

    /// Check that `q` has one finite number per joint (not the limits);
    /// errors name `field[i]`.
    pub fn validate_configuration(&self, field: &str, q: &[f64]) -> Result<()> {
        crate::error::ensure_len(field, q, self.dof())?;
        crate::error::ensure_finite(field, q)
    }

    /// Check that every entry of `q` lies within its joint's limits; errors
    /// name `field[i]` and the joint.
    pub fn validate_within_limits(&self, field: &str, q: &[f64]) -> Result<()> {
        for (i, (value, limit)) in q.iter().zip(&self.limits).enumerate() {
            if !limit.contains(*value) {
                return Err(Error::invalid(
                    format!("{field}[{i}]"),
                    format!(
                        "{} = {value} is outside its limits [{}, {}]",
                        self.joint_names[i], limit.lower, limit.upper
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Largest distance a chain step can move its child frame's origin from its
/// parent's (fixed offset plus prismatic travel).
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_for_another_robot_is_told_what_differs() {
        let load = |xml: &str, tip: &str| {
            urdf::robot_from_str(xml, "panda_link0", tip, &MeshFiles::Embedded(PANDA_MESHES))
                .unwrap()
        };
        let panda = Robot::panda().unwrap();
        let identity = panda.identity();
        assert_eq!(identity.urdf_sha256.len(), 64);
        assert!(identity.check(&panda, "model 'm'").is_ok());
        // The same URDF text loaded again: the same robot.
        let again = load(PANDA_URDF, "panda_tcp");
        assert!(identity.check(&again, "model 'm'").is_ok());
        // Other joints.
        let renamed = PANDA_URDF.replace("\"panda_joint7\"", "\"wrist\"");
        let short = load(&renamed, "panda_tcp");
        let e = identity.check(&short, "model 'm'").unwrap_err();
        assert_eq!(e.field(), Some("robot"));
        assert!(e.to_string().contains("joints"), "{e}");
        // Same chain, another tip: told the tip.
        let hand = load(PANDA_URDF, "panda_hand");
        let e = identity.check(&hand, "model 'm'").unwrap_err().to_string();
        assert!(e.contains("panda_hand") && e.contains("model 'm'"), "{e}");
        // An edited URDF (another link length): told the hash.
        let edited = PANDA_URDF.replacen("0.333", "0.343", 1);
        assert_ne!(edited, PANDA_URDF);
        let longer = load(&edited, "panda_tcp");
        let e = identity
            .check(&longer, "model 'm'")
            .unwrap_err()
            .to_string();
        assert!(e.contains("SHA-256"), "{e}");
    }

    #[test]
    fn panda_has_seven_joints_and_the_named_links() {
        let robot = Robot::panda().unwrap();
        assert_eq!(robot.dof(), 7);
        let names: Vec<&str> = robot.link_names().iter().map(|s| s.as_str()).collect();
        assert_eq!(
            names,
            [
                "panda_link0",
                "panda_link1",
                "panda_link2",
                "panda_link3",
                "panda_link4",
                "panda_link5",
                "panda_link6",
                "panda_link7",
                "panda_link8",
                "panda_hand",
                "panda_tcp"
            ]
        );
        assert_eq!(robot.tcp_link(), 10);
        assert_eq!(robot.link_index("panda_hand"), Some(9));
        assert_eq!(robot.home(), PANDA_HOME.to_vec());
        assert_eq!(robot.limits()[3].upper, -0.0698);
        assert_eq!(robot.limits()[5].velocity, 2.61);
    }

    #[test]
    fn configuration_validation_names_the_index() {
        let robot = Robot::panda().unwrap();
        let e = robot
            .validate_configuration("start", &[0.0; 6])
            .unwrap_err();
        assert_eq!(e.field(), Some("start"));
        let mut q = PANDA_HOME;
        q[4] = f64::INFINITY;
        let e = robot.validate_configuration("start", &q).unwrap_err();
        assert_eq!(e.field(), Some("start[4]"));
        let mut q = PANDA_HOME;
        q[3] = 0.1;
        let e = robot.validate_within_limits("goal", &q).unwrap_err();
        assert_eq!(e.field(), Some("goal[3]"));
        assert!(e.to_string().contains("panda_joint4"));
    }
}
