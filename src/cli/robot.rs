//! `dpmp robot`: forward kinematics, clearance, inverse kinematics and
//! collision primitives of the robot model, printed as JSON.

use crate::geometry::quaternion::to_xyzw;
use crate::robot::{IkOptions, IkTarget, Robot};
use crate::scene::{Clearance, Scene};
use crate::{Error, Result};
use nalgebra::{Point3, Unit, Vector3};
use serde_json::{json, Map, Value};
use std::path::PathBuf;

/// `dpmp robot` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum RobotCommand {
    /// Pose of every link: `{"frames": {"<link>": {"position", "quaternion"}}}`,
    /// position in m (base frame), quaternion `[x, y, z, w]` (scalar last).
    Fk(FkArgs),
    /// Minimum signed clearance against a scene file (`{"obstacles": [...]}`).
    Clearance(ClearanceArgs),
    /// Inverse kinematics for a TCP position (and optional approach axis).
    Ik(IkArgs),
    /// The collision primitives of every link (link frames).
    Shapes(super::RobotArgs),
    /// Per mesh link: the exact containment check of the mesh in its hull
    /// and how much clearance the hull gives away (gap mean/median/max).
    Geometry(GeometryArgs),
}

/// Arguments of `dpmp robot geometry`.
#[derive(Debug, clap::Args)]
pub struct GeometryArgs {
    /// Spacing (m) of the points sampled on each hull's surface for the gap.
    #[arg(long, default_value_t = 0.002)]
    pub spacing: f64,
    /// The robot model.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Arguments of `dpmp robot fk`.
#[derive(Debug, clap::Args)]
pub struct FkArgs {
    /// Joint values, comma separated (rad), one per joint.
    #[arg(long, allow_hyphen_values = true)]
    pub q: String,
    /// The robot model.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Arguments of `dpmp robot clearance`.
#[derive(Debug, clap::Args)]
pub struct ClearanceArgs {
    /// Joint values, comma separated (rad), one per joint.
    #[arg(long, allow_hyphen_values = true)]
    pub q: String,
    /// Scene file: `{"obstacles": [...]}` in the request schema (e.g.
    /// examples/scene.json), or an optimise request file (its obstacles).
    #[arg(long)]
    pub scene: PathBuf,
    /// Also list every pair closer than this (m).
    #[arg(long)]
    pub activation: Option<f64>,
    /// The robot model.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Arguments of `dpmp robot ik`.
#[derive(Debug, clap::Args)]
pub struct IkArgs {
    /// Target TCP position `x,y,z` (m, base frame).
    #[arg(long, allow_hyphen_values = true)]
    pub position: String,
    /// Desired TCP z axis `x,y,z` (normalised; must not be zero).
    #[arg(long, allow_hyphen_values = true)]
    pub axis: Option<String>,
    /// Seed configuration (default: home).
    #[arg(long, allow_hyphen_values = true)]
    pub seed: Option<String>,
    /// Exit 3 (after printing the answer) when IK does not converge.
    #[arg(long)]
    pub require_converged: bool,
    /// The robot model.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Run a `dpmp robot` subcommand.
pub fn run(command: RobotCommand) -> Result<()> {
    let value = match command {
        RobotCommand::Fk(args) => fk_json(&args.robot.load()?, &args.q)?,
        RobotCommand::Clearance(args) => clearance_json(&args)?,
        RobotCommand::Ik(args) => ik_json(&args)?,
        RobotCommand::Shapes(robot_args) => {
            let robot = robot_args.load()?;
            json!({"link_names": robot.link_names(), "shapes": robot.collision_shapes()})
        }
        RobotCommand::Geometry(args) => {
            if !(args.spacing.is_finite() && (0.0005..=0.05).contains(&args.spacing)) {
                return Err(Error::invalid(
                    "--spacing",
                    format!("must be within [0.0005, 0.05] m, got {}", args.spacing),
                ));
            }
            let robot = args.robot.load()?;
            json!({
                "links": robot.hull_tightness(args.spacing, true),
                "warnings": robot.warnings(),
            })
        }
    };
    super::print_json(&value)
}

/// Parse `a,b,c` into numbers; errors name `flag[i]`.
pub fn parse_list(flag: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',')
        .enumerate()
        .map(|(i, part)| {
            part.trim().parse::<f64>().map_err(|_| {
                Error::invalid(
                    format!("{flag}[{i}]"),
                    format!("not a number: \"{}\"", part.trim()),
                )
            })
        })
        .collect::<Result<Vec<_>>>()
        .and_then(|v| crate::error::ensure_finite(flag, &v).map(|_| v))
}

fn parse_configuration(robot: &Robot, flag: &str, text: &str) -> Result<Vec<f64>> {
    let q = parse_list(flag, text)?;
    robot.validate_configuration(flag, &q)?;
    Ok(q)
}

fn parse_vector(flag: &str, text: &str) -> Result<Vector3<f64>> {
    let v = parse_list(flag, text)?;
    crate::error::ensure_len(flag, &v, 3)?;
    Ok(Vector3::new(v[0], v[1], v[2]))
}

/// `{"frames": {"<link>": {"position": [...], "quaternion": [x, y, z, w]}}}`.
pub fn fk_json(robot: &Robot, q_text: &str) -> Result<Value> {
    let q = parse_configuration(robot, "--q", q_text)?;
    let frames = robot.fk(&q);
    let mut out = Map::new();
    for (name, pose) in robot.link_names().iter().zip(&frames.poses) {
        out.insert(
            name.clone(),
            json!({"position": pose.translation.vector.as_slice(), "quaternion": to_xyzw(&pose.rotation)}),
        );
    }
    Ok(json!({"joint_names": robot.joint_names(), "q": q, "frames": out}))
}

/// The scene `--scene` names: a scene file (`{"obstacles": [...]}`), or an
/// optimise request file, whose obstacles it takes.
fn scene_of(path: &std::path::Path) -> Result<Scene> {
    use std::collections::BTreeMap;
    let keys: BTreeMap<String, serde::de::IgnoredAny> = crate::fsio::read_json(path)?;
    if !keys.contains_key("prior") {
        return Scene::from_file(path);
    }
    let request = super::optimize::read_request(path)?;
    Scene::new(request.task.obstacles)
}

fn clearance_json(args: &ClearanceArgs) -> Result<Value> {
    let robot = args.robot.load()?;
    let q = parse_configuration(&robot, "--q", &args.q)?;
    let scene = scene_of(&args.scene)?;
    let frames = robot.fk(&q);
    let mut out = match scene.min_clearance(&robot, &frames) {
        None => json!({"min_clearance_m": null, "link": null, "obstacle": null}),
        Some(c) => {
            let gradient = scene.clearance_gradient(&robot, &q, &frames, &c);
            json!({
                "min_clearance_m": c.distance,
                "link": c.link_name(&robot),
                "obstacle": c.obstacle_id(&scene),
                "shape": c.shape,
                "shape_name": robot.collision_shapes()[c.shape].describe(),
                "point_robot": c.point_robot,
                "point_obstacle": c.point_obstacle,
                "normal": c.normal,
                "gradient": gradient.as_slice(),
            })
        }
    };
    if let Some(activation) = args.activation {
        if !activation.is_finite() {
            return Err(Error::invalid("--activation", "must be a finite number"));
        }
        let within = scene.clearances_within(&robot, &frames, activation);
        out["within"] = within
            .iter()
            .map(|c| named_clearance(c, &robot, &scene))
            .collect();
    }
    Ok(out)
}

/// One pair of `robot clearance --activation` with the link and obstacle
/// names beside their indices.
fn named_clearance(c: &Clearance, robot: &Robot, scene: &Scene) -> Value {
    json!({
        "distance": c.distance,
        "shape": c.shape,
        "shape_name": robot.collision_shapes()[c.shape].describe(),
        "link": c.link,
        "link_name": c.link_name(robot),
        "obstacle": c.obstacle,
        "obstacle_id": c.obstacle_id(scene),
        "point_robot": c.point_robot,
        "point_obstacle": c.point_obstacle,
        "normal": c.normal,
    })
}

fn ik_json(args: &IkArgs) -> Result<Value> {
    let robot = args.robot.load()?;
    let position = parse_vector("--position", &args.position)?;
    let approach_axis = match &args.axis {
        None => None,
        Some(text) => Some(
            Unit::try_new(parse_vector("--axis", text)?, 1e-9)
                .ok_or_else(|| Error::invalid("--axis", "must not be zero"))?,
        ),
    };
    let seed = match &args.seed {
        None => robot.home(),
        Some(text) => parse_configuration(&robot, "--seed", text)?,
    };
    let target = IkTarget {
        position: Point3::from(position),
        approach_axis,
    };
    let solution = robot.ik(&target, &seed, &IkOptions::default())?;
    let converged = solution.converged;
    let value = serde_json::to_value(solution).map_err(|e| Error::Numerical(e.to_string()))?;
    if args.require_converged && !converged {
        super::print_json(&value)?;
        return Err(Error::Unsolved(
            "IK did not converge (--require-converged)".into(),
        ));
    }
    Ok(value)
}
