//! The dataset on disk, generated (`dpmp-dataset/4`; version 1, without
//! depth, and version 2, without task-space weights, still load) or imported from a lab's recordings
//! (`dpmp-dataset/5`; version 3, without task-space weights, still loads:
//! no generator settings, targets grouped by plant,
//! ids chosen by the lab; see [`crate::demos::import`]):
//!
//! ```text
//! DIR/manifest.json                written last (temp file + rename)
//! DIR/images/<target_id>.png       640x480 RGB, target berry boxed in white
//! DIR/depth/<target_id>.png        640x480 16-bit z-depth (mm, 0 = no return), format 2
//! DIR/targets/<target_id>.json     one TargetRecord per target
//! ```
//!
//! A generated `target_id` is `c{config:04}_b{berry:02}`. The types here are the
//! contract with the network, training, evaluation and benchmark code;
//! loaders validate shapes and finiteness and name the file and field.

use crate::error::{ensure_finite, ensure_len};
use crate::fsio::read_json;
use crate::promp::annotation::JointAnnotation;
use crate::promp::PrompConfig;
use crate::scene::{Obstacle, SceneFile};
use crate::synth::camera::Intrinsics;
use crate::synth::settings::SynthSettings;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The format tag of the manifests this version generates: version 2 added
/// aligned depth images (`depth/<id>.png`) and each target's measured depth;
/// version 4 adds the task-space weights of every demonstration and their
/// distribution ([`TargetRecord::task_distribution`]).
pub const FORMAT: &str = "dpmp-dataset/4";

/// The format tag of imported datasets: generator fields are absent,
/// targets carry a `group` and whether their image is already masked
/// (`dpmp-dataset/3`); version 5 adds the task-space fields as format 4.
pub const IMPORT_FORMAT: &str = "dpmp-dataset/5";

/// Format tags this version reads (version 1: colour only; versions 1-3
/// have no task-space fields, derived at load from the joint-space
/// demonstrations by [`TargetRecord::task_space_distribution`]).
pub const READABLE_FORMATS: [&str; 5] = [
    "dpmp-dataset/1",
    "dpmp-dataset/2",
    "dpmp-dataset/3",
    FORMAT,
    IMPORT_FORMAT,
];

/// Depth scale (m per unit) of imported depth images without one.
pub const DEFAULT_DEPTH_SCALE_M: f64 = 0.001;

/// `c{config:04}_b{berry:02}`.
pub fn target_id(config: usize, berry: usize) -> String {
    format!("c{config:04}_b{berry:02}")
}

/// Train / validation / test target ids (split by configuration).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Splits {
    /// Training targets.
    pub train: Vec<String>,
    /// Validation targets.
    pub val: Vec<String>,
    /// Test targets.
    pub test: Vec<String>,
}

/// One manifest entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetEntry {
    /// Target id.
    pub id: String,
    /// Configuration index.
    pub config: usize,
    /// Berry index within the configuration.
    pub berry: usize,
    /// Image path relative to the dataset directory.
    pub image: String,
    /// Record path relative to the dataset directory.
    pub record: String,
    /// Aligned depth image (16-bit PNG) relative to the dataset directory,
    /// when the dataset has depth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<String>,
    /// The plant (or other unit) the target belongs to; the splits keep a
    /// group together. Imported datasets only (generated ones group by
    /// `config`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// Whether the image already shows the box painted white (generated
    /// images do); `false` for imported images, painted at load time.
    #[serde(default = "yes", skip_serializing_if = "is_yes")]
    pub mask_applied: bool,
}

fn yes() -> bool {
    true
}

fn is_yes(v: &bool) -> bool {
    *v
}

impl TargetEntry {
    /// The entry of target (`config`, `berry`) with the standard paths.
    pub fn new(config: usize, berry: usize) -> TargetEntry {
        let id = target_id(config, berry);
        TargetEntry {
            image: format!("images/{id}.png"),
            record: format!("targets/{id}.json"),
            depth: None,
            group: None,
            mask_applied: true,
            id,
            config,
            berry,
        }
    }
}

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// One of [`READABLE_FORMATS`].
    pub format: String,
    /// Crate version that generated (or imported) the data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator_version: Option<String>,
    /// Generator (or split) seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Every generator setting (generated datasets only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<SynthSettings>,
    /// ProMP basis of every record.
    pub promp: PrompConfig,
    /// Camera intrinsics of every image.
    pub camera: Intrinsics,
    /// The camera with its gripper mount (imported datasets; generated
    /// ones have it in `settings`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_model: Option<crate::perception::CameraModel>,
    /// Depth scale of the depth images (imported datasets; generated ones
    /// have it in `settings`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale_m: Option<f64>,
    /// The robot of the demonstrations (imported datasets; generated ones
    /// are the shipped Panda's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<crate::robot::RobotIdentity>,
    /// Split by configuration.
    pub splits: Splits,
    /// Every target, in (config, berry) order.
    pub targets: Vec<TargetEntry>,
}

impl Manifest {
    /// The camera (intrinsics and gripper mount) that took the images.
    pub fn camera_model(&self) -> crate::perception::CameraModel {
        match (&self.camera_model, &self.settings) {
            (Some(model), _) => *model,
            (None, Some(settings)) => settings.camera.model,
            (None, None) => SynthSettings::default().camera.model,
        }
    }

    /// Metres per unit of the depth images.
    pub fn depth_scale_m(&self) -> f64 {
        match (self.depth_scale_m, &self.settings) {
            (Some(scale), _) => scale,
            (None, Some(settings)) => settings.depth.scale_m,
            (None, None) => DEFAULT_DEPTH_SCALE_M,
        }
    }

    /// Entries of one split: `"train" | "val" | "test" | "all"`.
    pub fn split(&self, name: &str) -> Result<Vec<&TargetEntry>> {
        let ids = match name {
            "all" => return Ok(self.targets.iter().collect()),
            "train" => &self.splits.train,
            "val" => &self.splits.val,
            "test" => &self.splits.test,
            other => {
                return Err(Error::invalid(
                    "split",
                    format!("expected train, val, test or all, got {other:?}"),
                ))
            }
        };
        ids.iter()
            .map(|id| {
                self.targets.iter().find(|t| &t.id == id).ok_or_else(|| {
                    Error::invalid(
                        format!("splits.{name}"),
                        format!("lists {id:?}, which is not among the targets"),
                    )
                })
            })
            .collect()
    }

    fn validate(&self) -> Result<()> {
        if !READABLE_FORMATS.contains(&self.format.as_str()) {
            return Err(Error::invalid(
                "format",
                format!(
                    "expected one of {READABLE_FORMATS:?}, got {:?}",
                    self.format
                ),
            ));
        }
        let mut ids = std::collections::HashSet::new();
        for (i, t) in self.targets.iter().enumerate() {
            if self.settings.is_some() && t.id != target_id(t.config, t.berry) {
                return Err(Error::invalid(
                    format!("targets[{i}].id"),
                    format!("{:?} does not match config/berry", t.id),
                ));
            }
            check_target_id(&t.id).map_err(|e| e.within(&format!("targets[{i}]")))?;
            if !ids.insert(t.id.as_str()) {
                return Err(Error::invalid(
                    format!("targets[{i}].id"),
                    format!("{:?} appears twice", t.id),
                ));
            }
            for (name, p) in [("image", &t.image), ("record", &t.record)] {
                relative_path(p).map_err(|e| e.within(&format!("targets[{i}].{name}")))?;
            }
        }
        for name in ["train", "val", "test"] {
            self.split(name)?;
        }
        Ok(())
    }
}

/// A pose: position and unit quaternion `[x, y, z, w]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position (m, base frame).
    pub position: [f64; 3],
    /// Orientation `[x, y, z, w]`.
    pub quaternion: [f64; 4],
}

/// One demonstration, reduced to what training needs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Demo {
    /// Joint-major ProMP weights (n_joints * n_basis).
    pub weights: Vec<f64>,
    /// Final configuration (rad).
    pub final_q: Vec<f64>,
    /// Dimension-major task-space weights (`7 * n_basis`: x, y, z, qx, qy,
    /// qz, qw; see [`crate::task_space`]); absent before format 4.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_weights: Option<Vec<f64>>,
}

pub use crate::promp::distribution::DistributionJson;

/// `targets/<id>.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetRecord {
    /// Target id.
    pub id: String,
    /// Configuration index.
    pub config: usize,
    /// Berry index.
    pub berry: usize,
    /// Image path relative to the dataset directory.
    pub image: String,
    /// Aligned depth image path relative to the dataset directory (format 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<String>,
    /// The target's depth measured in that image: the camera-frame z of
    /// the berry centre by [`crate::perception::locate_target`] (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_depth_m: Option<f64>,
    /// Target box `[x1, y1, x2, y2]` (px).
    #[serde(rename = "box")]
    pub bbox: [f64; 4],
    /// Box centre `[cx, cy]` (px).
    pub center: [f64; 2],
    /// The whole configuration as obstacles (request schema), with the
    /// intruders placed after the demonstrations marked.
    #[serde(default)]
    pub scene: RecordScene,
    /// Id of the target berry among the obstacles (generated data).
    #[serde(default)]
    pub target_obstacle_id: String,
    /// Target berry centre (m): the truth in generated data; imported
    /// data has none (its depth is a measurement).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_position: Option<[f64; 3]>,
    /// Mean demonstration start (rad).
    pub start: Vec<f64>,
    /// Mean final TCP pose.
    pub final_tcp: Pose,
    /// Demonstration duration (s).
    pub duration_s: f64,
    /// ProMP basis.
    pub promp: PrompConfig,
    /// The demonstrations.
    pub demos: Vec<Demo>,
    /// Full (joint-coupled) weight distribution.
    pub distribution: DistributionJson,
    /// The demonstrations' task-space weight distribution (format 4; older
    /// records derive it, see [`TargetRecord::task_space_distribution`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_distribution: Option<DistributionJson>,
    /// The paper's per-joint annotation (Raw diagonal).
    pub annotation: Vec<JointAnnotation>,
}

impl TargetRecord {
    /// Shape and finiteness checks (errors name the field).
    pub fn validate(&self) -> Result<()> {
        let n_joints = self.start.len();
        if n_joints == 0 {
            return Err(Error::invalid("start", "must not be empty"));
        }
        self.promp.validate().map_err(|e| e.within("promp"))?;
        let n_w = n_joints * self.promp.n_basis;
        let n_task = crate::task_space::TASK_DIMS * self.promp.n_basis;
        ensure_finite("box", &self.bbox)?;
        if self.bbox[0] > self.bbox[2] || self.bbox[1] > self.bbox[3] {
            return Err(Error::invalid(
                "box",
                "must be [x1, y1, x2, y2] with x1 <= x2 and y1 <= y2",
            ));
        }
        ensure_finite("center", &self.center)?;
        if let Some(p) = &self.target_position {
            ensure_finite("target_position", p)?;
        }
        if let Some(d) = self.target_depth_m {
            if !(d.is_finite() && d > 0.0) {
                return Err(Error::invalid(
                    "target_depth_m",
                    format!("must be a finite depth > 0, got {d}"),
                ));
            }
        }
        ensure_finite("start", &self.start)?;
        ensure_finite("final_tcp.position", &self.final_tcp.position)?;
        ensure_finite("final_tcp.quaternion", &self.final_tcp.quaternion)?;
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(Error::invalid("duration_s", "must be a finite number > 0"));
        }
        for (i, d) in self.demos.iter().enumerate() {
            ensure_len(&format!("demos[{i}].weights"), &d.weights, n_w)?;
            ensure_finite(&format!("demos[{i}].weights"), &d.weights)?;
            ensure_len(&format!("demos[{i}].final_q"), &d.final_q, n_joints)?;
            ensure_finite(&format!("demos[{i}].final_q"), &d.final_q)?;
            if let Some(t) = &d.task_weights {
                let field = format!("demos[{i}].task_weights");
                ensure_len(&field, t, n_task)?;
                ensure_finite(&field, t)?;
            }
        }
        check_distribution("distribution", &self.distribution, n_w)?;
        if let Some(task) = &self.task_distribution {
            check_distribution("task_distribution", task, n_task)?;
        }
        if self.annotation.len() != n_joints {
            return Err(Error::invalid(
                "annotation",
                format!("expected {n_joints} joints, got {}", self.annotation.len()),
            ));
        }
        let n_l = self.promp.n_basis * (self.promp.n_basis + 1) / 2;
        for (j, a) in self.annotation.iter().enumerate() {
            ensure_len(
                &format!("annotation[{j}].mean_weights"),
                &a.mean_weights,
                self.promp.n_basis,
            )?;
            ensure_finite(&format!("annotation[{j}].mean_weights"), &a.mean_weights)?;
            ensure_len(&format!("annotation[{j}].L"), &a.l, n_l)?;
            ensure_finite(&format!("annotation[{j}].L"), &a.l)?;
        }
        Ok(())
    }

    /// The weight distribution as a [`crate::promp::WeightDistribution`].
    pub fn weight_distribution(&self) -> Result<crate::promp::WeightDistribution> {
        to_distribution(&self.distribution, self.start.len(), self.promp.n_basis)
    }

    /// The task-space weight distribution: the record's (format 4), or
    /// derived from the joint-space demonstrations through `robot`'s
    /// forward kinematics (older formats; the same computation the
    /// generator records).
    pub fn task_space_distribution(
        &self,
        robot: &crate::robot::Robot,
    ) -> Result<crate::promp::WeightDistribution> {
        let dims = crate::task_space::TASK_DIMS;
        match &self.task_distribution {
            Some(task) => to_distribution(task, dims, self.promp.n_basis),
            None => Ok(self.derive_task_space(robot)?.0),
        }
    }

    /// Record the task-space weights of every demonstration and their
    /// distribution (what format 4 stores).
    pub fn fill_task_space(&mut self, robot: &crate::robot::Robot) -> Result<()> {
        let (distribution, weights) = self.derive_task_space(robot)?;
        for (demo, w) in self.demos.iter_mut().zip(weights) {
            demo.task_weights = Some(w);
        }
        self.task_distribution = Some(DistributionJson::from(&distribution));
        Ok(())
    }

    /// The task-space distribution of the demonstrations and each one's
    /// task-space weights; a record with fewer than two demonstrations (an
    /// imported annotation) uses 64 seeded draws of its joint-space
    /// distribution instead, and returns no per-demonstration weights.
    fn derive_task_space(
        &self,
        robot: &crate::robot::Robot,
    ) -> Result<(crate::promp::WeightDistribution, Vec<Vec<f64>>)> {
        use rand::SeedableRng;
        robot.validate_configuration("start", &self.start)?;
        let basis = crate::promp::Basis::new(&self.promp)?;
        let reference = self.task_reference(robot);
        let draws: Vec<Vec<f64>> = if self.demos.len() >= 2 {
            self.demos.iter().map(|d| d.weights.clone()).collect()
        } else {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
            let joint = self.weight_distribution()?;
            joint
                .sample(&mut rng, 64)
                .iter()
                .map(|w| w.as_slice().to_vec())
                .collect()
        };
        let refs: Vec<&[f64]> = draws.iter().map(Vec::as_slice).collect();
        let weights = crate::task_space::task_weight_set(&basis, robot, &refs, &reference)?;
        let distribution = crate::promp::WeightDistribution::from_demonstrations(
            &weights,
            crate::task_space::TASK_DIMS,
            basis.n_basis(),
        )?;
        let per_demo = if self.demos.len() >= 2 {
            weights.iter().map(|w| w.as_slice().to_vec()).collect()
        } else {
            Vec::new()
        };
        Ok((distribution, per_demo))
    }

    /// The orientation the task-space quaternions' signs start from: the
    /// TCP's at the mean start.
    pub fn task_reference(&self, robot: &crate::robot::Robot) -> nalgebra::UnitQuaternion<f64> {
        robot.tcp_pose(&self.start).rotation
    }
}

/// A stored distribution as a [`crate::promp::WeightDistribution`].
fn to_distribution(
    d: &DistributionJson,
    n_dims: usize,
    n_basis: usize,
) -> Result<crate::promp::WeightDistribution> {
    let n = d.mean.len();
    let mean = nalgebra::DVector::from_column_slice(&d.mean);
    let cov = nalgebra::DMatrix::from_fn(n, n, |i, j| d.cov[i][j]);
    crate::promp::WeightDistribution::new(mean, cov, n_dims, n_basis)
}

/// Shape and finiteness of a stored distribution of `n` weights.
fn check_distribution(field: &str, d: &DistributionJson, n: usize) -> Result<()> {
    ensure_len(&format!("{field}.mean"), &d.mean, n)?;
    ensure_finite(&format!("{field}.mean"), &d.mean)?;
    if d.cov.len() != n {
        return Err(Error::invalid(
            format!("{field}.cov"),
            format!("expected {n} rows, got {}", d.cov.len()),
        ));
    }
    for (i, row) in d.cov.iter().enumerate() {
        ensure_len(&format!("{field}.cov[{i}]"), row, n)?;
        ensure_finite(&format!("{field}.cov[{i}]"), row)?;
    }
    Ok(())
}

/// A target id names files: letters, digits, `-`, `_` and `.`, not
/// starting with `.`, at most 100 characters.
pub fn check_target_id(id: &str) -> Result<()> {
    let ok = !id.is_empty()
        && id.len() <= 100
        && !id.starts_with('.')
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(
            "id",
            format!("{id:?} must be 1-100 letters, digits, '-', '_' or '.', not starting with '.'"),
        ))
    }
}

/// A manifest path must be relative and stay inside the dataset directory.
fn relative_path(p: &str) -> Result<PathBuf> {
    let path = PathBuf::from(p);
    let ok = !p.is_empty()
        && path.is_relative()
        && path
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
    if ok {
        Ok(path)
    } else {
        Err(Error::invalid(
            "",
            format!("{p:?} must be a relative path inside the dataset directory"),
        ))
    }
}

/// Read and validate `DIR/manifest.json`.
pub fn load_manifest(dir: &Path) -> Result<Manifest> {
    let path = dir.join("manifest.json");
    let m: Manifest = read_json(&path)?;
    m.validate()
        .map_err(|e| Error::file(&path, e.to_string()))?;
    Ok(m)
}

/// Read and validate the record of one entry.
pub fn load_record(dir: &Path, entry: &TargetEntry) -> Result<TargetRecord> {
    let path = dir.join(relative_path(&entry.record).map_err(|e| e.within("record"))?);
    let r: TargetRecord = read_json(&path)?;
    r.validate()
        .map_err(|e| Error::file(&path, e.to_string()))?;
    if r.id != entry.id {
        return Err(Error::file(
            &path,
            format!(
                "id {:?} does not match the manifest entry {:?}",
                r.id, entry.id
            ),
        ));
    }
    Ok(r)
}

/// Read the image of one entry as 8-bit RGB.
pub fn load_image(dir: &Path, entry: &TargetEntry) -> Result<image::RgbImage> {
    let path = dir.join(relative_path(&entry.image).map_err(|e| e.within("image"))?);
    let img =
        image::open(&path).map_err(|e| Error::file(&path, format!("cannot read image: {e}")))?;
    Ok(img.to_rgb8())
}

/// Read the aligned depth image of one entry (`None` when the dataset has
/// no depth), in the dataset's depth scale.
pub fn load_depth(
    dir: &Path,
    entry: &TargetEntry,
    scale_m: f64,
) -> Result<Option<crate::perception::DepthImage>> {
    let Some(rel) = &entry.depth else {
        return Ok(None);
    };
    let path = dir.join(relative_path(rel).map_err(|e| e.within("depth"))?);
    let bytes = std::fs::read(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    crate::perception::DepthImage::decode_png(&bytes, scale_m, "depth")
        .map(Some)
        .map_err(|e| Error::file(&path, e.to_string()))
}

pub use crate::fsio::write_atomic;

/// Serialise `value` as pretty JSON to `path` atomically.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_vec_pretty(value)
        .map_err(|e| Error::file(path, format!("cannot serialise: {e}")))?;
    write_atomic(path, &text)
}

/// Encode an image as PNG and write it atomically.
pub fn write_png_atomic(path: &Path, img: &image::RgbImage) -> Result<()> {
    let mut bytes = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Sub,
    );
    image::ImageEncoder::write_image(
        encoder,
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| Error::file(path, format!("cannot encode PNG: {e}")))?;
    write_atomic(path, &bytes)
}

/// The true scene of a record: every obstacle of the configuration, each
/// marked `"intruder": true` when it was placed across the target's path
/// after the demonstrations were made (`dpmp data generate --intruders`).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RecordScene {
    /// The obstacles in the request schema, each with its intruder mark.
    pub obstacles: Vec<SceneObstacle>,
}

/// One obstacle of a record's scene.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SceneObstacle {
    /// The obstacle (request schema).
    #[serde(flatten)]
    pub obstacle: Obstacle,
    /// Placed after the demonstrations, which never met it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub intruder: bool,
}

impl RecordScene {
    /// A scene of `plant` obstacles and `intruders`, in that order.
    pub fn new(plant: SceneFile, intruders: Vec<Obstacle>) -> RecordScene {
        let mark = |intruder| move |obstacle| SceneObstacle { obstacle, intruder };
        RecordScene {
            obstacles: plant
                .obstacles
                .into_iter()
                .map(mark(false))
                .chain(intruders.into_iter().map(mark(true)))
                .collect(),
        }
    }

    /// Every obstacle, as a request takes them.
    pub fn obstacles(&self) -> Vec<Obstacle> {
        self.obstacles.iter().map(|o| o.obstacle.clone()).collect()
    }

    /// The obstacles the demonstrations met (all but the intruders).
    pub fn plant(&self) -> Vec<Obstacle> {
        self.marked(false)
    }

    /// The intruders.
    pub fn intruders(&self) -> Vec<Obstacle> {
        self.marked(true)
    }

    fn marked(&self, intruder: bool) -> Vec<Obstacle> {
        self.obstacles
            .iter()
            .filter(|o| o.intruder == intruder)
            .map(|o| o.obstacle.clone())
            .collect()
    }
}
