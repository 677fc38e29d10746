//! What a new user hits in the first hour, each case a regression test:
//! the shipped model found from any working folder, `--no-model` said
//! explicitly, reports never written into a shipped model, empty splits
//! refused before training, numeric lists in their documented comma form,
//! nanosecond timestamps, renamed joint columns, and exit code 2 for every
//! invalid input.

use crate::common::cli::{dpmp, stderr};
use crate::common::process::{exit_within, serve_process_in, signal};
use serde_json::Value;
use std::time::Duration;

/// `/readyz` of a `dpmp serve` started from `dir` with `flags`.
fn readyz_of_server_in(dir: &std::path::Path, flags: &[&str]) -> (u16, Value) {
    let (mut child, addr) = serve_process_in(dir, flags);
    let answer = reqwest::blocking::get(format!("http://{addr}/readyz")).unwrap();
    let status = answer.status().as_u16();
    let body: Value = answer.json().unwrap();
    signal(&child, "TERM");
    assert_eq!(exit_within(&mut child, Duration::from_secs(30)), Some(0));
    (status, body)
}

#[cfg(unix)]
#[test]
fn serve_from_another_folder_finds_the_shipped_model() {
    let elsewhere = tempfile::tempdir().unwrap();
    let (status, body) = readyz_of_server_in(elsewhere.path(), &[]);
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["model"]["loaded"], true, "{body}");
    assert_eq!(body["model"]["source"], "shipped", "{body}");
    assert!(body["model"]["name"]
        .as_str()
        .is_some_and(|n| !n.is_empty()));
}

#[cfg(unix)]
#[test]
fn serve_without_a_model_only_when_asked_and_says_so() {
    let elsewhere = tempfile::tempdir().unwrap();
    let (status, body) = readyz_of_server_in(elsewhere.path(), &["--no-model"]);
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["model"]["loaded"], false, "{body}");
    assert!(body["model"]["source"].is_null(), "{body}");
    // A configured model that is missing stops the start, naming it.
    let missing = elsewhere.path().join("no-such-model");
    let o = dpmp(&["serve", "--model", missing.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no-such-model"), "{}", stderr(&o));
}

/// A one-plant dataset in `dir/data`, `extra` flags appended; its stderr.
fn generate(dir: &std::path::Path, configs: &str, extra: &[&str]) -> std::process::Output {
    let data = dir.join("data");
    let mut args = vec![
        "data",
        "generate",
        "--out",
        data.to_str().unwrap(),
        "--configs",
        configs,
        "--berries-per-config",
        "1",
        "--demos",
        "2",
        "--seed",
        "5",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    dpmp(&args)
}

#[test]
fn region_takes_the_comma_form_of_its_help_with_negative_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let o = generate(dir.path(), "1", &["--region", "0.5,-0.2,0.5,0.75,0.2,0.8"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = tempfile::tempdir().unwrap();
    let o = generate(dir.path(), "1", &["--region", "0.5,-0.2,0.5"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--region"), "{}", stderr(&o));
}

#[test]
fn empty_splits_are_said_at_generation_and_refused_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let o = generate(dir.path(), "2", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: Value = serde_json::from_slice(&o.stdout).unwrap();
    let warnings = summary["warnings"].as_array().unwrap();
    assert_eq!(warnings.len(), 2, "{summary}");
    assert!(
        stderr(&o).contains("the val split is empty"),
        "{}",
        stderr(&o)
    );
    let model = dir.path().join("m");
    let o = dpmp(&[
        "train",
        "--data",
        dir.path().join("data").to_str().unwrap(),
        "--arch",
        "ae",
        "--out",
        model.to_str().unwrap(),
        "--epochs-tp1",
        "1",
        "--epochs-tp2",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("0 val targets"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("backtrace"), "{}", stderr(&o));
    assert!(!model.join("model.safetensors").exists());
}

/// Three recordings of a 4 s motion at 50 Hz as a `/joint_states` export
/// would write them: epoch nanoseconds and `position_k` columns.
fn ros_export(dir: &std::path::Path) -> std::path::PathBuf {
    let demos = dir.join("ros");
    std::fs::create_dir_all(&demos).unwrap();
    let home = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    for k in 0..3 {
        let mut text = String::from("time");
        for j in 0..7 {
            text += &format!(",position_{j}");
        }
        text.push('\n');
        for i in 0..=200 {
            let t = i as f64 / 50.0;
            let s = t / 4.0;
            text += &format!("{}", 1_700_000_000_000_000_000u64 + (t * 1e9) as u64);
            for (j, h) in home.iter().enumerate() {
                let q = h + 0.2
                    * (1.0 + 0.1 * k as f64)
                    * s
                    * s
                    * (3.0 - 2.0 * s)
                    * (j as f64 * 0.3).cos();
                text += &format!(",{q:.6}");
            }
            text.push('\n');
        }
        std::fs::write(demos.join(format!("{k}.csv")), text).unwrap();
    }
    demos
}

#[test]
fn prior_fit_reads_nanosecond_times_and_renamed_joint_columns() {
    let dir = tempfile::tempdir().unwrap();
    let demos = ros_export(dir.path());
    let map: Vec<String> = (0..7)
        .map(|j| format!("panda_joint{}=position_{j}", j + 1))
        .collect();
    let map = map.join(",");
    let out = dir.path().join("prior");
    let demos_s = demos.to_str().unwrap();
    let out_s = out.to_str().unwrap();
    let fit = |extra: &[&str]| {
        let mut args = vec!["prior", "fit", "--demos", demos_s, "--out", out_s];
        args.extend_from_slice(extra);
        dpmp(&args)
    };
    // Without the map the missing column is named, with the hint.
    let o = fit(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("panda_joint1") && stderr(&o).contains("--joint-map"));
    let o = fit(&["--joint-map", &map]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: Value =
        serde_json::from_slice(&std::fs::read(out.join("fit.json")).unwrap()).unwrap();
    let text = report.to_string();
    assert!(text.contains("\"duration_s\":4.0"), "{text}");
    assert!(text.contains("\"rate_hz\":50.0"), "{text}");
    // Read as seconds, the recording lasts 4e9 s: refused, naming the unit.
    let o = fit(&["--joint-map", &map, "--time-unit", "s"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--time-unit"), "{}", stderr(&o));
    // A joint the robot does not have.
    let o = fit(&["--joint-map", "elbow=position_3"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--joint-map"), "{}", stderr(&o));
}

#[test]
fn every_invalid_input_exits_2_and_an_unwanted_answer_3() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.json");
    let missing_s = missing.to_str().unwrap();
    let bad_csv = dir.path().join("bad.csv");
    std::fs::write(&bad_csv, "time,panda_joint1\n0,0.1\n1,x\n").unwrap();
    let prior_out = dir.path().join("p");
    let beyond = dir.path().join("beyond.csv");
    let header = "time,panda_joint1,panda_joint2,panda_joint3,panda_joint4,panda_joint5,panda_joint6,panda_joint7";
    let rows: String = (0..20)
        .map(|i| format!("{},5.0,-0.785,0,-2.356,0,1.571,0.785\n", i as f64 * 0.1))
        .collect();
    std::fs::write(&beyond, format!("{header}\n{rows}")).unwrap();
    let cases: Vec<Vec<&str>> = vec![
        vec!["optimize", "--request", missing_s],
        vec![
            "robot",
            "fk",
            "--q",
            "0,0,0,0,0,0,0",
            "--robot",
            missing_s,
            "--base",
            "a",
            "--tip",
            "b",
        ],
        vec![
            "prior",
            "fit",
            "--demos",
            bad_csv.to_str().unwrap(),
            "--out",
            prior_out.to_str().unwrap(),
        ],
        vec!["eval", "--model", missing_s, "--data", missing_s],
        vec![
            "prior",
            "fit",
            "--demos",
            beyond.to_str().unwrap(),
            "--out",
            prior_out.to_str().unwrap(),
        ],
        vec!["plan", "--image", missing_s, "--box", "1,2,3,4"],
    ];
    for args in &cases {
        let o = dpmp(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        let named = ["missing", "bad.csv", "beyond.csv"];
        let err = stderr(&o);
        assert!(named.iter().any(|n| err.contains(n)), "{args:?}: {err}");
    }
    // IK to a point out of reach: the answer is printed, exit 0 or 3 on request.
    let far = ["robot", "ik", "--position", "3,0,0.5"];
    let o = dpmp(&far);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(answer["converged"], false, "{answer}");
    let mut strict = far.to_vec();
    strict.push("--require-converged");
    let o = dpmp(&strict);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(serde_json::from_slice::<Value>(&o.stdout).is_ok());
}

#[test]
fn robot_clearance_names_the_shape() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.json");
    std::fs::write(
        &scene,
        r#"{"obstacles": [{"id": "b", "type": "sphere", "center": [0.5, 0.0, 0.4], "radius": 0.03}]}"#,
    )
    .unwrap();
    let o = dpmp(&[
        "robot",
        "clearance",
        "--q",
        "0,-0.785,0,-2.356,0,1.571,0.785",
        "--scene",
        scene.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    let name = answer["shape_name"].as_str().unwrap();
    assert!(
        name.starts_with(answer["link"].as_str().unwrap()),
        "{answer}"
    );
}

#[test]
fn plan_from_another_folder_uses_the_shipped_model_and_checks_the_box_first() {
    let dir = tempfile::tempdir().unwrap();
    let o = generate(dir.path(), "1", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let data = dir.path().join("data");
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(data.join("manifest.json")).unwrap()).unwrap();
    let record_path = data.join(manifest["targets"][0]["record"].as_str().unwrap());
    let record: Value = serde_json::from_slice(&std::fs::read(record_path).unwrap()).unwrap();
    let image = data.join(record["image"].as_str().unwrap());
    let depth = data.join(record["depth"].as_str().unwrap());
    let b: Vec<String> = record["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.to_string())
        .collect();
    let run_in = |b: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_dpmp"))
            .current_dir(dir.path())
            .env_remove("DPMP_MODEL_DIR")
            .args(["plan", "--image", image.to_str().unwrap(), "--box", b])
            .args(["--mask-applied", "--depth", depth.to_str().unwrap()])
            .output()
            .unwrap()
    };
    for bad in ["0.61,0.17,0.66,0.26", "400,120,380,100", "630,470,700,520"] {
        let o = run_in(bad);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
        assert!(stderr(&o).contains("--box"), "{bad}: {}", stderr(&o));
        assert!(
            !stderr(&o).contains("depth samples"),
            "{bad}: {}",
            stderr(&o)
        );
    }
    // A colour image not of the camera's size is named as such.
    let small = dir.path().join("small.png");
    image::open(&image)
        .unwrap()
        .resize_exact(320, 240, image::imageops::FilterType::Triangle)
        .save(&small)
        .unwrap();
    let plan_small = |flag: &str, file: &std::path::Path| {
        let small = small.to_str().unwrap();
        dpmp(&[
            "plan",
            "--image",
            small,
            "--box",
            "10,10,40,40",
            flag,
            file.to_str().unwrap(),
        ])
    };
    // An 8-bit depth image is refused as input (2), naming the file.
    let depth8 = dir.path().join("depth8.png");
    image::GrayImage::new(640, 480).save(&depth8).unwrap();
    let o = dpmp(&[
        "plan",
        "--image",
        image.to_str().unwrap(),
        "--box",
        &b.join(","),
        "--depth",
        depth8.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("depth8.png") && stderr(&o).contains("16-bit"),
        "{}",
        stderr(&o)
    );
    let o = plan_small("--depth", &depth);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--image")
            && stderr(&o).contains("320x240")
            && stderr(&o).contains("640x480"),
        "{}",
        stderr(&o)
    );
    // A camera file that is not one is named.
    let camera = dir.path().join("camera.json");
    std::fs::write(&camera, r#"{"intrinsics": {"width": 320}}"#).unwrap();
    let o = plan_small("--camera", &camera);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("camera.json"), "{}", stderr(&o));
    let o = run_in(&b.join(","));
    assert!(o.status.success(), "{}", stderr(&o));
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        answer["model"].as_str().is_some_and(|m| !m.is_empty()),
        "{answer}"
    );
}

#[test]
fn a_missing_top_level_field_is_named_over_http() {
    use crate::common::http::{client, field, post_json, start, test_config};
    let server = start(test_config());
    let (status, body) = post_json(
        &client(),
        &server.url("/v1/optimize"),
        r#"{"duration_s": 2}"#,
    );
    // Without `prior` the request gets the smooth prior, which needs the
    // start: the first missing field is `start`, and the message says why.
    assert_eq!((status, field(&body)), (422, Some("start")), "{body}");
    assert!(body.to_string().contains("smooth prior"), "{body}");
}
