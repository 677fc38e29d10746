//! `dpmp optimize` end to end: JSON out, plot file, exit codes.

use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::robot::Robot;

use crate::common::cli::{arg, dpmp, dpmp_ok, stderr};

fn write_request(
    dir: &std::path::Path,
    mutate: impl Fn(&mut serde_json::Value),
) -> std::path::PathBuf {
    let robot = Robot::panda().unwrap();
    let settings = ExampleSettings {
        n_obstacles: 3,
        ..Default::default()
    };
    let req = typical_request(&robot, 11, &settings).unwrap();
    let mut json = serde_json::to_value(&req).unwrap();
    mutate(&mut json);
    let path = dir.join("request.json");
    std::fs::write(&path, serde_json::to_string(&json).unwrap()).unwrap();
    path
}

#[test]
fn optimize_prints_the_response_and_draws_the_plot() {
    let dir = tempfile::tempdir().unwrap();
    let req = write_request(dir.path(), |_| {});
    let plot = dir.path().join("joints.png");
    let out = dpmp_ok(&["optimize", "--request", arg(&req), "--plot", arg(&plot)]);
    let resp: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(["optimal", "infeasible", "max_iterations"].contains(&resp["status"].as_str().unwrap()));
    assert_eq!(resp["weights"].as_array().unwrap().len(), 56);
    assert_eq!(resp["trajectory"]["points"].as_array().unwrap().len(), 150);
    assert_eq!(resp["report"]["verified_samples"], 600);
    assert!(std::fs::metadata(&plot).unwrap().len() > 10_000);
}

#[test]
fn invalid_input_exits_2_and_names_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let req = write_request(dir.path(), |j| j["clearance_m"] = serde_json::json!(-1.0));
    let out = dpmp(&["optimize", "--request", arg(&req)]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains("clearance_m") && err.contains("request.json"),
        "{err}"
    );
    let req = write_request(dir.path(), |j| j["unknown_field"] = serde_json::json!(1));
    let out = dpmp(&["optimize", "--request", arg(&req)]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("unknown_field"));
    let out = dpmp(&["optimize", "--request", arg(&req), "--plot", "x.gif"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn a_reader_that_closes_the_pipe_early_is_not_a_panic() {
    // `dpmp serve --print-typical-request 0 | head -c 10`: the JSON is far
    // longer than what the reader takes before closing.
    use std::io::Read;
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_dpmp"))
        .args(["serve", "--print-typical-request", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let mut first = [0u8; 10];
    stdout.read_exact(&mut first).unwrap();
    drop(stdout);
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(out.status.success(), "{stderr}");
}
