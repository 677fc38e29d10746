//! `dpmp data import` at a lab's scale: 25 targets (five plants), each with
//! ten demonstrations recorded at 1 kHz for 8 s (8,001 rows x 7 joints of
//! CSV, 250 files, ~150 MB), a 640x480 JPEG and its depth PNG. One
//! iteration imports the whole manifest into a fresh folder: reading and
//! validating every cell, fitting, locating the berry in depth, writing.
//! Target: <= 5 s (`cargo bench --bench import`).

use criterion::{criterion_group, criterion_main, Criterion};
use dpmp::demos::{import, ImportSettings};
use dpmp::robot::Robot;
use serde_json::json;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Duration;

const TARGETS: usize = 25;
const DEMOS: usize = 10;
const RATE_HZ: f64 = 1000.0;
const DURATION_S: f64 = 8.0;

/// One smooth recording from home to an offset (minimum jerk), distinct
/// per target and demonstration.
fn recording(robot: &Robot, target: usize, demo: usize) -> String {
    let home = robot.home();
    let mut text = String::from("time");
    for name in robot.joint_names() {
        write!(text, ",{name}").ok();
    }
    text.push('\n');
    let n = (RATE_HZ * DURATION_S) as usize + 1;
    for k in 0..n {
        let t = k as f64 / RATE_HZ;
        let z = t / DURATION_S;
        let s = z * z * z * (10.0 - 15.0 * z + 6.0 * z * z);
        write!(text, "{t:.4}").ok();
        for (j, h) in home.iter().enumerate() {
            let offset = 0.2 * (((target * 7 + j) as f64).sin() + 0.05 * demo as f64);
            write!(text, ",{:.6}", h + offset * s).ok();
        }
        text.push('\n');
    }
    text
}

/// The example's images and depth, reused; the recordings written fresh.
fn write_manifest(dir: &Path) -> std::path::PathBuf {
    let robot = Robot::panda().expect("panda");
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/import");
    let source: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(example.join("manifest.json")).expect("example manifest"),
    )
    .expect("example json");
    let originals = source["targets"].as_array().expect("targets");
    let targets: Vec<_> = (0..TARGETS)
        .map(|k| {
            let original = &originals[k % originals.len()];
            let demos: Vec<String> = (0..DEMOS)
                .map(|d| {
                    let file = format!("demos/t{k:02}_{d}.csv");
                    let path = dir.join(&file);
                    std::fs::create_dir_all(path.parent().expect("dir")).expect("mkdir");
                    std::fs::write(&path, recording(&robot, k, d)).expect("write csv");
                    file
                })
                .collect();
            let at = |key: &str| example.join(original[key].as_str().expect("path"));
            json!({
                "id": format!("t{k:02}"),
                "group": format!("plant{}", k / 5),
                "image": at("image"),
                "box": original["box"],
                "mask_applied": true,
                "depth": at("depth"),
                "demos": demos,
                "obstacles": original["obstacles"],
            })
        })
        .collect();
    let path = dir.join("manifest.json");
    std::fs::write(&path, json!({ "targets": targets }).to_string()).expect("manifest");
    path
}

fn bench_import(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let manifest = write_manifest(dir.path());
    let robot = Robot::panda().expect("panda");
    let settings = ImportSettings {
        overwrite: true,
        ..Default::default()
    };
    let out = dir.path().join("out");
    let mut group = c.benchmark_group("import");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(40));
    group.bench_function("25_targets_x_10_demos_1khz_8s", |b| {
        b.iter(|| import(&manifest, &out, &robot, &settings).expect("import"))
    });
    group.finish();
}

criterion_group!(benches, bench_import);
criterion_main!(benches);
