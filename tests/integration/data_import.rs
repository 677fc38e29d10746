//! `dpmp data import` on the worked example in `examples/import/` (three
//! plants, two berries each, three CSV demonstrations per berry, depth):
//! the import is checked against independent computations (the recordings'
//! final configurations through forward kinematics, the fit's residual),
//! splits never share a plant, the result trains and plans end to end, and
//! bad manifests are reported target by target with nothing written.

use crate::common::cli::{arg, dpmp, dpmp_ok, stderr};
use crate::common::json::{numbers, read_json};
use dpmp::robot::Robot;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/import")
}

/// `dpmp data import --manifest MANIFEST --out OUT`, which must succeed;
/// its summary.
fn import(manifest: &Path, out: &Path) -> Value {
    let o = dpmp_ok(&[
        "data",
        "import",
        "--manifest",
        arg(manifest),
        "--out",
        arg(out),
    ]);
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The last row of a demonstration CSV, joints only.
fn last_configuration(csv: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(csv).unwrap();
    let last = text.lines().last().unwrap();
    last.split(',')
        .skip(1)
        .take(7)
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn the_worked_example_imports_trains_and_plans() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let manifest = example().join("manifest.json");
    let summary = import(&manifest, &data);
    assert_eq!(
        (
            &summary["targets"],
            &summary["groups"],
            &summary["demonstrations"]
        ),
        (&json!(6), &json!(3), &json!(18))
    );
    // The recordings are ProMP trajectories written to 6 decimals.
    assert!(
        summary["max_rms_residual_rad"].as_f64().unwrap() < 1e-5,
        "{summary}"
    );

    // Splits keep each plant together.
    let written = read_json(&data.join("manifest.json"));
    assert_eq!(written["format"], "dpmp-dataset/5");
    let group_of = |id: &str| id.split('-').next().unwrap().to_string();
    let mut seen = std::collections::HashMap::new();
    for split in ["train", "val", "test"] {
        for id in written["splits"][split].as_array().unwrap() {
            let previous = seen.insert(group_of(id.as_str().unwrap()), split);
            assert!(previous.is_none_or(|p| p == split), "{id} in two splits");
        }
    }

    // Each record's final TCP is the mean of its recordings' final TCPs.
    let robot = Robot::panda().unwrap();
    let input = read_json(&manifest);
    for target in input["targets"].as_array().unwrap() {
        let id = target["id"].as_str().unwrap();
        let record = read_json(&data.join(format!("targets/{id}.json")));
        let finals: Vec<_> = target["demos"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| {
                let q = last_configuration(&example().join(f.as_str().unwrap()));
                robot.tcp_pose(&q).translation.vector
            })
            .collect();
        let mean = finals.iter().sum::<nalgebra::Vector3<f64>>() / finals.len() as f64;
        let recorded = numbers(&record["final_tcp"]["position"]);
        let error = (mean - nalgebra::Vector3::from_row_slice(&recorded)).norm();
        assert!(error < 1e-9, "{id}: {error}");
        assert!(record["target_depth_m"].as_f64().unwrap() > 0.2);
        assert!(record.get("target_position").is_none());
    }

    // The same import again: the same bytes.
    let again = dir.path().join("again");
    import(&manifest, &again);
    for file in ["manifest.json", "targets/plant1-berry0.json"] {
        assert_eq!(
            std::fs::read(data.join(file)).unwrap(),
            std::fs::read(again.join(file)).unwrap(),
            "{file}"
        );
    }

    // The dataset records its robot: training for another one is refused.
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/panda/panda.urdf");
    let o = dpmp(&[
        "train",
        "--data",
        arg(&data),
        "--arch",
        "cvae",
        "--out",
        arg(&dir.path().join("hand-model")),
        "--robot",
        arg(&urdf),
        "--tip",
        "panda_hand",
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("dataset") && err.contains("is for another robot"),
        "{err}"
    );

    // Train a tiny depth-conditioned model for a few steps and plan with it.
    let model = dir.path().join("model");
    dpmp_ok(&[
        "train",
        "--data",
        arg(&data),
        "--arch",
        "cvae",
        "--depth-condition",
        "--out",
        arg(&model),
        "--epochs-tp1",
        "1",
        "--epochs-tp2",
        "2",
        "--latent-dim",
        "16",
        "--quiet",
    ]);
    let target = &input["targets"][2];
    let bbox: Vec<String> = target["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.to_string())
        .collect();
    let scene = dir.path().join("scene.json");
    std::fs::write(
        &scene,
        json!({"obstacles": target["obstacles"]}).to_string(),
    )
    .unwrap();
    let o = dpmp_ok(&[
        "plan",
        "--model",
        arg(&model),
        "--image",
        arg(&example().join(target["image"].as_str().unwrap())),
        "--box",
        &bbox.join(","),
        "--mask-applied",
        "--depth",
        arg(&example().join(target["depth"].as_str().unwrap())),
        "--scene",
        arg(&scene),
    ]);
    let answer: Value = serde_json::from_slice(&o.stdout).unwrap();
    let status = answer["status"].as_str().unwrap();
    assert!(["optimal", "infeasible", "max_iterations"].contains(&status));
    assert_eq!(answer["target"]["source"], "depth");
    for p in answer["trajectory"]["points"].as_array().unwrap() {
        for (q, l) in p["positions"]
            .as_array()
            .unwrap()
            .iter()
            .zip(robot.limits())
        {
            let q = q.as_f64().unwrap();
            assert!(q >= l.lower - 1e-6 && q <= l.upper + 1e-6);
        }
    }

    // eval reads the imported dataset (no ground-truth berry positions).
    let o = dpmp_ok(&[
        "eval",
        "--model",
        arg(&model),
        "--data",
        arg(&data),
        "--split",
        "all",
        "--format",
        "json",
        "--out",
        arg(&dir.path().join("eval")),
    ]);
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["plan_targets"], 6);
    assert!(report.get("target_position_error_m").is_none());
}

/// A copy of the example's manifest with `edit` applied, in `dir`.
fn edited_manifest(dir: &Path, edit: impl Fn(&mut Value)) -> PathBuf {
    let mut manifest = read_json(&example().join("manifest.json"));
    // Paths stay relative to the example folder.
    for t in manifest["targets"].as_array_mut().unwrap() {
        for key in ["image", "depth"] {
            t[key] = json!(example().join(t[key].as_str().unwrap()));
        }
        for d in t["demos"].as_array_mut().unwrap() {
            *d = json!(example().join(d.as_str().unwrap()));
        }
    }
    edit(&mut manifest);
    let path = dir.join("manifest.json");
    std::fs::write(&path, manifest.to_string()).unwrap();
    path
}

/// A change to the example's manifest.
type Edit = Box<dyn Fn(&mut Value)>;

#[test]
fn bad_manifests_name_every_bad_target_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let no_joint5 = dir.path().join("no_joint5.csv");
    let good = std::fs::read_to_string(example().join("demos/plant0-berry0/0.csv")).unwrap();
    std::fs::write(&no_joint5, good.replacen("panda_joint5", "j5", 1)).unwrap();
    let cases: Vec<(&str, Edit, Vec<&str>)> = vec![
        (
            "empty",
            Box::new(|m| m["targets"] = json!([])),
            vec!["targets: empty"],
        ),
        (
            "duplicate",
            Box::new(|m| m["targets"][1]["id"] = m["targets"][0]["id"].clone()),
            vec!["\"plant0-berry0\" appears twice"],
        ),
        (
            "several",
            Box::new(move |m| {
                m["targets"][0]["image"] = json!("/nonexistent/a.png");
                m["targets"][3]["box"] = json!([600.0, 400.0, 700.0, 500.0]);
                m["targets"][4]["demos"][1] = json!(no_joint5.clone());
            }),
            vec![
                "3 of 6 targets are invalid",
                "(plant0-berry0)",
                "/nonexistent/a.png",
                "(plant1-berry1)",
                "box",
                "(plant2-berry0)",
                "no_joint5.csv",
                "column 'panda_joint5' is missing",
            ],
        ),
        (
            "unknown",
            Box::new(|m| m["targets"][0]["colour"] = json!("red")),
            vec!["targets[0]", "colour"],
        ),
        (
            "time unit",
            Box::new(|m| m["time_unit"] = json!("minutes")),
            vec!["time_unit", "expected auto, s, ms, us or ns"],
        ),
        (
            "joint columns",
            Box::new(|m| m["joint_columns"] = json!({"elbow": "position_3"})),
            vec!["joint_columns", "`elbow` is not a joint"],
        ),
        (
            "recorded in ms read as ns",
            Box::new(|m| m["time_unit"] = json!("ns")),
            vec!["column 'time'", "--time-unit"],
        ),
        (
            "neither",
            Box::new(|m| {
                m["targets"][5]
                    .as_object_mut()
                    .unwrap()
                    .remove("demos")
                    .map(|_| ())
                    .unwrap()
            }),
            vec!["(plant2-berry1)", "either demos"],
        ),
    ];
    for (name, edit, expected) in cases {
        let case = dir.path().join(name);
        std::fs::create_dir_all(&case).unwrap();
        let manifest = edited_manifest(&case, edit);
        let out = case.join("out");
        let o = dpmp(&[
            "data",
            "import",
            "--manifest",
            arg(&manifest),
            "--out",
            arg(&out),
        ]);
        assert_eq!(o.status.code(), Some(2), "{name}: {}", stderr(&o));
        let err = stderr(&o);
        for e in expected {
            assert!(err.contains(e), "{name}: {e:?} not in {err}");
        }
        assert!(err.contains("manifest.json"), "{name}: {err}");
        let left: Vec<_> = std::fs::read_dir(&case)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left.len(), 1, "{name}: left {left:?}");
    }
}

#[test]
fn annotation_folders_are_a_prior_source() {
    // The paper's layout (J1..J7/K.json) beside one's own image: the
    // record's distribution is the annotation's, decoded.
    let dir = tempfile::tempdir().unwrap();
    let annotation = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/priors/example");
    let manifest = edited_manifest(dir.path(), |m| {
        let mut t = m["targets"][0].clone();
        t.as_object_mut().unwrap().remove("demos");
        t["prior"] = json!({"annotation": annotation, "index": 0});
        t["duration_s"] = json!(5.0);
        m["targets"] = json!([t]);
    });
    let out = dir.path().join("data");
    import(&manifest, &out);
    let record = read_json(&out.join("targets/plant0-berry0.json"));
    let prior = dpmp::promp::annotation::load_dir(&annotation, 0).unwrap();
    let mean: Vec<f64> = serde_json::from_value(record["distribution"]["mean"].clone()).unwrap();
    let diff = mean
        .iter()
        .zip(prior.distribution.mean.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-12, "{diff}");
    assert_eq!(record["demos"], json!([]));
    assert_eq!(record["duration_s"], json!(5.0));
    // Its final TCP is the prior mean's final configuration through FK.
    let basis = dpmp::promp::Basis::new(&dpmp::promp::PrompConfig::default()).unwrap();
    let last = prior.distribution.trajectory_mean(&basis);
    let q: Vec<f64> = last.row(last.nrows() - 1).iter().copied().collect();
    let tcp = Robot::panda().unwrap().tcp_pose(&q).translation.vector;
    let recorded: Vec<f64> =
        serde_json::from_value(record["final_tcp"]["position"].clone()).unwrap();
    assert!((tcp - nalgebra::Vector3::from_row_slice(&recorded)).norm() < 1e-12);
}

/// A TCP recording (`time,x,y,z,qx,qy,qz,qw`) of a joint recording, by FK
/// row by row, the quaternion's sign flipped on odd rows as some loggers do.
fn tcp_recording(joint_csv: &Path, robot: &Robot) -> String {
    let text = std::fs::read_to_string(joint_csv).unwrap();
    let mut out = String::from("time,x,y,z,qx,qy,qz,qw\n");
    for (k, line) in text.lines().skip(1).enumerate() {
        let cells: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let pose = robot.tcp_pose(&cells[1..8]);
        let p = pose.translation.vector;
        let sign = if k % 2 == 1 { -1.0 } else { 1.0 };
        let c = pose.rotation.coords * sign;
        out += &format!(
            "{},{},{},{},{},{},{},{}\n",
            cells[0], p.x, p.y, p.z, c[0], c[1], c[2], c[3]
        );
    }
    out
}

#[test]
fn tcp_recordings_give_the_task_space_weights_fk_derives() {
    // The example's targets with TCP recordings of their demonstrations:
    // the fitted task-space distribution is the one derived from the joint
    // recordings by FK (the recordings are smooth; fit residuals only).
    let dir = tempfile::tempdir().unwrap();
    let robot = Robot::panda().unwrap();
    let plain = edited_manifest(dir.path(), |_| {});
    let derived_dir = dir.path().join("derived");
    import(&plain, &derived_dir);
    let tcp_dir = dir.path().join("tcp");
    std::fs::create_dir_all(&tcp_dir).unwrap();
    let mut manifest = read_json(&plain);
    for t in manifest["targets"].as_array_mut().unwrap() {
        let files: Vec<Value> = t["demos"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let path = tcp_dir.join(format!("{}-{k}.csv", t["id"].as_str().unwrap()));
                std::fs::write(&path, tcp_recording(Path::new(d.as_str().unwrap()), &robot))
                    .unwrap();
                json!(path)
            })
            .collect();
        t["task_demos"] = json!(files);
    }
    let with_tcp = dir.path().join("with_tcp.json");
    std::fs::write(&with_tcp, manifest.to_string()).unwrap();
    let fitted_dir = dir.path().join("fitted");
    import(&with_tcp, &fitted_dir);
    for t in manifest["targets"].as_array().unwrap() {
        let file = format!("targets/{}.json", t["id"].as_str().unwrap());
        let (a, b) = (
            read_json(&derived_dir.join(&file)),
            read_json(&fitted_dir.join(&file)),
        );
        let mean = |r: &Value| numbers(&r["task_distribution"]["mean"]);
        let (ma, mb) = (mean(&a), mean(&b));
        assert_eq!(ma.len(), 56);
        let diff = ma
            .iter()
            .zip(&mb)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(diff < 1e-3, "{file}: task-space means differ by {diff}");
        assert_eq!(b["demos"][0]["task_weights"].as_array().unwrap().len(), 56);
    }
    // One recording fewer than the demonstrations is refused by name.
    let mut short = manifest.clone();
    short["targets"][0]["task_demos"]
        .as_array_mut()
        .unwrap()
        .pop();
    let path = dir.path().join("short.json");
    std::fs::write(&path, short.to_string()).unwrap();
    let o = dpmp(&[
        "data",
        "import",
        "--manifest",
        arg(&path),
        "--out",
        arg(&dir.path().join("short")),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(err.contains("task_demos"), "{err}");
    assert!(!dir.path().join("short").exists());
}
