//! End-to-end checks of the synthetic dataset generator: determinism across
//! worker counts, the manifest contract, statistics against the real data's
//! band, and validation before anything is written.

use crate::common::json::read_json;
use dpmp::perception::locate_target;
use dpmp::robot::Robot;
use dpmp::synth::dataset::{load_depth, load_image, load_manifest, load_record};
use dpmp::synth::generate::{generate, GenerateOptions, Generator};
use dpmp::synth::settings::SynthSettings;
use dpmp::synth::stats::{dataset_stats, default_basis, TargetSummary};
use std::path::Path;

fn options(out: &Path, workers: usize) -> GenerateOptions {
    GenerateOptions {
        out: out.to_path_buf(),
        seed: 7,
        workers: Some(workers),
        progress: false,
        overwrite: false,
    }
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for sub in ["images", "targets", "depth"] {
        let mut names: Vec<_> = std::fs::read_dir(dir.join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        for p in names {
            out.push((
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            ));
        }
    }
    out.push((
        "manifest.json".into(),
        std::fs::read(dir.join("manifest.json")).unwrap(),
    ));
    out
}

#[test]
fn same_seed_gives_byte_identical_datasets_for_any_worker_count() {
    let g = Generator::new(SynthSettings::new(3, 2), Robot::panda().unwrap()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("one"), tmp.path().join("two"));
    generate(&g, &options(&a, 1)).unwrap();
    generate(&g, &options(&b, 2)).unwrap();
    let (fa, fb) = (files(&a), files(&b));
    assert_eq!(fa.len(), 3 * 2 * 3 + 1);
    for ((na, ba), (nb, bb)) in fa.iter().zip(&fb) {
        assert_eq!(na, nb);
        assert!(ba == bb, "{na} differs between 1 and 2 workers");
    }
}

#[test]
fn manifest_lists_only_existing_valid_files_and_splits_by_config() {
    let g = Generator::new(SynthSettings::new(4, 3), Robot::panda().unwrap()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    generate(&g, &options(tmp.path(), 2)).unwrap();
    let m = load_manifest(tmp.path()).unwrap();
    assert_eq!(m.targets.len(), 12);
    for e in &m.targets {
        let r = load_record(tmp.path(), e).unwrap();
        let img = load_image(tmp.path(), e).unwrap();
        assert_eq!(img.dimensions(), (640, 480));
        assert_eq!(r.demos.len(), 10);
        // The box is painted white and filled; its centre pixel is white.
        let [cx, cy] = r.center;
        assert_eq!(img.get_pixel(cx as u32, cy as u32).0, [255, 255, 255]);
        assert!(r
            .scene
            .obstacles()
            .iter()
            .any(|o| o.id == r.target_obstacle_id));
        // The aligned depth image: same size, and the recorded target depth
        // is what back-projection measures in it, within a few mm of the
        // true berry centre.
        let depth = load_depth(tmp.path(), e, 0.001).unwrap().unwrap();
        assert_eq!((depth.width(), depth.height()), (640, 480));
        let measured = r.target_depth_m.expect("measured depth");
        let camera = g.camera();
        let t = locate_target(&depth, &r.bbox, camera, "depth").unwrap();
        assert_eq!(t.depth_m, measured);
        let truth = nalgebra::Point3::from(r.target_position.unwrap());
        let error = (nalgebra::Point3::from(t.position) - truth).norm();
        assert!(error < 0.008, "{}: {error} m", r.id);
    }
    let all: usize = ["train", "val", "test"]
        .iter()
        .map(|s| m.split(s).unwrap().len())
        .sum();
    assert_eq!(all, 12);
    for s in ["train", "val", "test"] {
        for e in m.split(s).unwrap() {
            for other in ["train", "val", "test"].iter().filter(|o| **o != s) {
                assert!(
                    m.split(other).unwrap().iter().all(|x| x.config != e.config),
                    "config {} in {s} and {other}",
                    e.config
                );
            }
        }
    }
    assert!(m.split("bogus").is_err());
}

#[test]
fn a_colour_only_dataset_of_format_1_still_loads() {
    let mut settings = SynthSettings::new(2, 2);
    settings.depth.enabled = false;
    let g = Generator::new(settings, Robot::panda().unwrap()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    generate(&g, &options(tmp.path(), 1)).unwrap();
    // Rewrite the manifest as version 1 wrote it: old tag, no depth fields.
    let path = tmp.path().join("manifest.json");
    let mut m = read_json(&path);
    m["format"] = "dpmp-dataset/1".into();
    m["settings"].as_object_mut().unwrap().remove("depth");
    std::fs::write(&path, serde_json::to_string(&m).unwrap()).unwrap();
    let m = load_manifest(tmp.path()).unwrap();
    for e in &m.targets {
        assert!(e.depth.is_none());
        assert!(load_depth(tmp.path(), e, 0.001).unwrap().is_none());
        let r = load_record(tmp.path(), e).unwrap();
        assert!(r.depth.is_none() && r.target_depth_m.is_none());
    }
    let mut bad = serde_json::to_value(&m).unwrap();
    bad["format"] = "dpmp-dataset/9".into();
    std::fs::write(&path, serde_json::to_string(&bad).unwrap()).unwrap();
    let e = load_manifest(tmp.path()).unwrap_err();
    assert!(e.to_string().contains("format"), "{e}");
}

#[test]
fn a_failed_run_leaves_no_manifest() {
    let mut s = SynthSettings::new(2, 3);
    // Demonstrations can never keep 5 cm from every leaf and berry.
    s.demos.clearance_m = 0.05;
    s.demos.standoff_m = 0.15;
    s.demos.max_tries = 1;
    s.demos.max_config_tries = 1;
    let g = Generator::new(s, Robot::panda().unwrap()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("manifest.json"), "{}").unwrap();
    let mut o = options(tmp.path(), 1);
    assert!(generate(&g, &o)
        .unwrap_err()
        .to_string()
        .contains("--overwrite"));
    o.overwrite = true;
    let e = generate(&g, &o).unwrap_err();
    assert!(e.to_string().contains("gave up"), "{e}");
    assert!(!tmp.path().join("manifest.json").exists());
}

#[test]
fn bad_settings_fail_before_any_file_is_written() {
    let robot = Robot::panda().unwrap();
    let mut far = SynthSettings::new(2, 3);
    far.plant.region.min = [1.4, -0.1, 0.6];
    far.plant.region.max = [1.5, 0.1, 0.7];
    let e = Generator::new(far, robot.clone()).err().unwrap();
    assert_eq!(e.field(), Some("plant.region"), "{e}");
    assert!(Generator::new(SynthSettings::new(2, 0), robot.clone()).is_err());
    let mut tight = SynthSettings::new(2, 3);
    tight.demos.clearance_m = 1.0;
    assert!(Generator::new(tight, robot).is_err());
}

/// REFERENCE.md: final-time std per joint, median over the real targets.
const REFERENCE_FINAL_STD: [f64; 7] = [0.04, 0.05, 0.04, 0.11, 0.09, 0.22, 0.34];

#[test]
fn final_std_per_joint_is_within_a_factor_two_of_the_real_data() {
    let g = Generator::new(SynthSettings::new(4, 3), Robot::panda().unwrap()).unwrap();
    let summaries: Vec<TargetSummary> = (0..4)
        .flat_map(|c| g.config(3, c).unwrap().records)
        .map(|r| TargetSummary::from_record(&r).unwrap())
        .collect();
    let stats = dataset_stats(&summaries, &default_basis().unwrap(), &g.robot().home());
    for (j, (s, r)) in stats
        .final_std_median
        .iter()
        .zip(REFERENCE_FINAL_STD)
        .enumerate()
    {
        assert!(
            *s >= r / 2.0 && *s <= r * 2.0,
            "joint {}: synthetic {s:.3} vs real {r}",
            j + 1
        );
    }
    assert!(stats.start_spread_max < 0.015);
    assert!(
        stats.spacing_min >= 0.04 && stats.spacing_max <= 0.25,
        "{stats:?}"
    );
}
