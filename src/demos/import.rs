//! A trainable dataset from a lab's own data (`dpmp data import`).
//!
//! The input is a JSON manifest; every path in it is relative to the
//! manifest's folder:
//!
//! ```json
//! {"camera": {"intrinsics": {...}, "mount_back_m": 0.05, "mount_up_m": 0.04},
//!  "depth_scale_m": 0.001,
//!  "targets": [{"id": "plant3-b1", "group": "plant3", "image": "img/p3b1.png",
//!               "box": [x1, y1, x2, y2], "mask_applied": false,
//!               "depth": "depth/p3b1.png",
//!               "demos": ["demos/p3b1/0.csv", "demos/p3b1/1.csv"],
//!               "task_demos": ["demos/p3b1/0-tcp.csv", "demos/p3b1/1-tcp.csv"],
//!               "obstacles": [...]}]}
//! ```
//!
//! A target takes its prior from recorded demonstrations (`demos`, fitted
//! as in [`super::fit`]) or from the paper's annotation folder (`"prior":
//! {"annotation": "dir", "index": K}`). Its task-space weights are derived
//! from the demonstrations by FK, or fitted from `task_demos`, TCP
//! recordings of the same demonstrations ([`super::task`]). `camera` (default: the generator's
//! D435i on the Panda's gripper), `depth`, `obstacles` and `mask_applied`
//! are optional. `group` is the plant: the splits never put one group in
//! two sets.
//!
//! Import validates every target (image decodes and matches the camera,
//! box inside it, depth decodes, matches and has the berry in it, demos
//! read and fit within the joint limits, obstacles valid) and reports every
//! bad target by id in one error; only then it writes the dataset into a
//! temporary folder beside `--out` and renames it, so `--out` holds a whole
//! dataset or nothing.

use super::task::set_task_space;
use super::{fit_prior, read_demonstration_with, ReadOptions};
use crate::perception::{locate_target, Camera, CameraModel, DepthImage};
use crate::promp::{annotation, Basis, PrompConfig, WeightDistribution};
use crate::robot::Robot;
use crate::scene::{Obstacle, SceneFile};
use crate::synth::dataset::{
    self, check_target_id, write_json_atomic, write_png_atomic, Demo, DistributionJson, Manifest,
    Splits, TargetEntry, TargetRecord, IMPORT_FORMAT,
};
use crate::{Error, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The manifest `dpmp data import` reads.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportManifest {
    /// The camera that took the images (default: the generator's).
    #[serde(default)]
    pub camera: Option<CameraModel>,
    /// Metres per unit of the depth images (default 0.001).
    #[serde(default)]
    pub depth_scale_m: Option<f64>,
    /// Unit of the recordings' `time` column: `auto` (default), `s`, `ms`,
    /// `us` or `ns` (see [`TimeUnit`](super::TimeUnit)).
    #[serde(default)]
    pub time_unit: Option<String>,
    /// Joints recorded under other column names: `{"panda_joint1":
    /// "position_0", ...}` (joints not listed keep their names).
    #[serde(default)]
    pub joint_columns: std::collections::BTreeMap<String, String>,
    /// The targets.
    pub targets: Vec<ImportTarget>,
}

/// One target of an [`ImportManifest`].
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportTarget {
    /// Unique id (letters, digits, `-`, `_`, `.`); names the written files.
    pub id: String,
    /// The plant (or other unit) the target belongs to.
    pub group: String,
    /// Colour image (PNG or JPEG).
    pub image: String,
    /// Target box `[x1, y1, x2, y2]` in pixels.
    #[serde(rename = "box")]
    pub bbox: [f64; 4],
    /// Whether the image already shows the box painted white.
    #[serde(default)]
    pub mask_applied: bool,
    /// Aligned 16-bit depth PNG.
    #[serde(default)]
    pub depth: Option<String>,
    /// Demonstration files (CSV or JSON).
    #[serde(default)]
    pub demos: Option<Vec<String>>,
    /// Or a prior from the paper's annotation folder.
    #[serde(default)]
    pub prior: Option<AnnotationSource>,
    /// TCP recordings of the same demonstrations (`time, x, y, z, qx, qy,
    /// qz, qw`; [`super::task`]), in the order of `demos`: the task-space
    /// weights are fitted from them instead of derived by FK.
    #[serde(default)]
    pub task_demos: Option<Vec<String>>,
    /// Motion duration (s) for a target with an annotation prior
    /// (default 4 s; with demos, their median duration).
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// The scene's obstacles (request schema).
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
}

/// A prior in the paper's annotation layout (`dir/J1..Jn/{index}.json`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnnotationSource {
    /// The annotation folder.
    pub annotation: String,
    /// Target index K.
    pub index: usize,
}

/// How [`import`] splits and fits.
#[derive(Clone, Debug)]
pub struct ImportSettings {
    /// ProMP basis of the fitted weights.
    pub promp: PrompConfig,
    /// Fraction of groups for validation.
    pub val_fraction: f64,
    /// Fraction of groups for test.
    pub test_fraction: f64,
    /// Seed of the group shuffle.
    pub seed: u64,
    /// Replace an existing `--out`.
    pub overwrite: bool,
    /// Draw a progress bar on stderr.
    pub progress: bool,
}

impl Default for ImportSettings {
    fn default() -> Self {
        ImportSettings {
            promp: PrompConfig::default(),
            val_fraction: 0.1,
            test_fraction: 0.1,
            seed: 0,
            overwrite: false,
            progress: false,
        }
    }
}

/// What an import wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ImportSummary {
    /// The dataset folder.
    pub out: PathBuf,
    /// Targets written.
    pub targets: usize,
    /// Groups, and how many went to train / val / test.
    pub groups: usize,
    /// Targets per split.
    pub train: usize,
    /// Validation targets.
    pub val: usize,
    /// Test targets.
    pub test: usize,
    /// Demonstrations fitted.
    pub demonstrations: usize,
    /// Largest RMS fit residual of any demonstration (rad).
    pub max_rms_residual_rad: f64,
}

/// One validated target, ready to write.
struct Prepared {
    entry: TargetEntry,
    image: image::RgbImage,
    depth: Option<DepthImage>,
    record: TargetRecord,
    max_rms_residual: f64,
}

/// Import the dataset `manifest_path` describes into `out` for `robot`.
pub fn import(
    manifest_path: &Path,
    out: &Path,
    robot: &Robot,
    settings: &ImportSettings,
) -> Result<ImportSummary> {
    check_fractions(settings)?;
    check_out(out, settings.overwrite)?;
    let manifest: ImportManifest = read_manifest(manifest_path)?;
    let base = manifest_path.parent().unwrap_or(Path::new("."));
    let basis = Basis::new(&settings.promp).map_err(|e| e.within("promp"))?;
    let camera_model = manifest.camera.unwrap_or_else(|| {
        crate::synth::settings::SynthSettings::default()
            .camera
            .model
    });
    camera_model
        .validate("camera")
        .map_err(|e| Error::file(manifest_path, e.to_string()))?;
    let camera = Camera::at_home(&camera_model, robot)?;
    let scale = manifest
        .depth_scale_m
        .unwrap_or(dataset::DEFAULT_DEPTH_SCALE_M);
    if !(scale.is_finite() && scale > 0.0 && scale <= 0.01) {
        return Err(Error::file(
            manifest_path,
            format!("depth_scale_m must be in (0, 0.01] m per unit, got {scale}"),
        ));
    }
    check_ids_and_groups(&manifest, manifest_path)?;
    let read =
        read_options(&manifest, robot).map_err(|e| Error::file(manifest_path, e.to_string()))?;
    let group_names = group_names(&manifest);
    let groups = group_indices(&manifest, &group_names);
    let context = Context {
        base,
        robot,
        basis: &basis,
        camera: &camera,
        scale,
        read: &read,
    };
    let mut prepared = Vec::new();
    let mut problems = Vec::new();
    let progress = crate::progress::bar(
        settings.progress,
        manifest.targets.len() as u64,
        "targets checked",
    );
    for (i, target) in manifest.targets.iter().enumerate() {
        progress.inc(1);
        let (config, berry) = groups[i];
        match context.prepare(target, config, berry) {
            Ok(p) => prepared.push(p),
            Err(e) => problems.push(format!("targets[{i}] ({}): {e}", target.id)),
        }
    }
    progress.finish_and_clear();
    if !problems.is_empty() {
        return Err(Error::file(
            manifest_path,
            format!(
                "{} of {} targets are invalid, nothing written:\n  {}",
                problems.len(),
                manifest.targets.len(),
                problems.join("\n  ")
            ),
        ));
    }
    let splits = split_by_group(&manifest, &group_names, settings);
    let written = Manifest {
        format: IMPORT_FORMAT.to_string(),
        generator_version: Some(env!("CARGO_PKG_VERSION").to_string()),
        seed: Some(settings.seed),
        settings: None,
        promp: settings.promp.clone(),
        camera: camera_model.intrinsics,
        camera_model: Some(camera_model),
        depth_scale_m: Some(scale),
        robot: Some(robot.identity()),
        splits,
        targets: prepared.iter().map(|p| p.entry.clone()).collect(),
    };
    write_dataset(out, &written, &prepared, settings.overwrite)?;
    Ok(ImportSummary {
        out: out.to_path_buf(),
        targets: prepared.len(),
        groups: group_names.len(),
        train: written.splits.train.len(),
        val: written.splits.val.len(),
        test: written.splits.test.len(),
        demonstrations: prepared.iter().map(|p| p.record.demos.len()).sum(),
        max_rms_residual_rad: prepared
            .iter()
            .map(|p| p.max_rms_residual)
            .fold(0.0, f64::max),
    })
}

fn check_fractions(s: &ImportSettings) -> Result<()> {
    for (name, f) in [
        ("val_fraction", s.val_fraction),
        ("test_fraction", s.test_fraction),
    ] {
        if !(0.0..1.0).contains(&f) {
            return Err(Error::invalid(name, format!("must be in [0, 1), got {f}")));
        }
    }
    if s.val_fraction + s.test_fraction >= 1.0 {
        return Err(Error::invalid(
            "test_fraction",
            "val_fraction + test_fraction must leave groups for training",
        ));
    }
    Ok(())
}

fn check_out(out: &Path, overwrite: bool) -> Result<()> {
    if out.exists() && !overwrite {
        return Err(Error::file(
            out,
            "already exists (pass --overwrite to replace it)",
        ));
    }
    Ok(())
}

fn read_manifest(path: &Path) -> Result<ImportManifest> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    let manifest: ImportManifest = serde_path_to_error::deserialize(de)
        .map_err(|e| Error::file(path, format!("{}: {}", e.path(), e.inner())))?;
    if manifest.targets.is_empty() {
        return Err(Error::file(path, "targets: empty, nothing to import"));
    }
    Ok(manifest)
}

/// The manifest's `time_unit` and `joint_columns` as reading options;
/// errors name the field.
fn read_options(manifest: &ImportManifest, robot: &Robot) -> Result<ReadOptions> {
    let time_unit = match &manifest.time_unit {
        Some(text) => text
            .parse()
            .map_err(|e: String| Error::invalid("time_unit", e))?,
        None => super::TimeUnit::Auto,
    };
    let pairs = manifest
        .joint_columns
        .iter()
        .map(|(j, c)| (j.clone(), c.clone()))
        .collect();
    let joint_columns =
        ReadOptions::check_joint_columns("joint_columns", pairs, robot.joint_names())?;
    Ok(ReadOptions {
        time_unit,
        joint_columns,
    })
}

/// Every id well-formed and unique, every group named; errors name the
/// target.
fn check_ids_and_groups(manifest: &ImportManifest, path: &Path) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    for (i, t) in manifest.targets.iter().enumerate() {
        check_target_id(&t.id)
            .map_err(|e| Error::file(path, e.within(&format!("targets[{i}]")).to_string()))?;
        if !seen.insert(t.id.as_str()) {
            return Err(Error::file(
                path,
                format!("targets[{i}].id: {:?} appears twice", t.id),
            ));
        }
        if t.group.trim().is_empty() {
            return Err(Error::file(
                path,
                format!("targets[{i}].group: must not be empty"),
            ));
        }
    }
    Ok(())
}

/// The group names, sorted and unique.
fn group_names(manifest: &ImportManifest) -> Vec<&str> {
    let mut names: Vec<&str> = manifest.targets.iter().map(|t| t.group.as_str()).collect();
    names.sort_unstable();
    names.dedup();
    names
}

/// Each target's (index of its group in `names`, index within its group).
fn group_indices(manifest: &ImportManifest, names: &[&str]) -> Vec<(usize, usize)> {
    let mut counts = vec![0usize; names.len()];
    manifest
        .targets
        .iter()
        .map(|t| {
            let g = names.binary_search(&t.group.as_str()).unwrap_or_default();
            counts[g] += 1;
            (g, counts[g] - 1)
        })
        .collect()
}

/// Groups shuffled by the seed, then cut into val / test / train; a group
/// never spans two sets. With at least three groups and a positive
/// fraction, each of val and test gets at least one group.
fn split_by_group(manifest: &ImportManifest, names: &[&str], s: &ImportSettings) -> Splits {
    let mut groups = names.to_vec();
    groups.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(s.seed));
    let n = groups.len();
    let count = |f: f64| {
        let k = (n as f64 * f).round() as usize;
        if n >= 3 && f > 0.0 {
            k.max(1)
        } else {
            k
        }
    };
    let (n_val, n_test) = (count(s.val_fraction), count(s.test_fraction));
    let (n_val, n_test) = if n_val + n_test >= n {
        (0, 0)
    } else {
        (n_val, n_test)
    };
    let ids = |gs: &[&str]| -> Vec<String> {
        manifest
            .targets
            .iter()
            .filter(|t| gs.contains(&t.group.as_str()))
            .map(|t| t.id.clone())
            .collect()
    };
    Splits {
        val: ids(&groups[..n_val]),
        test: ids(&groups[n_val..n_val + n_test]),
        train: ids(&groups[n_val + n_test..]),
    }
}

/// What every target's validation needs.
struct Context<'a> {
    base: &'a Path,
    robot: &'a Robot,
    basis: &'a Basis,
    camera: &'a Camera,
    scale: f64,
    read: &'a ReadOptions,
}

impl Context<'_> {
    fn path(&self, rel: &str) -> PathBuf {
        self.base.join(rel)
    }

    /// Validate one target and build its record.
    fn prepare(&self, t: &ImportTarget, config: usize, berry: usize) -> Result<Prepared> {
        let image = self.image(t)?;
        let depth = t.depth.as_ref().map(|rel| self.depth(rel)).transpose()?;
        let located = depth
            .as_ref()
            .map(|d| locate_target(d, &t.bbox, self.camera, "depth"))
            .transpose()?;
        crate::scene::obstacle::validate_obstacles(&t.obstacles)
            .map_err(|e| e.within("obstacles"))?;
        let prior = self.prior(t)?;
        let id = t.id.clone();
        let entry = TargetEntry {
            image: format!("images/{id}.png"),
            record: format!("targets/{id}.json"),
            depth: depth.as_ref().map(|_| format!("depth/{id}.png")),
            group: Some(t.group.clone()),
            mask_applied: t.mask_applied,
            id: id.clone(),
            config,
            berry,
        };
        let dist = &prior.distribution;
        let mut record = TargetRecord {
            id,
            config,
            berry,
            image: entry.image.clone(),
            depth: entry.depth.clone(),
            target_depth_m: located.as_ref().map(|l| l.depth_m),
            bbox: t.bbox,
            center: [(t.bbox[0] + t.bbox[2]) / 2.0, (t.bbox[1] + t.bbox[3]) / 2.0],
            scene: crate::synth::dataset::RecordScene::new(
                SceneFile {
                    obstacles: t.obstacles.clone(),
                },
                Vec::new(),
            ),
            target_obstacle_id: String::new(),
            target_position: None,
            start: prior.start,
            final_tcp: prior.final_tcp,
            duration_s: prior.duration_s,
            promp: self.basis.config().clone(),
            demos: prior.demos,
            distribution: DistributionJson::from(dist),
            task_distribution: None,
            annotation: annotation::joints_from_distribution(dist)?,
        };
        record.fill_task_space(self.robot)?;
        if let Some(files) = &t.task_demos {
            let paths: Vec<PathBuf> = files.iter().map(|f| self.path(f)).collect();
            set_task_space(self.basis, self.robot, &paths, self.read, &mut record)
                .map_err(|e| e.within("task_demos"))?;
        }
        record.validate()?;
        Ok(Prepared {
            entry,
            image,
            depth,
            record,
            max_rms_residual: prior.max_rms_residual,
        })
    }

    fn image(&self, t: &ImportTarget) -> Result<image::RgbImage> {
        let path = self.path(&t.image);
        let image = image::open(&path)
            .map_err(|e| {
                Error::invalid(
                    "image",
                    format!("{}: cannot read image: {e}", path.display()),
                )
            })?
            .to_rgb8();
        let k = &self.camera.intrinsics;
        if (image.width(), image.height()) != (k.width, k.height) {
            return Err(Error::invalid(
                "image",
                format!(
                    "{} is {}x{}, the camera's images are {}x{} (set the manifest's camera)",
                    path.display(),
                    image.width(),
                    image.height(),
                    k.width,
                    k.height
                ),
            ));
        }
        crate::net::preprocess::validate_box(t.bbox, image.width(), image.height())?;
        Ok(image)
    }

    fn depth(&self, rel: &str) -> Result<DepthImage> {
        let path = self.path(rel);
        let bytes = std::fs::read(&path)
            .map_err(|e| Error::invalid("depth", format!("{}: {e}", path.display())))?;
        DepthImage::decode_png(&bytes, self.scale, "depth")
            .map_err(|e| Error::invalid("depth", format!("{}: {e}", path.display())))
    }

    /// The target's prior, from demonstrations or an annotation folder.
    fn prior(&self, t: &ImportTarget) -> Result<TargetPrior> {
        match (&t.demos, &t.prior) {
            (Some(demos), None) => self.prior_from_demos(demos),
            (None, Some(source)) => self.prior_from_annotation(source, t.duration_s),
            _ => Err(Error::invalid(
                "demos",
                "give either demos (a list of recordings) or prior (an annotation folder and index)",
            )),
        }
    }

    fn prior_from_demos(&self, files: &[String]) -> Result<TargetPrior> {
        let recordings = files
            .iter()
            .map(|f| read_demonstration_with(&self.path(f), self.robot.joint_names(), self.read))
            .collect::<Result<Vec<_>>>()?;
        let fit = fit_prior(self.basis, self.robot, &recordings)?;
        let n = self.robot.dof();
        let firsts: Vec<Vec<f64>> = recordings
            .iter()
            .map(|r| r.positions.row(0).iter().copied().collect())
            .collect();
        let finals: Vec<Vec<f64>> = recordings
            .iter()
            .map(|r| r.positions.row(r.len() - 1).iter().copied().collect())
            .collect();
        let start = (0..n)
            .map(|j| firsts.iter().map(|q| q[j]).sum::<f64>() / firsts.len() as f64)
            .collect();
        let poses: Vec<_> = finals.iter().map(|q| self.robot.tcp_pose(q)).collect();
        Ok(TargetPrior {
            duration_s: fit.median_duration_s(),
            max_rms_residual: fit.max_rms_residual(),
            demos: fit
                .weights
                .iter()
                .zip(finals)
                .map(|(w, final_q)| Demo {
                    weights: w.as_slice().to_vec(),
                    final_q,
                    task_weights: None,
                })
                .collect(),
            start,
            final_tcp: crate::synth::demos::mean_pose(&poses),
            distribution: fit.distribution,
        })
    }

    fn prior_from_annotation(
        &self,
        source: &AnnotationSource,
        duration_s: Option<f64>,
    ) -> Result<TargetPrior> {
        let prior = annotation::load_dir(&self.path(&source.annotation), source.index)?;
        let dist = prior.distribution;
        if dist.n_joints != self.robot.dof() || dist.n_basis != self.basis.n_basis() {
            return Err(Error::invalid(
                "prior",
                format!(
                    "{} joints x {} basis functions, expected {} x {}",
                    dist.n_joints,
                    dist.n_basis,
                    self.robot.dof(),
                    self.basis.n_basis()
                ),
            ));
        }
        let duration_s = duration_s.unwrap_or(4.0);
        if !(duration_s.is_finite() && duration_s > 0.0) {
            return Err(Error::invalid("duration_s", "must be a finite number > 0"));
        }
        let mean = dist.trajectory_mean(self.basis);
        let start = mean.row(0).iter().copied().collect();
        let last: Vec<f64> = mean.row(mean.nrows() - 1).iter().copied().collect();
        Ok(TargetPrior {
            duration_s,
            max_rms_residual: 0.0,
            demos: Vec::new(),
            start,
            final_tcp: crate::synth::demos::mean_pose(&[self.robot.tcp_pose(&last)]),
            distribution: dist,
        })
    }
}

/// A target's prior and what the record keeps of its demonstrations.
struct TargetPrior {
    distribution: WeightDistribution,
    demos: Vec<Demo>,
    start: Vec<f64>,
    final_tcp: dataset::Pose,
    duration_s: f64,
    max_rms_residual: f64,
}

/// Write the dataset into a temporary folder beside `out`, then rename it
/// (replacing `out` when `overwrite`); on failure nothing is left.
fn write_dataset(
    out: &Path,
    manifest: &Manifest,
    targets: &[Prepared],
    overwrite: bool,
) -> Result<()> {
    let name = out
        .file_name()
        .ok_or_else(|| Error::file(out, "not a folder path"))?
        .to_string_lossy();
    let tmp = out.with_file_name(format!(".{name}.import-{}", std::process::id()));
    let result = write_into(&tmp, manifest, targets).and_then(|()| {
        if overwrite && out.exists() {
            std::fs::remove_dir_all(out).map_err(|e| Error::file(out, e.to_string()))?;
        }
        std::fs::rename(&tmp, out).map_err(|e| Error::write(out, format!("cannot write: {e}")))
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

fn write_into(dir: &Path, manifest: &Manifest, targets: &[Prepared]) -> Result<()> {
    for t in targets {
        write_png_atomic(&dir.join(&t.entry.image), &t.image)?;
        if let (Some(rel), Some(depth)) = (&t.entry.depth, &t.depth) {
            crate::fsio::write_atomic(&dir.join(rel), &depth.encode_png()?)?;
        }
        write_json_atomic(&dir.join(&t.entry.record), &t.record)?;
    }
    write_json_atomic(&dir.join("manifest.json"), manifest)?;
    // The written dataset must load as one.
    dataset::load_manifest(dir).map(|_| ())
}
