//! Synthetic strawberry scenes, the gripper-camera renderer and the
//! demonstration generator that together produce training and benchmark
//! datasets (the paper's 250 real images are not available).
//!
//! - [`settings`] — every generator setting, validated.
//! - [`plant`] — the plant sampler (berries, stems, leaves, tray).
//! - [`obstacles`] — a plant as request-schema obstacles.
//! - [`camera`] — the pinhole camera on the gripper (from [`crate::perception`]).
//! - [`render`] — rasteriser, shading, textures, noise, the target box.
//! - [`demos`] — IK-based, minimum-jerk, collision-checked demonstrations.
//! - [`intruders`] — objects placed across a target's path after its demonstrations.
//! - [`dataset`] — the on-disk format (`dpmp-dataset/4`, with depth and task-space weights; versions 1 and 2 still load) and its loaders.
//! - [`generate`] — the deterministic parallel driver.
//! - [`stats`] — dataset statistics beside the real annotation data.
//!
//! ```no_run
//! use dpmp::synth::{generate::{generate, GenerateOptions, Generator}, settings::SynthSettings};
//! let g = Generator::new(SynthSettings::new(50, 5), dpmp::robot::Robot::panda()?)?;
//! let opts = GenerateOptions { out: "data/synth".into(), seed: 7, workers: None, progress: true, overwrite: false };
//! let summary = generate(&g, &opts)?;
//! println!("{} targets at {:.1}/s", summary.targets, summary.targets_per_s);
//! # Ok::<(), dpmp::Error>(())
//! ```

/// The camera lives in [`crate::perception`]; this path stays for callers.
pub use crate::perception::camera;
pub mod dataset;
pub mod demos;
pub mod generate;
pub mod intruders;
pub mod obstacles;
pub mod plant;
pub mod render;
pub mod settings;
pub mod stats;
