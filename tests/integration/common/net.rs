//! Shared helpers of the network tests: a tiny dataset on disk in the
//! `dpmp data generate` format (random images with a white target box,
//! random valid block-diagonal weight distributions) and tiny settings.

use dpmp::net::Arch;
use dpmp::train::{ShapeSettings, TrainSettings};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

pub const N_JOINTS: usize = 7;
pub const N_BASIS: usize = 8;

/// A random symmetric positive definite `n x n` matrix scaled by `scale`.
pub fn random_spd(rng: &mut ChaCha8Rng, n: usize, scale: f64) -> Vec<Vec<f64>> {
    let a: Vec<Vec<f64>> = (0..n)
        .map(|_| (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect())
        .collect();
    (0..n)
        .map(|r| {
            (0..n)
                .map(|c| {
                    let dot: f64 = (0..n).map(|k| a[r][k] * a[c][k]).sum();
                    scale * (dot + if r == c { 0.1 } else { 0.0 })
                })
                .collect()
        })
        .collect()
}

/// Write a dataset with `configs` configurations of `berries` targets each
/// into `dir` with the synth engineer's types; configuration 0 goes to val,
/// 1 to test (when there are more than two), the rest to train. Images are
/// `width x height`.
pub fn write_dataset(
    dir: &Path,
    configs: usize,
    berries: usize,
    width: u32,
    height: u32,
    seed: u64,
) {
    use dpmp::synth::dataset::{
        DistributionJson, Manifest, Pose, Splits, TargetEntry, TargetRecord, FORMAT,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("targets")).unwrap();
    let dim = N_JOINTS * N_BASIS;
    let promp = dpmp::promp::PrompConfig::default();
    let mut targets = Vec::new();
    let mut splits = Splits {
        train: vec![],
        val: vec![],
        test: vec![],
    };
    for c in 0..configs {
        let background = [
            rng.gen_range(0..200u8),
            rng.gen_range(0..200u8),
            rng.gen_range(0..200u8),
        ];
        for b in 0..berries {
            let entry = TargetEntry::new(c, b);
            let x1 = rng.gen_range(0.0..(width as f64 * 0.7));
            let y1 = rng.gen_range(0.0..(height as f64 * 0.7));
            let bx = [x1, y1, x1 + width as f64 * 0.25, y1 + height as f64 * 0.25];
            let mut image = image::RgbImage::from_pixel(width, height, image::Rgb(background));
            dpmp::net::preprocess::paint_box(&mut image, bx, [255, 255, 255]);
            image.save(dir.join(&entry.image)).unwrap();
            // Targets depend on the box position so that they are learnable.
            let u = (bx[0] + bx[2]) / (2.0 * width as f64);
            let v = (bx[1] + bx[3]) / (2.0 * height as f64);
            let mut mean = vec![0.0; dim];
            let mut cov = vec![vec![0.0; dim]; dim];
            for j in 0..N_JOINTS {
                for i in 0..N_BASIS {
                    mean[j * N_BASIS + i] = 0.3 * j as f64 - 1.0 + u * (i as f64 / 4.0) - v * 0.5;
                }
                let block = random_spd(&mut rng, N_BASIS, 1e-3);
                for r in 0..N_BASIS {
                    for k in 0..N_BASIS {
                        cov[j * N_BASIS + r][j * N_BASIS + k] = block[r][k];
                    }
                }
            }
            let distribution = dpmp::promp::WeightDistribution::new(
                nalgebra::DVector::from_vec(mean.clone()),
                nalgebra::DMatrix::from_fn(dim, dim, |r, k| cov[r][k]),
                N_JOINTS,
                N_BASIS,
            )
            .unwrap();
            let record = TargetRecord {
                id: entry.id.clone(),
                config: c,
                berry: b,
                image: entry.image.clone(),
                depth: None,
                target_depth_m: None,
                bbox: bx,
                center: [(bx[0] + bx[2]) / 2.0, (bx[1] + bx[3]) / 2.0],
                scene: dpmp::synth::dataset::RecordScene::default(),
                target_obstacle_id: format!("berry-{b}"),
                target_position: Some([0.65, 0.0, 0.7]),
                start: vec![0.0; N_JOINTS],
                final_tcp: Pose {
                    position: [0.65, 0.0, 0.7],
                    quaternion: [0.0, 0.0, 0.0, 1.0],
                },
                duration_s: 4.0,
                promp: promp.clone(),
                demos: vec![],
                distribution: DistributionJson { mean, cov },
                task_distribution: None,
                annotation: dpmp::promp::annotation::joints_from_distribution(&distribution)
                    .unwrap(),
            };
            std::fs::write(
                dir.join(&entry.record),
                serde_json::to_string(&record).unwrap(),
            )
            .unwrap();
            match c {
                0 => splits.val.push(entry.id.clone()),
                1 if configs > 2 => splits.test.push(entry.id.clone()),
                _ => splits.train.push(entry.id.clone()),
            }
            targets.push(entry);
        }
    }
    let manifest = Manifest {
        format: FORMAT.to_string(),
        generator_version: Some("test".into()),
        seed: Some(seed),
        settings: Some(dpmp::synth::settings::SynthSettings::default()),
        promp,
        camera: dpmp::synth::camera::Intrinsics {
            width,
            height,
            fx: 615.0,
            fy: 615.0,
            cx: 320.0,
            cy: 240.0,
        },
        camera_model: None,
        depth_scale_m: None,
        robot: None,
        splits,
        targets,
    };
    std::fs::write(
        dir.join("manifest.json"),
        serde_json::to_string(&manifest).unwrap(),
    )
    .unwrap();
}

/// Tiny, fast network settings.
pub fn tiny_settings(data: &Path, out: &Path, arch: Arch) -> TrainSettings {
    let mut s = TrainSettings::new(data, out, arch);
    s.shape = ShapeSettings {
        input_size: 16,
        encoder_channels: vec![4, 8],
        latent_dim: 16,
        head_hidden: vec![32],
    };
    s.progress = false;
    s.epochs_tp1 = 3;
    s.epochs_tp2 = 3;
    s.epochs_tp3 = 2;
    s.batch = 4;
    s.lr = 1e-3;
    s
}
