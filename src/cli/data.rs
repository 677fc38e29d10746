//! `dpmp data`: generate a synthetic dataset, print its statistics, or
//! render a preview of one plant configuration.

use crate::perception::{Camera, DepthImage};
use crate::plan::world::{sensed_cloud, TargetKeepOut};
use crate::plot::{scene_picture, ScenePicture};
use crate::promp::annotation::load_dir;
use crate::robot::Robot;
use crate::synth::dataset::{load_manifest, load_record, write_png_atomic, TargetRecord};
use crate::synth::generate::{check_output_dir, generate, GenerateOptions, Generator};
use crate::synth::settings::{RegionAnchor, SynthSettings};
use crate::synth::stats::{
    dataset_stats, default_basis, format_table, DatasetStats, TargetSummary,
};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// `dpmp data` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum DataCommand {
    /// Generate a synthetic dataset (images, per-target records, manifest).
    Generate(GenerateArgs),
    /// Print a dataset's statistics, optionally beside the real annotation data.
    Stats(StatsArgs),
    /// Render the images of one configuration to PNG files, and per target
    /// its true scene under the cloud sensed from its depth (no dataset).
    Preview(PreviewArgs),
    /// Write a trainable dataset from your own images, boxes, depth and
    /// demonstrations (a JSON manifest; see the README).
    Import(ImportArgs),
}

/// Flags of `dpmp data import`.
#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// The import manifest (JSON; paths in it are relative to it).
    #[arg(long)]
    pub manifest: PathBuf,
    /// Output dataset folder (must not exist unless --overwrite).
    #[arg(long)]
    pub out: PathBuf,
    /// Fraction of groups (plants) for validation.
    #[arg(long, default_value_t = 0.1)]
    pub val_fraction: f64,
    /// Fraction of groups for test.
    #[arg(long, default_value_t = 0.1)]
    pub test_fraction: f64,
    /// Seed of the split.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The ProMP basis.
    #[command(flatten)]
    pub promp: crate::cli::PrompArgs,
    /// Replace an existing dataset in --out.
    #[arg(long)]
    pub overwrite: bool,
    /// The robot of the demonstrations.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Flags of `dpmp data generate`.
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Plant configurations.
    #[arg(long)]
    pub configs: usize,
    /// Berries (targets) per configuration.
    #[arg(long)]
    pub berries_per_config: usize,
    /// Demonstrations per target.
    #[arg(long, default_value_t = 10)]
    pub demos: usize,
    /// Seed (the output is identical for a seed, whatever the worker count).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub workers: Option<usize>,
    /// JSON file overriding generator settings (any subset of the manifest's `settings`).
    #[arg(long)]
    pub settings: Option<PathBuf>,
    /// Target region `xmin,ymin,zmin,xmax,ymax,zmax` (m), instead of the real data's region.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub region: Option<Vec<f64>>,
    /// What `--region` bounds: `pre-grasp` (default: the demonstrations end
    /// in it, as the real ones do) or `berry` (the berry centres).
    #[arg(long, value_parser = parse_anchor)]
    pub region_anchor: Option<RegionAnchor>,
    /// Pre-grasp stop distance before the berry centre (m).
    #[arg(long)]
    pub standoff: Option<f64>,
    /// Objects (unripe berries on stems, leaflets) placed across each
    /// target's demonstrated path after its demonstrations, rendered and
    /// marked `"intruder": true` in its scene (0..=3).
    #[arg(long)]
    pub intruders: Option<usize>,
    /// Replace an existing dataset in `--out`.
    #[arg(long)]
    pub overwrite: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Flags of `dpmp data stats`.
#[derive(Debug, clap::Args)]
pub struct StatsArgs {
    /// Dataset directory.
    pub dir: PathBuf,
    /// Real annotation directory (J1..J7/K.json) to compare with.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// Flags of `dpmp data preview`.
#[derive(Debug, clap::Args)]
pub struct PreviewArgs {
    /// Output directory for `c<config>_b<berry>.png` and, per target, the
    /// picture of its true scene and the cloud `world: depth` senses from
    /// its depth image, `c<config>_b<berry>.world.png`.
    #[arg(long)]
    pub out: PathBuf,
    /// Berries in the configuration.
    #[arg(long, default_value_t = 5)]
    pub berries: usize,
    /// Configuration index (selects the random stream).
    #[arg(long, default_value_t = 0)]
    pub config: usize,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Objects (unripe berries on stems, leaflets) placed across each
    /// target's demonstrated path after its demonstrations, rendered and
    /// drawn as intruders in the world pictures (0..=3).
    #[arg(long, default_value_t = 0)]
    pub intruders: usize,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
}

/// `pre-grasp` or `berry`.
fn parse_anchor(text: &str) -> std::result::Result<RegionAnchor, String> {
    match text {
        "pre-grasp" => Ok(RegionAnchor::PreGrasp),
        "berry" => Ok(RegionAnchor::Berry),
        other => Err(format!("expected `pre-grasp` or `berry`, got `{other}`")),
    }
}

/// Run a `dpmp data` subcommand.
pub fn run(command: DataCommand) -> Result<()> {
    match command {
        DataCommand::Generate(a) => run_generate(a),
        DataCommand::Stats(a) => run_stats(a),
        DataCommand::Preview(a) => run_preview(a),
        DataCommand::Import(a) => run_import(a),
    }
}

fn run_import(a: ImportArgs) -> Result<()> {
    let promp = a.promp.config()?;
    let settings = crate::demos::ImportSettings {
        promp,
        val_fraction: a.val_fraction,
        test_fraction: a.test_fraction,
        seed: a.seed,
        overwrite: a.overwrite,
        progress: true,
    };
    let robot = a.robot.load()?;
    let summary = crate::demos::import(&a.manifest, &a.out, &robot, &settings)
        .map_err(super::as_flag_error)?;
    super::print_json(&summary)
}

/// Settings from the flags (and the optional settings file), validated.
pub fn settings_from_args(a: &GenerateArgs) -> Result<SynthSettings> {
    let mut s: SynthSettings = match &a.settings {
        Some(path) => super::read_json(path)?,
        None => SynthSettings::default(),
    };
    s.configs = a.configs;
    s.berries_per_config = a.berries_per_config;
    s.demos.demos = a.demos;
    if let Some(r) = &a.region {
        crate::error::ensure_len("--region", r, 6)?;
        crate::error::ensure_finite("--region", r)?;
        s.plant.region.min = [r[0], r[1], r[2]];
        s.plant.region.max = [r[3], r[4], r[5]];
    }
    if let Some(anchor) = a.region_anchor {
        s.plant.region_anchor = anchor;
    }
    if let Some(d) = a.standoff {
        s.demos.standoff_m = d;
    }
    if let Some(n) = a.intruders {
        s.intruders = n;
    }
    s.validate()?;
    Ok(s)
}

fn run_generate(a: GenerateArgs) -> Result<()> {
    let settings = settings_from_args(&a)?;
    if a.workers == Some(0) {
        return Err(Error::invalid("workers", "must be >= 1"));
    }
    check_output_dir(&a.out, a.overwrite)?;
    let generator = Generator::new(settings, a.robot.load()?)?;
    let summary = generate(
        &generator,
        &GenerateOptions {
            out: a.out.clone(),
            seed: a.seed,
            workers: a.workers,
            progress: !a.quiet,
            overwrite: a.overwrite,
        },
    )?;
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    super::print_json(&summary)
}

/// Statistics of every target in a dataset directory.
pub fn stats_of_dataset(dir: &Path, robot: &Robot) -> Result<DatasetStats> {
    let manifest = load_manifest(dir)?;
    let summaries = manifest
        .targets
        .iter()
        .map(|e| load_record(dir, e).and_then(|r| TargetSummary::from_record(&r)))
        .collect::<Result<Vec<_>>>()?;
    Ok(dataset_stats(&summaries, &default_basis()?, &robot.home()))
}

/// Statistics of the real annotation data (`K.json` files, configuration `K / 5`).
pub fn stats_of_annotations(dir: &Path, robot: &Robot) -> Result<DatasetStats> {
    let basis = default_basis()?;
    let mut summaries = Vec::new();
    while dir
        .join("J1")
        .join(format!("{}.json", summaries.len()))
        .exists()
    {
        let k = summaries.len();
        let prior = load_dir(dir, k)?;
        summaries.push(TargetSummary::from_prior(
            k / 5,
            prior.distribution,
            robot,
            &basis,
        ));
    }
    if summaries.is_empty() {
        return Err(Error::file(
            dir,
            "no annotation files J1/0.json, J1/1.json, ... found",
        ));
    }
    Ok(dataset_stats(&summaries, &basis, &robot.home()))
}

fn run_stats(a: StatsArgs) -> Result<()> {
    let robot = a.robot.load()?;
    let synthetic = stats_of_dataset(&a.dir, &robot)?;
    let reference = a
        .reference
        .as_deref()
        .map(|d| stats_of_annotations(d, &robot))
        .transpose()?;
    if a.json {
        return super::print_json(
            &serde_json::json!({ "synthetic": synthetic, "reference": reference }),
        );
    }
    print!("{}", format_table(&synthetic, reference.as_ref()));
    Ok(())
}

fn run_preview(a: PreviewArgs) -> Result<()> {
    let mut settings = SynthSettings::new(1, a.berries);
    settings.intruders = a.intruders;
    let generator = Generator::new(settings, a.robot.load()?)?;
    let output = generator.config(a.seed, a.config)?;
    std::fs::create_dir_all(&a.out).map_err(|e| Error::write(&a.out, e.to_string()))?;
    let targets = output
        .records
        .iter()
        .zip(&output.images)
        .zip(&output.depths);
    for ((record, image), depth) in targets {
        let path = a.out.join(format!("{}.png", record.id));
        write_png_atomic(&path, image)?;
        crate::cli::write_stdout(&path.display().to_string())?;
        let Some(depth) = depth else {
            continue;
        };
        // The target located as a plan with this depth image locates it.
        let camera = generator.camera();
        let keep = match TargetKeepOut::locate(depth, record.bbox, camera, "depth") {
            Ok(keep) => keep,
            Err(e) => {
                // A plan would refuse this target too; the other pictures stand.
                eprintln!("warning: {}: no world picture: {e}", record.id);
                continue;
            }
        };
        let path = a.out.join(format!("{}.world.png", record.id));
        world_picture(&path, record, depth, camera, &keep)?;
        crate::cli::write_stdout(&path.display().to_string())?;
    }
    Ok(())
}

/// The picture of `record`'s true scene (intruders marked) under the cloud
/// a plan with `world: "depth"` senses from `depth` through `camera` (the
/// generator's, at home), with the located target `keep` kept out.
fn world_picture(
    path: &Path,
    record: &TargetRecord,
    depth: &DepthImage,
    camera: &Camera,
    keep: &TargetKeepOut,
) -> Result<()> {
    let cloud = sensed_cloud(depth, camera, keep);
    let obstacles = record.scene.obstacles();
    let intruder: Vec<bool> = record.scene.obstacles.iter().map(|o| o.intruder).collect();
    let picture = ScenePicture {
        title: format!(
            "{}: true scene and the cloud sensed from depth (world: depth)",
            record.id
        ),
        scene_label: "true scene".to_string(),
        obstacles: &obstacles,
        intruder: &intruder,
        cloud: &cloud.points,
        tcp_path: None,
        target: Some(keep.center),
    };
    scene_picture(path, &picture)
}
