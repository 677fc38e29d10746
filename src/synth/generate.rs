//! The parallel dataset driver behind `dpmp data generate`.
//!
//! [`Generator::new`] checks everything before any file is written (settings,
//! the camera posed by forward kinematics at home, the region in view and
//! reachable). [`Generator::config`] makes one configuration in memory:
//! plant, demonstrations for every berry (the whole configuration is drawn
//! again when a berry has no valid demonstration, a bounded number of
//! times), one render, and per target the noisy image with its white box
//! and the record. Every configuration has its own ChaCha8 stream derived
//! from the seed, so the output is byte-identical for any worker count.
//! [`generate`] runs the configurations on a rayon pool, writes images and
//! records atomically as they finish and the manifest last.

use crate::perception::{locate_target, DepthImage};
use crate::promp::{Basis, PrompConfig};
use crate::robot::{IkOptions, IkTarget, Robot};
use crate::scene::Scene;
use crate::synth::camera::Camera;
use crate::synth::dataset::{
    self, DistributionJson, Manifest, RecordScene, Splits, TargetEntry, TargetRecord,
};
use crate::synth::demos::{approach_axis, DemoContext, TargetDemos};
use crate::synth::intruders::{place_intruders, Intruder, TargetView};
use crate::synth::obstacles::plant_scene_file;
use crate::synth::plant::{sample_plant, Placement, Plant};
use crate::synth::render::depth::measured_depth;
use crate::synth::render::{box_center, render_plant, target_box, target_image};
use crate::synth::settings::RegionAnchor;
use crate::synth::settings::SynthSettings;
use crate::{Error, Result};
use image::RgbImage;
use nalgebra::Point3;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// A validated generator: settings, robot, basis and the posed camera.
pub struct Generator {
    settings: SynthSettings,
    robot: Robot,
    basis: Basis,
    camera: Camera,
}

/// One configuration, in memory.
pub struct ConfigOutput {
    /// One record per berry.
    pub records: Vec<TargetRecord>,
    /// One image per berry.
    pub images: Vec<RgbImage>,
    /// One aligned depth image per berry (when depth is enabled).
    pub depths: Vec<Option<DepthImage>>,
    /// Draws of the configuration that were needed (1 = first draw accepted).
    pub attempts: usize,
}

/// Per berry of a configuration: records, colour images, depth images.
type RenderedTargets = (Vec<TargetRecord>, Vec<RgbImage>, Vec<Option<DepthImage>>);

/// The RNG of the depth noise of configuration `config` under `seed`: a
/// stream of its own, so the colour images do not depend on the depth
/// settings.
pub fn depth_rng(seed: u64, config: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xD3E7_5EED_0000_0000);
    rng.set_stream(config as u64);
    rng
}

/// The RNG of configuration `config` under `seed` (its own ChaCha8 stream).
pub fn config_rng(seed: u64, config: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(config as u64);
    rng
}

impl Generator {
    /// Validate `settings` against the robot: the camera is posed by FK at
    /// home, the region must be in view and its centre and corners reachable
    /// at the pre-grasp standoff.
    pub fn new(settings: SynthSettings, robot: Robot) -> Result<Generator> {
        settings.validate()?;
        if settings.demos.null_space_std_rad.len() != robot.dof() {
            return Err(Error::invalid(
                "demos.null_space_std_rad",
                format!(
                    "expected {} numbers (one per joint), got {}",
                    robot.dof(),
                    settings.demos.null_space_std_rad.len()
                ),
            ));
        }
        let basis = Basis::new(&PrompConfig::default())?;
        let camera = Camera::at_home(&settings.camera.model, &robot)?;
        let g = Generator {
            settings,
            robot,
            basis,
            camera,
        };
        g.check_region_in_view()?;
        g.check_region_reachable()?;
        Ok(g)
    }

    /// The settings.
    pub fn settings(&self) -> &SynthSettings {
        &self.settings
    }

    /// The gripper camera at home.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The robot.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The ProMP basis of the records.
    pub fn basis(&self) -> &Basis {
        &self.basis
    }

    fn home_tcp(&self) -> Point3<f64> {
        Point3::from(self.robot.tcp_pose(&self.robot.home()).translation.vector)
    }

    /// Where berries go relative to the region draws (see [`RegionAnchor`]).
    pub fn placement(&self) -> Placement {
        match self.settings.plant.region_anchor {
            RegionAnchor::PreGrasp => Placement {
                origin: self.home_tcp(),
                push_m: self.settings.demos.standoff_m,
            },
            RegionAnchor::Berry => Placement::at_points(),
        }
    }

    fn check_region_in_view(&self) -> Result<()> {
        let c = self
            .placement()
            .berry_center(&Point3::from(self.settings.plant.region.center()));
        let inside = self
            .camera
            .project(&c)
            .is_some_and(|(uv, _)| self.camera.box_inside(&[uv[0], uv[1], uv[0], uv[1]], 0.0));
        if inside {
            Ok(())
        } else {
            Err(Error::invalid(
                "plant.region",
                format!(
                    "its centre {:?} is outside the gripper camera's view at home",
                    self.settings.plant.region.center()
                ),
            ))
        }
    }

    fn check_region_reachable(&self) -> Result<()> {
        let region = &self.settings.plant.region;
        let home = self.robot.home();
        let tcp = self.home_tcp();
        let placement = self.placement();
        for p in std::iter::once(region.center()).chain(region.corners()) {
            let berry = placement.berry_center(&Point3::from(p));
            let axis = approach_axis(&tcp, &berry).map_err(|e| e.within("plant.region"))?;
            let target = IkTarget {
                position: berry - axis.into_inner() * self.settings.demos.standoff_m,
                approach_axis: Some(axis),
            };
            let d = &self.settings.demos;
            let options = IkOptions {
                tolerance_m: d.ik_tolerance_m,
                axis_tolerance_rad: d.ik_axis_tolerance_rad,
                ..IkOptions::default()
            };
            let sol = self.robot.ik(&target, &home, &options)?;
            if !(sol.position_error_m <= d.ik_tolerance_m
                && sol.axis_error_rad <= d.ik_axis_tolerance_rad)
            {
                return Err(Error::invalid(
                    "plant.region",
                    format!(
                        "unreachable: the pre-grasp pose for a berry at {p:?} has no IK solution \
                         (position error {:.3} m, axis error {:.3} rad)",
                        sol.position_error_m, sol.axis_error_rad
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Generate configuration `config` under `seed`.
    pub fn config(&self, seed: u64, config: usize) -> Result<ConfigOutput> {
        let mut rng = config_rng(seed, config);
        let mut last = String::new();
        for attempt in 1..=self.settings.demos.max_config_tries {
            let plant = sample_plant(
                &self.settings.plant,
                &self.camera,
                self.settings.camera.border_px,
                self.settings.berries_per_config,
                &self.placement(),
                &mut rng,
            )?;
            let made = self
                .demos_for(&plant, &mut rng)
                .and_then(|(scene_file, demos)| {
                    let rngs = (&mut rng, &mut depth_rng(seed, config));
                    self.finish(config, &plant, scene_file, demos, rngs)
                });
            match made {
                Ok((records, images, depths)) => {
                    return Ok(ConfigOutput {
                        records,
                        images,
                        depths,
                        attempts: attempt,
                    })
                }
                Err(Error::Infeasible(reason)) => last = reason,
                Err(other) => return Err(other),
            }
        }
        Err(Error::Infeasible(format!(
            "configuration {config}: gave up after {} plant draws; last: {last}",
            self.settings.demos.max_config_tries
        )))
    }

    fn demos_for(
        &self,
        plant: &Plant,
        rng: &mut ChaCha8Rng,
    ) -> Result<(crate::scene::SceneFile, Vec<TargetDemos>)> {
        let scene_file = plant_scene_file(plant);
        let scene = Scene::new(scene_file.obstacles.clone())?;
        let ctx = DemoContext {
            robot: &self.robot,
            scene: &scene,
            basis: &self.basis,
            settings: &self.settings.demos,
        };
        let demos = plant
            .berries
            .iter()
            .map(|b| ctx.target(&b.center, &b.id, rng))
            .collect::<Result<Vec<_>>>()?;
        Ok((scene_file, demos))
    }

    /// Render the plant once (per target when it has intruders), then per
    /// berry: its box, its intruders, the colour image with sensor noise and
    /// the box painted, the depth image with its error model and the
    /// target's measured depth, and the record.
    fn finish(
        &self,
        config: usize,
        plant: &Plant,
        scene: crate::scene::SceneFile,
        demos: Vec<TargetDemos>,
        (rng, depth_rng): (&mut ChaCha8Rng, &mut ChaCha8Rng),
    ) -> Result<RenderedTargets> {
        let render = &self.settings.render;
        let shared = (self.settings.intruders == 0)
            .then(|| render_plant(plant, &self.camera, render, &mut *rng));
        let mut out = (Vec::new(), Vec::new(), Vec::new());
        for (i, (berry, td)) in plant.berries.iter().zip(demos).enumerate() {
            let bbox = target_box(&self.camera, berry).ok_or_else(|| {
                Error::Numerical(format!("berry {} is behind the camera", berry.id))
            })?;
            let intruders = self.intruders_for(berry, bbox, &td, &mut *rng)?;
            let own;
            let (base, exact_depth) = match &shared {
                Some((base, depth)) => (base, depth),
                None => {
                    let mut with = plant.clone();
                    intruders.iter().for_each(|x| x.add_to(&mut with));
                    own = render_plant(&with, &self.camera, render, &mut *rng);
                    (&own.0, &own.1)
                }
            };
            let noise = render.noise_std.sample(&mut *rng);
            out.1.push(target_image(base, &bbox, noise, &mut *rng));
            let intruder_obstacles = intruders.iter().flat_map(Intruder::obstacles).collect();
            let record_scene = RecordScene::new(scene.clone(), intruder_obstacles);
            let mut record = self.record(config, i, berry, bbox, record_scene, td);
            record.fill_task_space(&self.robot)?;
            let depth = self.measure_depth(exact_depth, &bbox, depth_rng, &mut record)?;
            out.2.push(depth);
            out.0.push(record);
        }
        Ok(out)
    }

    /// The intruders of one target ([`crate::synth::intruders`]); a target
    /// where they find no place makes the configuration be drawn again.
    fn intruders_for(
        &self,
        berry: &crate::synth::plant::Berry,
        target_box: [f64; 4],
        td: &TargetDemos,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Intruder>> {
        let n = self.settings.intruders;
        if n == 0 {
            return Ok(Vec::new());
        }
        let mean = td.distribution.trajectory_mean(&self.basis);
        let view = TargetView {
            robot: &self.robot,
            camera: &self.camera,
            target: berry,
            target_box,
            mean: &mean,
        };
        place_intruders(&view, n, rng)?.ok_or_else(|| {
            Error::Infeasible(format!(
                "no place for {n} intruder(s) across the path to {}",
                berry.id
            ))
        })
    }

    /// The depth image of one target and its measured depth (written into
    /// `record`); `None` when depth is disabled. A berry whose box holds
    /// too little valid depth keeps its image but no measured depth.
    fn measure_depth(
        &self,
        exact: &[f64],
        bbox: &[f64; 4],
        rng: &mut ChaCha8Rng,
        record: &mut TargetRecord,
    ) -> Result<Option<DepthImage>> {
        let settings = &self.settings.depth;
        if !settings.enabled {
            return Ok(None);
        }
        let width = self.camera.intrinsics.width as usize;
        let depth = measured_depth(exact, width, settings, rng)?;
        record.depth = Some(format!("depth/{}.png", record.id));
        record.target_depth_m = locate_target(&depth, bbox, &self.camera, "depth")
            .ok()
            .map(|t| t.depth_m);
        Ok(Some(depth))
    }

    fn record(
        &self,
        config: usize,
        index: usize,
        berry: &crate::synth::plant::Berry,
        bbox: [f64; 4],
        scene: RecordScene,
        td: TargetDemos,
    ) -> TargetRecord {
        let entry = TargetEntry::new(config, index);
        TargetRecord {
            id: entry.id,
            config,
            berry: index,
            image: entry.image,
            depth: None,
            target_depth_m: None,
            bbox,
            center: box_center(&bbox),
            scene,
            target_obstacle_id: berry.id.clone(),
            target_position: Some([berry.center.x, berry.center.y, berry.center.z]),
            start: td.start,
            final_tcp: td.final_tcp,
            duration_s: self.settings.demos.duration_s,
            promp: self.basis.config().clone(),
            demos: td
                .demos
                .iter()
                .map(|d| dataset::Demo {
                    weights: d.weights.iter().copied().collect(),
                    final_q: d.final_q(),
                    task_weights: None,
                })
                .collect(),
            distribution: DistributionJson::from(&td.distribution),
            task_distribution: None,
            annotation: td.annotation,
        }
    }

    /// The manifest for `seed` listing every target.
    pub fn manifest(&self, seed: u64) -> Manifest {
        let s = &self.settings;
        let targets: Vec<TargetEntry> = (0..s.configs)
            .flat_map(|c| (0..s.berries_per_config).map(move |b| TargetEntry::new(c, b)))
            .map(|mut t| {
                if s.depth.enabled {
                    t.depth = Some(format!("depth/{}.png", t.id));
                }
                t
            })
            .collect();
        Manifest {
            format: dataset::FORMAT.to_string(),
            generator_version: Some(env!("CARGO_PKG_VERSION").to_string()),
            seed: Some(seed),
            settings: Some(s.clone()),
            promp: self.basis.config().clone(),
            camera: s.camera.model.intrinsics,
            camera_model: None,
            depth_scale_m: None,
            robot: None,
            splits: split_by_config(s, seed),
            targets,
        }
    }
}

/// Train / val / test ids: configurations shuffled by the seed, never one
/// configuration across sets.
pub fn split_by_config(s: &SynthSettings, seed: u64) -> Splits {
    let mut configs: Vec<usize> = (0..s.configs).collect();
    configs.shuffle(&mut config_rng(seed, usize::MAX));
    let n_val = (s.configs as f64 * s.split.val_fraction).round() as usize;
    let n_test = (s.configs as f64 * s.split.test_fraction).round() as usize;
    let (n_val, n_test) = if n_val + n_test >= s.configs {
        (0, 0)
    } else {
        (n_val, n_test)
    };
    let ids = |cs: &[usize]| -> Vec<String> {
        let mut cs = cs.to_vec();
        cs.sort_unstable();
        cs.iter()
            .flat_map(|&c| (0..s.berries_per_config).map(move |b| dataset::target_id(c, b)))
            .collect()
    };
    Splits {
        val: ids(&configs[..n_val]),
        test: ids(&configs[n_val..n_val + n_test]),
        train: ids(&configs[n_val + n_test..]),
    }
}

/// What a run did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GenerateSummary {
    /// Output directory.
    pub out: PathBuf,
    /// Configurations written.
    pub configs: usize,
    /// Targets written.
    pub targets: usize,
    /// Configurations that needed more than one plant draw.
    pub redrawn_configs: usize,
    /// Wall time (s).
    pub elapsed_s: f64,
    /// Throughput.
    pub targets_per_s: f64,
    /// What the user should know, e.g. an empty validation or test split
    /// (also printed to stderr by the CLI).
    pub warnings: Vec<String>,
}

/// Options of [`generate`].
#[derive(Clone, Debug)]
pub struct GenerateOptions {
    /// Output directory (created; must not already hold a dataset unless `overwrite`).
    pub out: PathBuf,
    /// Seed.
    pub seed: u64,
    /// Worker threads (`None`: rayon's default).
    pub workers: Option<usize>,
    /// Show a progress bar.
    pub progress: bool,
    /// Replace an existing dataset in `out`.
    pub overwrite: bool,
}

/// Check the output directory before anything is written.
pub fn check_output_dir(out: &Path, overwrite: bool) -> Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(Error::invalid(
            "out",
            format!("{} exists and is not a directory", out.display()),
        ));
    }
    if out.join("manifest.json").exists() && !overwrite {
        return Err(Error::invalid(
            "out",
            format!(
                "{} already holds a dataset (manifest.json); pass --overwrite to replace it",
                out.display()
            ),
        ));
    }
    Ok(())
}

/// Generate the whole dataset into `options.out`.
pub fn generate(generator: &Generator, options: &GenerateOptions) -> Result<GenerateSummary> {
    check_output_dir(&options.out, options.overwrite)?;
    if let Some(0) = options.workers {
        return Err(Error::invalid("workers", "must be >= 1"));
    }
    let started = std::time::Instant::now();
    let out = &options.out;
    let manifest_path = out.join("manifest.json");
    if manifest_path.exists() {
        std::fs::remove_file(&manifest_path)
            .map_err(|e| Error::file(&manifest_path, e.to_string()))?;
    }
    for sub in ["images", "targets", "depth"] {
        let d = out.join(sub);
        std::fs::create_dir_all(&d)
            .map_err(|e| Error::write(&d, format!("cannot create directory: {e}")))?;
    }
    let s = generator.settings();
    let bar = crate::progress::bar(
        options.progress,
        (s.configs * s.berries_per_config) as u64,
        "targets",
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.workers.unwrap_or(0))
        .build()
        .map_err(|e| Error::Numerical(format!("cannot start the worker pool: {e}")))?;
    let attempts = pool.install(|| {
        (0..s.configs)
            .into_par_iter()
            .map(|c| {
                let output = generator.config(options.seed, c)?;
                write_config(out, &output)?;
                bar.inc(output.records.len() as u64);
                Ok(output.attempts)
            })
            .collect::<Result<Vec<usize>>>()
    })?;
    bar.finish_and_clear();
    let manifest = generator.manifest(options.seed);
    dataset::write_json_atomic(&manifest_path, &manifest)?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let targets = s.configs * s.berries_per_config;
    Ok(GenerateSummary {
        out: out.clone(),
        configs: s.configs,
        targets,
        redrawn_configs: attempts.iter().filter(|a| **a > 1).count(),
        elapsed_s,
        targets_per_s: targets as f64 / elapsed_s.max(1e-9),
        warnings: split_warnings(s, &manifest.splits),
    })
}

/// A warning per empty validation or test split: `dpmp train` needs a
/// validation target, `dpmp eval --split test` a test one.
pub fn split_warnings(s: &SynthSettings, splits: &Splits) -> Vec<String> {
    let mut out = Vec::new();
    for (name, ids, fraction) in [
        ("val", &splits.val, s.split.val_fraction),
        ("test", &splits.test, s.split.test_fraction),
    ] {
        if ids.is_empty() {
            let least = (0.5 / fraction.max(1e-9)).ceil() as usize;
            out.push(format!(
                "the {name} split is empty: splits are by configuration and {} configurations x {fraction} rounds to none (and train keeps at least one); `dpmp train` needs a val target and `dpmp eval --split test` a test one: use --configs {} or more",
                s.configs,
                least.max(3)
            ));
        }
    }
    out
}

fn write_config(out: &Path, output: &ConfigOutput) -> Result<()> {
    for ((record, image), depth) in output
        .records
        .iter()
        .zip(&output.images)
        .zip(&output.depths)
    {
        dataset::write_png_atomic(&out.join(&record.image), image)?;
        if let (Some(path), Some(depth)) = (&record.depth, depth) {
            dataset::write_atomic(&out.join(path), &depth.encode_png()?)?;
        }
        dataset::write_json_atomic(&out.join(format!("targets/{}.json", record.id)), record)?;
    }
    Ok(())
}
