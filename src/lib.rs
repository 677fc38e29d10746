//! # dPMP — Deep Probabilistic Motion Planning
//!
//! A camera image of a strawberry plant, with the target berry marked, goes
//! through the dPMP network and becomes a Gaussian distribution over ProMP
//! weights of a 7-joint Franka Panda trajectory. A sequence of convex QPs
//! (Clarabel) then finds the weights closest to that Gaussian in Mahalanobis
//! distance that keep every joint within its limits and every link clear of
//! the berry-cluster geometry (parry3d).
//!
//! ```text
//! image + target box ──► net::preprocess ──► net (AE | VAE | cVAE | Direct)
//!                    ──► prior N(mu, Sigma) over 7 x n_basis ProMP weights   (promp)
//! prior + scene + limits ──► optim::problem (whitened QP data)               (robot, scene)
//!                    ──► optim::scp: linearise clearances, solve QP (Clarabel),
//!                        accept / shrink trust region, until converged
//!                    ──► optim::verify densely ──► trajectory + report
//! ```
//!
//! Each arrow is a plain function over plain data; the HTTP layer
//! ([`service`]), the CLI ([`cli`]) and the benchmark runner ([`bench`]) are
//! thin shells over the same library calls.
//!
//! ## Modules, in data-flow order
//!
//! **The live path** — what a request runs through (`/v1/plan`,
//! `/v1/optimize`, `dpmp plan`); none of it imports an offline tool
//! (`tests/integration/module_graph.rs` checks):
//!
//! - [`promp`] — basis, fitting, weight distributions, conditioning, the
//!   paper's covariance codec and annotation import.
//! - [`geometry`] — the `[x, y, z, w]` quaternion convention and segment
//!   distances, shared by the robot and the scene.
//! - [`robot`] — URDF loading, kinematics, Jacobians, inverse kinematics,
//!   link collision shapes.
//! - [`scene`] — obstacles and signed-distance queries against the robot.
//! - [`perception`] — the gripper camera model, aligned depth images, and
//!   the 3-D target position behind a box.
//! - [`net`] — the dPMP network in candle and its inference API.
//! - [`task_space`] — the TCP trajectory as ProMP weights (the paper's
//!   second space), and a task-space model's distribution as the joint-space
//!   prior the optimiser takes (IK-tracked draws).
//! - [`plan`] — one validated [`plan::PlanRequest`] and the image (+ depth)
//!   → prior → goal → optimiser pipeline behind `/v1/plan` and `dpmp plan`.
//! - [`optim`] — the Mahalanobis-closest trajectory optimiser: a typed prior
//!   beside an [`optim::Task`].
//! - [`moveit`] — MoveIt's `PlanningScene` read into the request schema's
//!   obstacles.
//! - [`service`] — the axum HTTP service, a shell over [`plan`] and [`optim`].
//! - `ros2` (cargo feature `ros2`) — the same planning as a native ROS 2
//!   node: camera, joint-state and target topics in, a `JointTrajectory` and
//!   diagnostics out.
//!
//! **The offline tools** — data, training, benchmarks, pictures:
//!
//! - [`demos`] — recorded demonstrations in (CSV/JSON joint recordings →
//!   phase-normalised weight fits → a prior).
//! - [`synth`] — synthetic plant scenes, camera renderer, demonstrations.
//! - [`train`] — training and evaluation of the network.
//! - [`bench`] — the offline benchmark runner.
//! - [`plot`] — shared plotting helpers (plotters).
//! - [`fixtures`] — generated typical optimiser requests for benchmarks,
//!   tests and examples.
//!
//! **Shared plumbing:** [`cli`] (the `dpmp` command line, a shell over
//! both), [`error`], [`fsio`] (whole-or-nothing file writes), [`strict_json`]
//! (duplicate object keys refused in every JSON input), [`progress`]
//! (progress bars on stderr for long work).
//!
//! ## Conventions
//!
//! Weights are joint-major: `w[j * n_basis + i]` is basis `i` of joint `j`.
//! Angles in rad, lengths in m, time in s, quaternions `[x, y, z, w]`, all
//! frames in the robot base frame. Trajectories are `T x n_joints` matrices
//! (rows are time samples).

pub mod bench;
pub mod cli;
pub mod demos;
pub mod error;
pub mod fixtures;
pub mod fsio;
pub mod geometry;
pub mod moveit;
pub mod net;
pub mod optim;
pub mod perception;
pub mod plan;
pub mod plot;
pub mod progress;
pub mod promp;
pub mod robot;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod scene;
pub mod service;
pub mod strict_json;
pub mod synth;
pub mod task_space;
pub mod train;

pub use error::{Error, Result};
