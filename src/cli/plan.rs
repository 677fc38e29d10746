//! `dpmp plan`: an image (+ aligned depth) and a target box → the
//! network's prior → (pre-grasp goal) → the optimiser; prints the
//! `/v1/plan` response JSON. A shell over [`crate::plan`].

use crate::net::Model;
use crate::optim::Task;
use crate::perception::depth::{DepthImage, DEFAULT_DEPTH_SCALE_M};
use crate::plan::{predict_and_optimize, GoalApproach, PlanInput, TargetInput};
use crate::robot::Robot;
use crate::{Error, Result};
use clap::Args;
use std::path::PathBuf;
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
        conflicts_with_all = ["image", "target_box", "mask_applied", "depth", "target_position", "scene", "camera", "duration"]
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
    /// Metres per depth unit (0.001: millimetres).
    #[arg(long, default_value_t = DEFAULT_DEPTH_SCALE_M)]
    pub depth_scale: f64,
    /// The berry centre x,y,z (m, base frame) from your own perception,
    /// instead of --depth.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        conflicts_with = "depth"
    )]
    pub target_position: Option<Vec<f64>>,
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
    /// Scene file `{"obstacles": [...]}` (request schema).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Trained model folder (model.safetensors + config.json; also from
    /// DPMP_MODEL_DIR) [default: the shipped model, carried by the binary].
    #[arg(long, env = super::serve::MODEL_DIR_ENV)]
    pub model: Option<PathBuf>,
    /// The robot (must be the one the model was trained for).
    #[command(flatten)]
    pub robot: super::RobotArgs,
    /// Required clearance to every obstacle (m).
    #[arg(long, default_value_t = 0.02)]
    pub clearance: f64,
    /// Trajectory duration (s).
    #[arg(long, default_value_t = 4.0)]
    pub duration: f64,
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
    let (input, model, robot) = match &args.record {
        Some(record) => {
            let (model, robot) = load_model_and_robot(&args)?;
            (record_input(&args, record)?, model, robot)
        }
        None => {
            // The box, the image and the scene are checked before the model loads.
            let flags = read_flags(&args)?;
            let (model, robot) = load_model_and_robot(&args)?;
            (flag_input(&args, &model, flags)?, model, robot)
        }
    };
    let response = predict_and_optimize(&model, &robot, input, &Default::default())?;
    crate::cli::print_json(&response)?;
    crate::cli::require_optimal(args.require_optimal, response.result.status)
}

/// The model (`--model` or the shipped one) and the robot it was trained for.
fn load_model_and_robot(args: &PlanArgs) -> Result<(Arc<Model>, Arc<Robot>)> {
    if let Some(dir) = &args.model {
        if !dir.join("config.json").is_file() {
            return Err(Error::file(
                dir,
                "no trained model here (config.json missing): train one with `dpmp train` (see the README), or leave --model out for the shipped one",
            ));
        }
    }
    let model = Arc::new(Model::load_or_shipped(args.model.as_deref())?);
    let robot = Arc::new(args.robot.load()?);
    model.config().check_robot(&robot)?;
    Ok((model, robot))
}

/// `--record`: the dataset target's own inputs, with `--clearance`, the
/// goal flags and the approach.
fn record_input(args: &PlanArgs, record: &std::path::Path) -> Result<PlanInput> {
    let (dir, manifest, entry) = crate::train::plan_eval::find_record(record)?;
    let (mut input, _) = crate::train::plan_eval::record_plan_input(
        &dir,
        &entry,
        manifest.depth_scale_m(),
        manifest.camera_model(),
        args.clearance,
    )?;
    crate::plan::check_standoff(args.goal_standoff, &input.target, "--goal-standoff")?;
    input.goal_standoff_m = args.goal_standoff;
    input.approach = approach(args)?;
    Ok(input)
}

/// What the flags give before the model is loaded: the image, the box
/// (checked against it) and the request with the scene.
struct Flags {
    image: image::DynamicImage,
    target_box: [f64; 4],
    task: Task,
}

/// `--image`, `--box`, `--scene`, `--duration` and `--clearance`.
fn read_flags(args: &PlanArgs) -> Result<Flags> {
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
    crate::plan::check_target_box(&target_box, image.width(), image.height(), "--box")?;
    let obstacles = match &args.scene {
        Some(path) => crate::cli::read_json::<crate::scene::SceneFile>(path)?.obstacles,
        None => Vec::new(),
    };
    let task = Task {
        duration_s: args.duration,
        clearance_m: args.clearance,
        obstacles,
        ..Task::default()
    };
    Ok(Flags {
        image,
        target_box,
        task,
    })
}

/// The plan input of the flags (--image, --box, --depth, --camera, ...).
fn flag_input(args: &PlanArgs, model: &Model, flags: Flags) -> Result<PlanInput> {
    let Flags {
        image,
        target_box,
        task,
    } = flags;
    let camera = match &args.camera {
        Some(path) => {
            let camera: crate::perception::CameraModel = crate::fsio::read_json(path)?;
            camera
                .validate("camera")
                .map_err(|e| Error::file(path, e.to_string()))?;
            Some(camera)
        }
        None => None,
    };
    if args.depth.is_some() {
        let (w, h) = (image.width(), image.height());
        crate::plan::check_camera_size(model, camera.as_ref(), w, h, "--image")?;
    }
    let target = target_input(args, &image)?;
    crate::plan::check_standoff(args.goal_standoff, &target, "--goal-standoff")?;
    Ok(PlanInput {
        image,
        target_box,
        mask_applied: args.mask_applied,
        target,
        goal_standoff_m: args.goal_standoff,
        task,
        approach: approach(args)?,
        camera,
    })
}

/// `--approach-axis` and `--approach-tolerance`, if an axis is given.
fn approach(args: &PlanArgs) -> Result<Option<GoalApproach>> {
    let Some(axis) = &args.approach_axis else {
        return Ok(None);
    };
    let approach_axis: [f64; 3] = axis
        .clone()
        .try_into()
        .map_err(|_| Error::invalid("--approach-axis", "expected three numbers x,y,z"))?;
    Ok(Some(GoalApproach {
        approach_axis,
        approach_tolerance_rad: args.approach_tolerance,
    }))
}

/// The 3-D target of `--depth` or `--target-position`.
fn target_input(args: &PlanArgs, image: &image::DynamicImage) -> Result<TargetInput> {
    if let Some(p) = &args.target_position {
        let p: [f64; 3] = p
            .clone()
            .try_into()
            .map_err(|_| Error::invalid("--target-position", "expected three numbers x,y,z"))?;
        return Ok(TargetInput::Position(p));
    }
    let Some(path) = &args.depth else {
        return Ok(TargetInput::None);
    };
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
    let depth = DepthImage::decode_png(&bytes, args.depth_scale, "--depth")
        .map_err(|e| Error::file(path, e.to_string()))?;
    depth
        .check_aligned(image.width(), image.height(), "--depth")
        .map_err(|e| Error::file(path, e.to_string()))?;
    Ok(TargetInput::Depth(depth, "--depth".into()))
}
