//! `dpmp plan`: an image (+ aligned depth) and a target box → the
//! network's prior → (pre-grasp goal) → the optimiser; prints the
//! `/v1/plan` response JSON. A shell over [`crate::plan`]: the flags (or a
//! dataset record) become the same [`PlanRequest`] the HTTP route builds,
//! and every field of `/v1/plan` has a flag or a place in `--task FILE`.

use crate::net::Model;
use crate::optim::task::DEFAULT_GOAL_TOLERANCE_M;
use crate::optim::{Goal, GoalApproach, Task};
use crate::perception::depth::{check_scale, DepthImage, DEFAULT_DEPTH_SCALE_M};
use crate::perception::CameraModel;
use crate::plan::{
    predict_and_optimize, PlanFields, PlanParts, PlanRequest, PlanResponse, WorldSource,
};
use crate::plot::{format_of, prior_and_answer, scene_picture, PriorBand, ScenePicture};
use crate::robot::Robot;
use crate::scene::SceneFile;
use crate::train::plan_eval::{find_record, record_fields, record_plan_input};
use crate::{Error, Result};
use clap::Args;
use nalgebra::DMatrix;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Arguments of `dpmp plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// A target record of a dataset (`DATA/targets/<id>.json`, from `dpmp
    /// data generate` or `data import`): plans it with its own image, box,
    /// depth (when the dataset has it), camera, start, duration and scene,
    /// instead of --image, --box and the rest.
    #[arg(
        long,
        conflicts_with_all = ["image", "target_box", "mask_applied", "depth", "depth_scale", "target_position", "scene", "camera", "duration", "task", "start", "goal"]
    )]
    pub record: Option<PathBuf>,
    /// Camera image (PNG or JPEG, any size).
    #[arg(long, required_unless_present = "record")]
    pub image: Option<PathBuf>,
    /// Target berry box in image pixels, `x1,y1,x2,y2` (top-left and
    /// bottom-right corners, x right and y down from the top-left pixel;
    /// at least 2 px each side, inside the image; not normalised).
    #[arg(
        long = "box",
        value_delimiter = ',',
        required_unless_present = "record",
        allow_negative_numbers = true
    )]
    pub target_box: Vec<f64>,
    /// The image already has the target painted as a white box.
    #[arg(long)]
    pub mask_applied: bool,
    /// Aligned z-depth image (16-bit PNG, same size as the image): the
    /// berry's 3-D position becomes the pre-grasp goal.
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Metres per depth unit of --depth [default: 0.001, millimetres].
    #[arg(long)]
    pub depth_scale: Option<f64>,
    /// The berry centre x,y,z (m, base frame) from your own perception,
    /// instead of --depth.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        conflicts_with = "depth"
    )]
    pub target_position: Option<Vec<f64>>,
    /// Where the world comes from besides the posted obstacles: `none`, or
    /// `depth` (the cloud --depth sees, the target kept out) [default: none].
    #[arg(long)]
    pub world: Option<String>,
    /// Standoff of the pre-grasp goal short of the berry (m); default 0.1.
    #[arg(long)]
    pub goal_standoff: Option<f64>,
    /// Unit vector x,y,z (base frame) the gripper's z axis must end within
    /// --approach-tolerance of (with --depth or --target-position).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub approach_axis: Option<Vec<f64>>,
    /// Allowed angle to --approach-axis (rad).
    #[arg(long, default_value_t = crate::optim::task::DEFAULT_APPROACH_TOLERANCE_RAD)]
    pub approach_tolerance: f64,
    /// The optimiser's fields of a `/v1/plan` request as a JSON file
    /// (`obstacles`, `clearance_m`, `duration_s`, `start`, `goal`,
    /// `options`, `trajectory_format`, ...: the `/v1/optimize` request
    /// without `prior`); the flags below override the fields they name.
    #[arg(long)]
    pub task: Option<PathBuf>,
    /// Scene file `{"obstacles": [...]}` (request schema).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Start configuration q1,...,q7 (rad) [default: free, the prior's].
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub start: Option<Vec<f64>>,
    /// A goal TCP position x,y,z (m, base frame), without a 3-D target.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub goal: Option<Vec<f64>>,
    /// Tolerance of --goal (m) [default: 0.01].
    #[arg(long)]
    pub goal_tolerance: Option<f64>,
    /// Restarts from prior draws when the run from the prior mean fails
    /// (0..=32) [default: 4].
    #[arg(long)]
    pub restarts: Option<usize>,
    /// How the answer writes the trajectory: `dpmp` or `ros2`
    /// (trajectory_msgs/JointTrajectory) [default: dpmp].
    #[arg(long)]
    pub trajectory_format: Option<String>,
    /// Draw the prior ±2σ band, its mean and the planned trajectory per
    /// joint into this `.png` or `.svg` file; with `--world depth` also the
    /// posted obstacles, the sensed cloud, the TCP path and the target, top
    /// and side view, into its sibling `<stem>.world.<ext>`.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Trained model folder (model.safetensors + config.json; also from
    /// DPMP_MODEL_DIR) [default: the shipped model, carried by the binary].
    #[arg(long, env = super::serve::MODEL_DIR_ENV)]
    pub model: Option<PathBuf>,
    /// The robot (must be the one the model was trained for).
    #[command(flatten)]
    pub robot: super::RobotArgs,
    /// Required clearance to every obstacle (m) [default: 0.02].
    #[arg(long)]
    pub clearance: Option<f64>,
    /// Trajectory duration (s) [default: 4].
    #[arg(long)]
    pub duration: Option<f64>,
    /// Exit 3 (after printing the answer) when its status is not `optimal`.
    #[arg(long)]
    pub require_optimal: bool,
    /// The camera that took the images, when not the model's: JSON
    /// `{"intrinsics": {"width", "height", "fx", "fy", "cx", "cy"},
    /// "mount_back_m", "mount_up_m"}` (the model config's `camera`).
    #[arg(long)]
    pub camera: Option<PathBuf>,
}

/// Run `dpmp plan`.
pub fn run(args: PlanArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        format_of(plot, "--plot")?;
    }
    // Every input is read and checked before the model loads.
    let request = match &args.record {
        Some(record) => record_request(&args, record)?,
        None => PlanRequest::new(flag_parts(&args)?, &flag_fields(&args))?,
    };
    let (model, robot) = load_model_and_robot(&args)?;
    // The plot needs the task's basis and duration after the request is spent.
    let plot = args
        .plot
        .as_ref()
        .map(|path| (path, request.task().clone()));
    let response = predict_and_optimize(&model, &robot, request, &Default::default())?;
    if let Some((path, task)) = &plot {
        plot_plan(path, task, &robot, &response)?;
        if response.world.is_some() {
            let world_path = world_plot_path(path);
            plot_world(&world_path, task, &robot, &response)?;
            eprintln!("wrote {}", world_path.display());
        }
    }
    crate::cli::print_json(&response)?;
    crate::cli::require_optimal(args.require_optimal, response.result.stop_reason)
}

/// The model (`--model` or the shipped one) and the robot it was trained for.
fn load_model_and_robot(args: &PlanArgs) -> Result<(Arc<Model>, Arc<Robot>)> {
    if let Some(dir) = &args.model {
        if !dir.join("config.json").is_file() {
            let here = std::env::current_dir()
                .map(|d| format!(" (relative paths start at {})", d.display()))
                .unwrap_or_default();
            return Err(Error::file(
                dir,
                format!("no trained model here (config.json missing){here}: give the model folder's path, train one with `dpmp train` (see the README), or leave --model out for the shipped model (it reads the berry's depth: give --depth or --target-position)"),
            ));
        }
    }
    let model = Arc::new(Model::load_or_shipped(args.model.as_deref())?);
    let robot = Arc::new(args.robot.load()?);
    model.config().check_robot(&robot)?;
    Ok((model, robot))
}

/// `--record`: the dataset target's own inputs, with the optimiser flags,
/// the goal standoff and the approach.
fn record_request(args: &PlanArgs, record: &Path) -> Result<PlanRequest> {
    let (dir, manifest, entry) = find_record(record)?;
    let clearance = args.clearance.unwrap_or(Task::default().clearance_m);
    let (mut parts, _) = record_plan_input(
        &dir,
        &entry,
        manifest.depth_scale_m(),
        manifest.camera_model(),
        clearance,
    )?;
    apply_task_flags(args, &mut parts.task)?;
    parts.goal_standoff_m = args.goal_standoff;
    parts.approach = approach(args)?;
    parts.world = world(args)?;
    PlanRequest::new(parts, &record_fields(&entry))
}

/// The inputs the flags give (--image, --box, --depth, --task, ...).
fn flag_parts(args: &PlanArgs) -> Result<PlanParts> {
    let image_path = args
        .image
        .as_ref()
        .ok_or_else(|| Error::invalid("--image", "required (or give --record)"))?;
    let target_box: [f64; 4] = args
        .target_box
        .clone()
        .try_into()
        .map_err(|_| Error::invalid("--box", "expected four numbers x1,y1,x2,y2"))?;
    let image = image::open(image_path)
        .map_err(|e| Error::file(image_path, format!("cannot read image: {e}")))?;
    let mut task = match &args.task {
        Some(path) => crate::fsio::read_json::<Task>(path)?,
        None => Task::default(),
    };
    apply_task_flags(args, &mut task)?;
    let camera = match &args.camera {
        Some(path) => Some(crate::fsio::read_json::<CameraModel>(path)?),
        None => None,
    };
    Ok(PlanParts {
        image,
        target_box,
        mask_applied: args.mask_applied,
        depth: read_depth(args)?,
        depth_scale_m: args.depth_scale,
        target_position: numbers::<3>(&args.target_position, "--target-position", "x,y,z")?,
        goal_standoff_m: args.goal_standoff,
        approach: approach(args)?,
        camera,
        camera_pose: None,
        world: world(args)?,
        task,
    })
}

/// `--world`, parsed.
fn world(args: &PlanArgs) -> Result<WorldSource> {
    args.world
        .as_deref()
        .map_or(Ok(WorldSource::None), |w| WorldSource::parse(w, "--world"))
}

/// The flags' names in errors, the images with their files.
fn flag_fields(args: &PlanArgs) -> PlanFields {
    let with_file = |flag: &str, path: &Option<PathBuf>| match path {
        Some(p) => format!("{flag} {}", p.display()),
        None => flag.to_string(),
    };
    PlanFields {
        image: with_file("--image", &args.image),
        depth: with_file("--depth", &args.depth),
        ..PlanFields::flags()
    }
}

/// The optimiser flags over `task`: each one given replaces its field.
fn apply_task_flags(args: &PlanArgs, task: &mut Task) -> Result<()> {
    if let Some(path) = &args.scene {
        task.obstacles = crate::cli::read_json::<SceneFile>(path)?.obstacles;
    }
    if let Some(clearance) = args.clearance {
        task.clearance_m = clearance;
    }
    if let Some(duration) = args.duration {
        task.duration_s = duration;
    }
    if let Some(start) = &args.start {
        task.start = Some(start.clone());
    }
    if let Some(restarts) = args.restarts {
        task.options.restarts = restarts;
    }
    if let Some(format) = &args.trajectory_format {
        task.trajectory_format =
            serde_json::from_value(serde_json::json!(format)).map_err(|_| {
                Error::invalid(
                    "--trajectory-format",
                    format!("expected dpmp or ros2, got {format:?}"),
                )
            })?;
    }
    if let Some(position) = numbers::<3>(&args.goal, "--goal", "x,y,z")? {
        let tolerance = args.goal_tolerance.unwrap_or(DEFAULT_GOAL_TOLERANCE_M);
        task.goal = Some(Goal::at(position, tolerance));
    } else if let Some(tolerance) = args.goal_tolerance {
        let goal = task.goal.as_mut().ok_or_else(|| {
            Error::invalid(
                "--goal-tolerance",
                "applies only with a goal (--goal or the --task file's)",
            )
        })?;
        goal.tolerance_m = tolerance;
    }
    Ok(())
}

/// `N` comma-separated numbers of flag `flag` (written `shape` in errors).
fn numbers<const N: usize>(
    values: &Option<Vec<f64>>,
    flag: &str,
    shape: &str,
) -> Result<Option<[f64; N]>> {
    values
        .as_ref()
        .map(|v| {
            v.clone()
                .try_into()
                .map_err(|_| Error::invalid(flag, format!("expected {N} numbers {shape}")))
        })
        .transpose()
}

/// `--approach-axis` and `--approach-tolerance`, if an axis is given.
fn approach(args: &PlanArgs) -> Result<Option<GoalApproach>> {
    Ok(
        numbers::<3>(&args.approach_axis, "--approach-axis", "x,y,z")?.map(|approach_axis| {
            GoalApproach {
                approach_axis,
                approach_tolerance_rad: args.approach_tolerance,
            }
        }),
    )
}

/// `--depth`, decoded with `--depth-scale` (errors name the file).
fn read_depth(args: &PlanArgs) -> Result<Option<DepthImage>> {
    let Some(path) = &args.depth else {
        return Ok(None);
    };
    let scale = args.depth_scale.unwrap_or(DEFAULT_DEPTH_SCALE_M);
    check_scale(scale, "--depth-scale")?;
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
    DepthImage::decode_png(&bytes, scale, "--depth")
        .map(Some)
        .map_err(|e| Error::file(path, e.to_string()))
}

/// `--plot`: the prior band the network predicted and the planned answer.
fn plot_plan(path: &Path, task: &Task, robot: &Robot, response: &PlanResponse) -> Result<()> {
    let rows = |r: &[Vec<f64>]| {
        let dof = r.first().map_or(0, Vec::len);
        DMatrix::from_fn(r.len(), dof, |t, j| r[t][j])
    };
    let band = PriorBand {
        mean: rows(&response.prior.mean),
        std: rows(&response.prior.std),
    };
    let title = format!(
        "dPMP plan ({}): Mahalanobis {:.3}, status {}",
        response.model,
        response.result.mahalanobis,
        response.result.status.as_str()
    );
    let basis = task.basis()?;
    prior_and_answer(
        path,
        &title,
        (&basis, task.duration_s),
        band,
        &response.result,
        robot,
    )
}

/// `--plot`'s sibling for the world picture: `traj.png` → `traj.world.png`.
fn world_plot_path(path: &Path) -> PathBuf {
    let mut name = path.file_stem().unwrap_or_default().to_os_string();
    name.push(".world.");
    name.push(path.extension().unwrap_or_default());
    path.with_file_name(name)
}

/// `--plot` with `world: depth`: the posted obstacles, the sensed cloud the
/// plan kept clear of, the planned TCP path (forward kinematics of the
/// answer's trajectory) and the target, in a top and a side view.
fn plot_world(path: &Path, task: &Task, robot: &Robot, response: &PlanResponse) -> Result<()> {
    let tcp_path: Vec<[f64; 3]> = response
        .result
        .trajectory
        .points
        .iter()
        .filter(|p| p.positions.len() == robot.dof())
        .map(|p| robot.tcp_pose(&p.positions).translation.vector.into())
        .collect();
    let cloud = response.sensed_cloud.as_deref().unwrap_or_default();
    let picture = ScenePicture {
        title: format!(
            "dPMP plan ({}): posted obstacles, sensed depth cloud and TCP path, status {}",
            response.model,
            response.result.status.as_str()
        ),
        scene_label: "posted obstacles".to_string(),
        obstacles: &task.obstacles,
        intruder: &[],
        cloud,
        tcp_path: Some(tcp_path.as_slice()),
        target: response.target.as_ref().map(|t| t.position),
    };
    scene_picture(path, &picture)
}
