//! The Python client (`clients/python/dpmp_client.py`) against the real
//! server on an ephemeral port, with the shipped model: `optimize` on a
//! typical request, `plan` from a generated plant's image and depth, and a
//! refused request raising `DpmpError` with the server's code and field.
//! Skipped, with a message, only when no `python3` is on the machine.

use crate::common::http::start_with_default_model;
use dpmp::robot::Robot;
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use serde_json::Value;
use std::io::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};

/// Runs the client against the server and prints what it saw as JSON.
const CHECK: &str = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
from dpmp_client import Client, DpmpError, points_obstacle
url, request_path, image, depth, box = sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5], json.loads(sys.argv[6])
scene = json.loads(sys.argv[7])
dpmp = Client(url)
out = {"ready": dpmp.ready(), "robot_joints": len(dpmp.robot()["joint_names"])}
with open(request_path) as f:
    answer = dpmp.optimize(json.load(f))
out["optimize_status"] = answer["status"]
out["optimize_points"] = len(answer["trajectory"]["points"])
plan = dpmp.plan(image, box, depth_path=depth, mask_applied=True, obstacles=scene, clearance_m=0.02)
out["plan_status"] = plan["status"]
out["plan_target_source"] = plan["target"]["source"]
out["plan_final"] = plan["trajectory"]["points"][-1]["positions"]
shelf = points_obstacle("shelf", [[0.9, 0.3, 0.2], [0.9, 0.32, 0.2], [0.92, 0.3, 0.2]], 0.01)
sensed = dpmp.plan(image, box, depth_path=depth, mask_applied=True, world="depth",
                   obstacles=[shelf], clearance_m=0.015)
out["world_points"] = sensed["world"]["points"]
out["world_status"] = sensed["status"]
try:
    dpmp.plan(image, [600, 400, 700, 500], depth_path=depth)
    out["refused"] = None
except DpmpError as e:
    out["refused"] = {"status": e.status, "code": e.code, "field": e.field}
print(json.dumps(out))
"#;

fn python3() -> Option<&'static str> {
    Command::new("python3")
        .arg("--version")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|_| "python3")
}

#[test]
fn the_python_client_optimizes_plans_and_raises_the_servers_errors() {
    let Some(python) = python3() else {
        eprintln!("SKIPPED: no python3 on this machine; the Python client was not run");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let robot = Robot::panda().unwrap();
    let request = dpmp::fixtures::typical_request(&robot, 0, &Default::default()).unwrap();
    let request_path = dir.path().join("request.json");
    std::fs::write(&request_path, serde_json::to_string(&request).unwrap()).unwrap();

    let generator = Generator::new(SynthSettings::new(1, 1), robot.clone()).unwrap();
    let plant = generator.config(21, 0).unwrap();
    let image = dir.path().join("plant.png");
    plant.images[0].save(&image).unwrap();
    let depth = dir.path().join("depth.png");
    let depth_png = plant.depths[0].as_ref().unwrap().encode_png().unwrap();
    std::fs::write(&depth, depth_png).unwrap();
    let record = &plant.records[0];

    let server = start_with_default_model();
    let clients = Path::new(env!("CARGO_MANIFEST_DIR")).join("clients/python");
    let mut child = Command::new(python)
        .arg("-")
        .args([
            clients.display().to_string(),
            server.url(""),
            request_path.display().to_string(),
            image.display().to_string(),
            depth.display().to_string(),
            serde_json::to_string(&record.bbox).unwrap(),
            serde_json::to_string(&record.scene.obstacles()).unwrap(),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(CHECK.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(seen["ready"], true);
    assert_eq!(seen["robot_joints"], 7);
    assert_eq!(seen["optimize_status"], "optimal", "{seen}");
    assert_eq!(seen["optimize_points"], 150);
    assert_eq!(seen["plan_target_source"], "depth");
    assert_eq!(seen["plan_status"], "optimal", "{seen}");
    // A compact cloud from the client and the depth world beside it.
    assert!(seen["world_points"].as_u64().unwrap() > 200, "{seen}");
    assert!(seen["world_status"].is_string(), "{seen}");
    let last: Vec<f64> = serde_json::from_value(seen["plan_final"].clone()).unwrap();
    let tcp = robot.tcp_pose(&last).translation.vector;
    let demos = nalgebra::Vector3::from(record.final_tcp.position);
    assert!((tcp - demos).norm() < 0.015, "{}", (tcp - demos).norm());
    // A box outside the image: 422 naming the box.
    assert_eq!(seen["refused"]["status"], 422);
    assert_eq!(seen["refused"]["code"], "invalid_input");
    assert!(
        seen["refused"]["field"]
            .as_str()
            .unwrap()
            .starts_with("target_box"),
        "{seen}"
    );
    server.shutdown().unwrap();
}

/// A service that is not there is a `DpmpError` with code `unreachable`
/// naming the URL, not urllib's own exception.
#[test]
fn the_python_client_says_when_the_service_cannot_be_reached() {
    let Some(python) = python3() else {
        eprintln!("SKIPPED: no python3 on this machine; the Python client was not run");
        return;
    };
    // A port nothing listens on: bound, then closed.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let clients = Path::new(env!("CARGO_MANIFEST_DIR")).join("clients/python");
    let script = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
from dpmp_client import Client, DpmpError
try:
    Client(sys.argv[2]).robot()
    print(json.dumps({"raised": None}))
except DpmpError as e:
    print(json.dumps({"raised": "DpmpError", "status": e.status, "code": e.code,
                      "message": e.message, "cause": type(e.__cause__).__name__}))
"#;
    let out = Command::new(python)
        .args([
            "-c",
            script,
            &clients.display().to_string(),
            &format!("http://127.0.0.1:{port}"),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(seen["raised"], "DpmpError", "{seen}");
    assert_eq!(
        (seen["status"].clone(), seen["code"].as_str()),
        (Value::Null, Some("unreachable"))
    );
    let message = seen["message"].as_str().unwrap();
    assert!(
        message.contains(&format!("127.0.0.1:{port}")) && message.contains("refused"),
        "{message}"
    );
    assert_eq!(seen["cause"], "URLError");
}
