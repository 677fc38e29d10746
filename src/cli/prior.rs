//! `dpmp prior`: fit priors to recorded demonstrations; inspect, plot and
//! create priors in the paper's annotation format.

use crate::demos;
use crate::fixtures::demonstrations as example;
use crate::promp::distribution::matrix_rows;
use crate::promp::{annotation, Basis, Prior, PrompConfig};
use crate::{Error, Result};
use clap::{Args, Subcommand, ValueEnum};
use nalgebra::DMatrix;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// `dpmp prior` subcommands.
#[derive(Debug, Subcommand)]
pub enum PriorCommand {
    /// Fit a prior to recorded demonstrations (CSV or JSON: a `time` column
    /// in seconds and one column per joint, named as in the URDF). Writes
    /// the annotation folder (J1..Jn/K.json), prior.json (an optimise
    /// request with the prior) and fit.json (residual per demonstration).
    Fit(FitArgs),
    /// Print the mean and per-time standard deviation of an annotated prior.
    Inspect(InspectArgs),
    /// Plot per-joint mean trajectories with ±2σ bands.
    Plot(PlotArgs),
    /// Write an example prior (synthetic joint-space demonstrations shaped
    /// like the paper's) in the annotation format.
    Example(ExampleArgs),
}

/// Arguments of `dpmp prior fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// Demonstration files, or directories of them (.csv, .json).
    #[arg(long, num_args = 1.., required = true, value_name = "FILE|DIR")]
    pub demos: Vec<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Target index K of the annotation files.
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// The robot the demonstrations were recorded on.
    #[command(flatten)]
    pub robot: crate::cli::RobotArgs,
    /// The ProMP basis.
    #[command(flatten)]
    pub promp: crate::cli::PrompArgs,
    /// Also plot the prior (mean ±2σ per joint) into this .png or .svg.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Unit of the `time` column: auto (the first of s, ms, us, ns giving
    /// a 0.1-600 s recording), s, ms, us or ns.
    #[arg(long, default_value = "auto")]
    pub time_unit: demos::TimeUnit,
    /// Joints recorded under other column names, `JOINT=COLUMN,...`
    /// (e.g. `panda_joint1=position_0,panda_joint2=position_1`).
    #[arg(long)]
    pub joint_map: Option<String>,
}

/// Where a prior comes from.
#[derive(Debug, Args)]
pub struct Source {
    /// Annotation folder with J1..J7/K.json.
    #[arg(long)]
    pub annotation: PathBuf,
    /// Target index K.
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// Number of phase samples T.
    #[arg(long, default_value_t = 150)]
    pub n_samples: usize,
    /// Basis width h.
    #[arg(long, default_value_t = 0.07)]
    pub width: f64,
    /// Trajectory duration in seconds (time axis of plots).
    #[arg(long, default_value_t = 4.0)]
    pub duration: f64,
}

/// Output formats of `dpmp prior inspect`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum OutputFormat {
    /// Full JSON.
    Json,
    /// Short human-readable summary.
    Table,
}

/// Arguments of `dpmp prior inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The prior to inspect.
    #[command(flatten)]
    pub source: Source,
    /// Output format.
    #[arg(long, value_enum, default_value_t = OutputFormat::Json)]
    pub format: OutputFormat,
}

/// Arguments of `dpmp prior plot`.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// The prior to plot.
    #[command(flatten)]
    pub source: Source,
    /// Output image (.png or .svg).
    #[arg(long)]
    pub out: PathBuf,
    /// The robot whose joint names and limits label the panels.
    #[command(flatten)]
    pub robot: crate::cli::RobotArgs,
}

/// Arguments of `dpmp prior example`.
#[derive(Debug, Args)]
pub struct ExampleArgs {
    /// Output annotation folder (J1..J7 are created in it).
    #[arg(long)]
    pub out: PathBuf,
    /// Target index K of the written files.
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// Number of demonstrations.
    #[arg(long, default_value_t = 10)]
    pub demos: usize,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// The JSON printed by `dpmp prior inspect`.
#[derive(Debug, Serialize)]
pub struct InspectReport {
    /// `T x 7` mean joint positions (rows = time).
    pub mean: Vec<Vec<f64>>,
    /// `T x 7` per-time standard deviations.
    pub std: Vec<Vec<f64>>,
    /// Smallest eigenvalue of the joint covariances before repair.
    pub min_eigenvalue: f64,
    /// Whether any covariance was repaired.
    pub repaired: bool,
    /// Repair notes.
    pub warnings: Vec<String>,
}

/// Run a `dpmp prior` subcommand.
pub fn run(command: PriorCommand) -> Result<()> {
    match command {
        PriorCommand::Fit(args) => fit(&args),
        PriorCommand::Inspect(args) => inspect(&args),
        PriorCommand::Plot(args) => plot(&args),
        PriorCommand::Example(args) => write_example(&args),
    }
}

fn fit(args: &FitArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        crate::plot::format_of(plot, "--plot")?;
    }
    let config = args.promp.config()?;
    let basis = Basis::new(&config).map_err(crate::cli::as_flag_error)?;
    let robot = args.robot.load()?;
    let paths = demos::demonstration_paths(&args.demos)?;
    let options = demos::ReadOptions {
        time_unit: args.time_unit,
        joint_columns: match &args.joint_map {
            Some(text) => {
                demos::ReadOptions::parse_joint_map("--joint-map", text, robot.joint_names())?
            }
            None => Vec::new(),
        },
    };
    let progress = crate::progress::bar(true, paths.len() as u64, "demonstrations read");
    let recordings = paths
        .iter()
        .map(|p| {
            progress.inc(1);
            demos::read_demonstration_with(p, robot.joint_names(), &options)
        })
        .collect::<Result<Vec<_>>>()?;
    progress.finish_and_clear();
    let fit = demos::fit_prior(&basis, &robot, &recordings)?;
    let report = demos::write_prior(&args.out, args.index, &fit, &config, &robot)?;
    if let Some(plot) = &args.plot {
        let times: Vec<f64> = basis
            .phases()
            .iter()
            .map(|z| z * report.duration_s)
            .collect();
        let demo = plotters::style::RGBColor(120, 120, 120);
        let mut series: Vec<crate::plot::JointSeries> = fit
            .weights
            .iter()
            .enumerate()
            .map(|(k, w)| {
                let label = if k == 0 {
                    "demonstrations (fitted)"
                } else {
                    ""
                };
                let q = crate::promp::trajectory_from_weights(&basis, w.as_slice(), robot.dof());
                crate::plot::JointSeries::line(label.into(), demo, q, 1)
            })
            .collect();
        series.push(prior_series(
            format!("prior of {} demonstrations, mean ± 2σ", fit.demos.len()),
            &fit.distribution,
            &basis,
        ));
        let title = format!("ProMP prior fitted to {}", args.out.display());
        let limits = joint_limits(&robot);
        crate::plot::joint_panels(
            plot,
            &title,
            &times,
            &series,
            robot.joint_names(),
            Some(&limits),
        )?;
    }
    crate::cli::print_json(&report)
}

/// The prior's mean with its ±2σ band, in the one colour every prior plot uses.
fn prior_series(
    label: String,
    distribution: &crate::promp::WeightDistribution,
    basis: &Basis,
) -> crate::plot::JointSeries {
    crate::plot::JointSeries::band(
        label,
        plotters::style::RGBColor(200, 30, 30),
        distribution.trajectory_mean(basis),
        distribution.trajectory_std(basis, 0.0),
        2.0,
    )
}

/// `(lower, upper)` of every joint of `robot`.
fn joint_limits(robot: &crate::robot::Robot) -> Vec<(f64, f64)> {
    robot.limits().iter().map(|l| (l.lower, l.upper)).collect()
}

fn load(source: &Source) -> Result<(Prior, Basis)> {
    if !source.duration.is_finite() || source.duration <= 0.0 {
        return Err(Error::invalid(
            "--duration",
            format!(
                "must be a positive number of seconds, got {}",
                source.duration
            ),
        ));
    }
    let flags = PrompConfig {
        width: source.width,
        n_samples: source.n_samples,
        ..Default::default()
    };
    flags.validate().map_err(crate::cli::as_flag_error)?;
    let prior = annotation::load_dir(&source.annotation, source.index)?;
    let config = PrompConfig {
        n_basis: prior.distribution.n_basis,
        width: source.width,
        n_samples: source.n_samples,
    };
    let basis = Basis::new(&config).map_err(crate::cli::as_flag_error)?;
    Ok((prior, basis))
}

fn inspect(args: &InspectArgs) -> Result<()> {
    let (prior, basis) = load(&args.source)?;
    let mean = prior.distribution.trajectory_mean(&basis);
    let std = prior.distribution.trajectory_std(&basis, 0.0);
    match args.format {
        OutputFormat::Json => crate::cli::print_json(&InspectReport {
            mean: matrix_rows(&mean),
            std: matrix_rows(&std),
            min_eigenvalue: prior.min_eigenvalue,
            repaired: prior.repaired,
            warnings: prior.warnings,
        }),
        OutputFormat::Table => {
            print!("{}", table(&args.source, &prior, &mean, &std));
            Ok(())
        }
    }
}

/// Human summary: start/end mean and std per joint, repair status.
fn table(source: &Source, prior: &Prior, mean: &DMatrix<f64>, std: &DMatrix<f64>) -> String {
    let last = mean.nrows() - 1;
    let mut out = format!(
        "prior {} #{}: {} joints x {} basis, T = {}\n",
        source.annotation.display(),
        source.index,
        prior.distribution.n_joints,
        prior.distribution.n_basis,
        mean.nrows()
    );
    out += "joint   start [rad]   final [rad]   final std   max std\n";
    for j in 0..mean.ncols() {
        let max_std = std.column(j).max();
        out += &format!(
            "J{:<5} {:>11.4} {:>13.4} {:>11.4} {:>9.4}\n",
            j + 1,
            mean[(0, j)],
            mean[(last, j)],
            std[(last, j)],
            max_std
        );
    }
    out += &format!(
        "min eigenvalue {:.3e}; repaired: {}\n",
        prior.min_eigenvalue,
        if prior.repaired { "yes" } else { "no" }
    );
    for w in &prior.warnings {
        out += &format!("warning: {w}\n");
    }
    out
}

fn plot(args: &PlotArgs) -> Result<()> {
    crate::plot::format_of(&args.out, "--out")?;
    let (prior, basis) = load(&args.source)?;
    let times: Vec<f64> = basis
        .phases()
        .iter()
        .map(|z| z * args.source.duration)
        .collect();
    let series = prior_series("prior mean ± 2σ".into(), &prior.distribution, &basis);
    let title = format!(
        "ProMP prior {} #{}",
        args.source.annotation.display(),
        args.source.index
    );
    let robot = args.robot.load()?;
    // The robot's joint names and limits when the prior is for its joints.
    let (names, limits): (Vec<String>, Option<Vec<(f64, f64)>>) =
        if robot.dof() == prior.distribution.n_joints {
            (robot.joint_names().to_vec(), Some(joint_limits(&robot)))
        } else {
            let names = (1..=prior.distribution.n_joints)
                .map(|j| format!("joint {j}"))
                .collect();
            (names, None)
        };
    crate::plot::joint_panels(
        &args.out,
        &title,
        &times,
        &[series],
        &names,
        limits.as_deref(),
    )?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

fn write_example(args: &ExampleArgs) -> Result<()> {
    if args.demos < 2 {
        return Err(Error::invalid(
            "--demos",
            format!("need at least 2 demonstrations, got {}", args.demos),
        ));
    }
    let basis = Basis::new(&PrompConfig::default())?;
    let dist = example::example_distribution(&basis, args.demos, args.seed)?;
    let joints = annotation::joints_from_distribution(&dist)?;
    annotation::write_dir(&args.out, args.index, &joints)?;
    eprintln!(
        "wrote {}",
        Path::new(&args.out)
            .join("J1..J7")
            .join(format!("{}.json", args.index))
            .display()
    );
    Ok(())
}
