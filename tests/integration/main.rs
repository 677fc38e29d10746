//! The integration tests, as one test binary: one link of the library
//! instead of one per file, which keeps the build small and fast. Each
//! module is the tests of one capability; `common` is their shared
//! support.

mod common;

mod annotation_reference;
mod bench_hard;
mod bench_model;
mod bench_problems;
mod bench_runner;
mod bench_typical_labels;
mod cli_optimize;
mod cli_plan;
mod cli_prior;
mod cli_prior_fit;
mod data_import;
mod first_hour;
mod geometry_convex_gap;
mod http_abuse;
mod http_api;
mod http_contract;
mod http_plan;
mod http_robustness;
mod module_graph;
mod net_cli;
mod net_model;
mod net_train;
mod optim_closed_form;
mod optim_continuous;
mod optim_determinism;
mod optim_dual_active_set;
mod optim_exactness;
mod optim_finer_basis;
mod optim_franka;
mod optim_global;
mod optim_properties;
mod optim_requests;
mod optim_screening;
mod optim_smooth_prior;
mod optim_task;
mod plan_interfaces;
mod plan_moveit;
mod plan_world;
mod python_client;
mod robot_cli;
mod robot_collision_mesh;
mod robot_hull_query;
mod robot_ik;
mod robot_kinematics;
mod robot_urdf_mesh;
#[cfg(feature = "ros2")]
mod ros2_cdr;
#[cfg(feature = "ros2")]
mod ros2_node;
mod scene_clearance;
mod scene_obstacles;
mod scene_points;
mod synth_dataset;
mod synth_demos;
mod task_space;
