//! Recorded demonstrations in: the way a lab's own data reaches dpmp.
//!
//! ```text
//! a.csv, b.json, … ──► file: time-stamped joint positions, in the robot's joint order
//!                 ──► fit: phase-normalised, resampled, ProMP weights + residual per demonstration
//!                 ──► a WeightDistribution (the prior)
//!                 ──► write: annotation folder J1..Jn/K.json, prior.json (optimise request), fit.json
//! ```
//!
//! A demonstration is a table with a `time` column in seconds (strictly
//! increasing, any sampling rate, any length) and one column per joint
//! named as in the robot's URDF: what a `joint_states` recording exported
//! to CSV looks like. [`file`] reads CSV and JSON and validates every cell;
//! [`fit`] maps each recording onto the ProMP phase `[0, 1]` and fits its
//! weights, so recordings of one motion at 1 kHz and at 30 Hz give the same
//! weights. [`import`] turns a manifest of images, boxes, depth and
//! demonstrations into a trainable dataset (`dpmp data import`).

pub mod file;
pub mod fit;
pub mod import;
pub mod task;
pub mod write;

pub use file::{
    demonstration_paths, read_demonstration, read_demonstration_with, Demonstration, ReadOptions,
    TimeUnit,
};
pub use fit::{fit_demonstration, fit_prior, DemoFit, PriorFit};
pub use import::{import, ImportManifest, ImportSettings, ImportSummary};
pub use write::{write_prior, FitReport};
