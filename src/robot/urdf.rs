//! Loading a robot from URDF (urdf-rs): the chain from a base link to a tip
//! link, joint limits, and collision primitives, with validation.
//!
//! Rules (each broken rule is an error naming the element, field `urdf...`):
//! link and joint names are unique; every joint's parent and child exist;
//! every link has at most one parent joint and following parents from the
//! tip never loops; the tip lies below the base; joints on the chain are
//! revolute, prismatic or fixed with finite origins, a non-zero axis and
//! `lower < upper`, `velocity > 0`; side branches off the chain (such as
//! fingers) contain only fixed joints, and their collision shapes are moved
//! onto the chain link they hang from; anything else is a non-serial chain.

use super::chain::{isometry_from_xyz_rpy, ChainStep, Motion};
use super::collision::{geometry_from_urdf, LinkShape};
use super::mesh_files::MeshFiles;
use super::side_link::SideLink;
use super::{JointLimit, Robot};
use crate::{Error, Result};
use nalgebra::{Isometry3, Unit, Vector3};
use std::collections::HashMap;

/// Parse URDF text and build the chain from `base` to `tip`; mesh files
/// are read from `files`.
pub fn robot_from_str(xml: &str, base: &str, tip: &str, files: &MeshFiles) -> Result<Robot> {
    let model = urdf_rs::read_from_string(xml)
        .map_err(|e| Error::invalid("urdf", format!("malformed URDF: {e}")))?;
    let mut robot = build(&model, base, tip, files).map_err(|e| e.within("urdf"))?;
    robot.urdf_sha256 = urdf_sha256(xml);
    Ok(robot)
}

/// The link/joint tree of a URDF, indexed by name.
struct Tree<'a> {
    links: HashMap<&'a str, &'a urdf_rs::Link>,
    /// child link name -> index of its parent joint
    parent_joint: HashMap<&'a str, usize>,
    /// parent link name -> indices of its child joints
    child_joints: HashMap<&'a str, Vec<usize>>,
    joints: &'a [urdf_rs::Joint],
}

fn build(model: &urdf_rs::Robot, base: &str, tip: &str, files: &MeshFiles) -> Result<Robot> {
    let tree = Tree::new(model)?;
    for (field, name) in [("base", base), ("tip", tip)] {
        if !tree.links.contains_key(name) {
            return Err(Error::invalid(
                format!("link[{name}]"),
                format!("the {field} link \"{name}\" is not in the URDF"),
            ));
        }
    }
    let chain_joints = tree.path_from_base(base, tip)?;
    let mut steps = Vec::with_capacity(chain_joints.len());
    let mut joint_names = Vec::new();
    let mut limits = Vec::new();
    let mut dof_step = Vec::new();
    let mut link_names = vec![base.to_string()];
    for (k, &j) in chain_joints.iter().enumerate() {
        let joint = &model.joints[j];
        let motion = chain_motion(joint, joint_names.len())?;
        if !matches!(motion, Motion::Fixed) {
            joint_names.push(joint.name.clone());
            limits.push(joint_limit(joint)?);
            dof_step.push(k);
        }
        steps.push(ChainStep {
            joint: joint.name.clone(),
            origin: joint_origin(joint)?,
            motion,
        });
        link_names.push(joint.child.link.clone());
    }
    if joint_names.is_empty() {
        return Err(Error::invalid(
            format!("link[{tip}]"),
            format!("the chain from \"{base}\" to \"{tip}\" has no revolute or prismatic joint"),
        ));
    }
    let mut warnings = Vec::new();
    let (shapes, side_links) = collect_shapes(&tree, &link_names, files, &mut warnings)?;
    let home = limits.iter().map(JointLimit::mid).collect();
    Ok(Robot {
        name: model.name.clone(),
        urdf_sha256: String::new(),
        joint_names,
        limits,
        link_names,
        steps,
        dof_step,
        shapes,
        side_links,
        home,
        warnings,
        lever_arms: Vec::new(),
        link_reach: Vec::new(),
    }
    .with_lever_arms())
}

/// Hex SHA-256 of the URDF text (the robot's identity in model configs).
fn urdf_sha256(xml: &str) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(xml.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

impl<'a> Tree<'a> {
    fn new(model: &'a urdf_rs::Robot) -> Result<Tree<'a>> {
        let mut links = HashMap::new();
        for link in &model.links {
            if links.insert(link.name.as_str(), link).is_some() {
                return Err(Error::invalid(
                    format!("link[{}]", link.name),
                    "link defined twice",
                ));
            }
        }
        let mut parent_joint: HashMap<&str, usize> = HashMap::new();
        let mut child_joints: HashMap<&str, Vec<usize>> = HashMap::new();
        let mut joint_names = std::collections::HashSet::new();
        for (j, joint) in model.joints.iter().enumerate() {
            let field = format!("joint[{}]", joint.name);
            if !joint_names.insert(joint.name.as_str()) {
                return Err(Error::invalid(field, "joint defined twice"));
            }
            for (role, name) in [("parent", &joint.parent.link), ("child", &joint.child.link)] {
                if !links.contains_key(name.as_str()) {
                    return Err(Error::invalid(
                        format!("{field}.{role}"),
                        format!("link \"{name}\" does not exist"),
                    ));
                }
            }
            if let Some(previous) = parent_joint.insert(joint.child.link.as_str(), j) {
                return Err(Error::invalid(
                    format!("{field}.child"),
                    format!(
                        "link \"{}\" already has parent joint \"{}\": the URDF is not a tree (loop)",
                        joint.child.link, model.joints[previous].name
                    ),
                ));
            }
            child_joints
                .entry(joint.parent.link.as_str())
                .or_default()
                .push(j);
        }
        Ok(Tree {
            links,
            parent_joint,
            child_joints,
            joints: &model.joints,
        })
    }

    /// Joint indices from `base` down to `tip`.
    fn path_from_base(&self, base: &str, tip: &str) -> Result<Vec<usize>> {
        let mut path = Vec::new();
        let mut link = tip;
        while link != base {
            let Some(&j) = self.parent_joint.get(link) else {
                return Err(Error::invalid(
                    format!("link[{tip}]"),
                    format!("the tip link \"{tip}\" is not below the base link \"{base}\""),
                ));
            };
            if path.contains(&j) || path.len() > self.joints.len() {
                return Err(Error::invalid(
                    format!("joint[{}]", self.joints[j].name),
                    "the joints form a loop",
                ));
            }
            path.push(j);
            link = self.joints[j].parent.link.as_str();
        }
        path.reverse();
        Ok(path)
    }
}

fn chain_motion(joint: &urdf_rs::Joint, dof: usize) -> Result<Motion> {
    let field = format!("joint[{}]", joint.name);
    match joint.joint_type {
        urdf_rs::JointType::Fixed => Ok(Motion::Fixed),
        urdf_rs::JointType::Revolute => Ok(Motion::Revolute {
            axis: joint_axis(joint)?,
            dof,
        }),
        urdf_rs::JointType::Prismatic => Ok(Motion::Prismatic {
            axis: joint_axis(joint)?,
            dof,
        }),
        ref other => Err(Error::invalid(
            format!("{field}.type"),
            format!("joint type {other:?} is not supported (use revolute with limits, prismatic or fixed)"),
        )),
    }
}

fn joint_axis(joint: &urdf_rs::Joint) -> Result<Unit<Vector3<f64>>> {
    let field = format!("joint[{}].axis", joint.name);
    crate::error::ensure_finite(&field, &joint.axis.xyz.0)?;
    Unit::try_new(Vector3::from(joint.axis.xyz.0), 1e-9)
        .ok_or_else(|| Error::invalid(field, "the axis must not be zero"))
}

fn joint_origin(joint: &urdf_rs::Joint) -> Result<Isometry3<f64>> {
    let field = format!("joint[{}].origin", joint.name);
    crate::error::ensure_finite(&format!("{field}.xyz"), &joint.origin.xyz.0)?;
    crate::error::ensure_finite(&format!("{field}.rpy"), &joint.origin.rpy.0)?;
    Ok(isometry_from_xyz_rpy(
        joint.origin.xyz.0,
        joint.origin.rpy.0,
    ))
}

fn joint_limit(joint: &urdf_rs::Joint) -> Result<JointLimit> {
    let field = format!("joint[{}].limit", joint.name);
    let l = &joint.limit;
    crate::error::ensure_finite(&field, &[l.lower, l.upper, l.velocity])?;
    if l.lower >= l.upper {
        return Err(Error::invalid(
            field,
            format!("lower ({}) must be below upper ({})", l.lower, l.upper),
        ));
    }
    if l.velocity <= 0.0 {
        return Err(Error::invalid(
            format!("{field}.velocity"),
            format!("must be > 0, got {}", l.velocity),
        ));
    }
    Ok(JointLimit {
        lower: l.lower,
        upper: l.upper,
        velocity: l.velocity,
        acceleration: None,
        jerk: None,
    })
}

/// Collision shapes of every chain link, plus those of side links hanging
/// off it through fixed joints (moved into the chain link's frame), and
/// the side links themselves (which shapes each carries).
fn collect_shapes(
    tree: &Tree,
    link_names: &[String],
    files: &MeshFiles,
    warnings: &mut Vec<String>,
) -> Result<(Vec<LinkShape>, Vec<SideLink>)> {
    let mut shapes = Vec::new();
    let mut side_links: Vec<SideLink> = Vec::new();
    for (index, name) in link_names.iter().enumerate() {
        let next_on_chain = link_names.get(index + 1).map(String::as_str);
        // (link, its pose in the chain link's frame, the side link it is under)
        let mut stack: Vec<(&str, Isometry3<f64>, Option<usize>)> =
            vec![(name.as_str(), Isometry3::identity(), None)];
        while let Some((link, pose, side)) = stack.pop() {
            for (c, collision) in tree.links[link].collision.iter().enumerate() {
                let element = format!("link[{link}].collision[{c}]");
                if let Some(side) = side {
                    side_links[side].shapes.push(shapes.len());
                }
                shapes.push(LinkShape {
                    link: index,
                    link_name: name.clone(),
                    geometry: geometry_from_urdf(&element, collision, &pose, files, warnings)?,
                });
            }
            for &j in tree
                .child_joints
                .get(link)
                .map(Vec::as_slice)
                .unwrap_or(&[])
            {
                let joint = &tree.joints[j];
                let is_chain =
                    link == name.as_str() && Some(joint.child.link.as_str()) == next_on_chain;
                if is_chain {
                    continue;
                }
                if joint.joint_type != urdf_rs::JointType::Fixed {
                    return Err(Error::invalid(
                        format!("joint[{}]", joint.name),
                        format!(
                            "non-serial chain: this {:?} joint branches off \"{name}\" away from the \
                             base-to-tip chain (side branches must be fixed)",
                            joint.joint_type
                        ),
                    ));
                }
                let child_pose = pose * joint_origin(joint)?;
                let side = side.or_else(|| {
                    side_links.push(SideLink {
                        name: joint.child.link.clone(),
                        chain_link: index,
                        pose: child_pose,
                        shapes: Vec::new(),
                    });
                    Some(side_links.len() - 1)
                });
                stack.push((joint.child.link.as_str(), child_pose, side));
            }
        }
    }
    Ok((shapes, side_links))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{OrientedBox, Primitive};
    use crate::robot::ShapeGeometry;

    const TWO_LINK: &str = r#"<robot name="two">
      <link name="base"><collision><geometry><sphere radius="0.1"/></geometry></collision></link>
      <link name="a"><collision><origin xyz="0 0 0.25"/><geometry><cylinder radius="0.05" length="0.5"/></geometry></collision></link>
      <link name="b"/>
      <link name="side"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
      <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><origin xyz="0 0 0.1"/>
        <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="2" effort="1"/></joint>
      <joint name="j2" type="prismatic"><parent link="a"/><child link="b"/><origin xyz="0 0 0.5"/>
        <axis xyz="1 0 0"/><limit lower="0" upper="0.2" velocity="0.5" effort="1"/></joint>
      <joint name="js" type="fixed"><parent link="a"/><child link="side"/><origin xyz="0.3 0 0"/></joint>
    </robot>"#;

    #[test]
    fn generic_chain_loads_with_side_shapes_moved_onto_the_chain() {
        let robot = robot_from_str(TWO_LINK, "base", "b", &MeshFiles::None).unwrap();
        assert_eq!(robot.dof(), 2);
        assert_eq!(robot.joint_names(), ["j1", "j2"]);
        assert_eq!(robot.link_names(), ["base", "a", "b"]);
        assert_eq!(robot.home(), vec![0.0, 0.1]);
        let shapes = robot.collision_shapes();
        assert_eq!(shapes.len(), 3);
        let side = shapes
            .iter()
            .find(|s| matches!(s.geometry, ShapeGeometry::Primitive(Primitive::Box(_))))
            .unwrap();
        assert_eq!(side.link_name, "a");
        match &side.geometry {
            ShapeGeometry::Primitive(Primitive::Box(OrientedBox { center, .. })) => {
                assert!((center[0] - 0.3).abs() < 1e-12)
            }
            _ => unreachable!(),
        }
        let tcp = robot.tcp_pose(&[std::f64::consts::FRAC_PI_2, 0.2]);
        // j1 turns x onto y, so the prismatic x-translation of 0.2 lands on y.
        assert!((tcp.translation.vector - Vector3::new(0.0, 0.2, 0.6)).norm() < 1e-12);
    }

    fn field_of(xml: &str, base: &str, tip: &str) -> String {
        let e = robot_from_str(xml, base, tip, &MeshFiles::None).unwrap_err();
        format!("{} | {}", e.field().unwrap_or(""), e)
    }

    #[test]
    fn bad_urdfs_are_rejected_naming_the_element() {
        assert!(field_of("<robot name=", "base", "b").contains("malformed"));
        assert!(field_of(TWO_LINK, "base", "nope").contains("urdf.link[nope]"));
        assert!(field_of(TWO_LINK, "b", "base").contains("not below"));
        let loop_xml = TWO_LINK.replace(
            "</robot>",
            r#"<joint name="jl" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"#,
        );
        assert!(field_of(&loop_xml, "base", "b").contains("urdf.joint[jl].child"));
        let branch = TWO_LINK.replace(r#"name="js" type="fixed""#, r#"name="js" type="revolute""#);
        let msg = field_of(&branch, "base", "b");
        assert!(
            msg.contains("urdf.joint[js]") && msg.contains("non-serial"),
            "{msg}"
        );
        let bad_limit = TWO_LINK.replace(r#"lower="-1" upper="1""#, r#"lower="1" upper="-1""#);
        assert!(field_of(&bad_limit, "base", "b").contains("urdf.joint[j1].limit"));
        let zero_axis = TWO_LINK.replace(r#"<axis xyz="0 0 1"/>"#, r#"<axis xyz="0 0 0"/>"#);
        assert!(field_of(&zero_axis, "base", "b").contains("urdf.joint[j1].axis"));
        let missing = TWO_LINK.replace(r#"<child link="side"/>"#, r#"<child link="ghost"/>"#);
        assert!(field_of(&missing, "base", "b").contains("urdf.joint[js].child"));
        let negative = TWO_LINK.replace(r#"sphere radius="0.1""#, r#"sphere radius="-0.1""#);
        assert!(field_of(&negative, "base", "b")
            .contains("urdf.link[base].collision[0].geometry.radius"));
        let mesh = TWO_LINK.replace(r#"<sphere radius="0.1"/>"#, r#"<mesh filename="x.stl"/>"#);
        assert!(field_of(&mesh, "base", "b").contains("mesh"));
        let continuous = TWO_LINK.replace(
            r#"name="j1" type="revolute""#,
            r#"name="j1" type="continuous""#,
        );
        assert!(field_of(&continuous, "base", "b").contains("urdf.joint[j1].type"));
    }
}
