//! Network-level tests: covariance decoding against the f64 codec, Eq. 7
//! and Eq. 8 against nalgebra references, checkpoints (bit-identical
//! round trip, errors naming the tensor), preprocessing shared by training
//! and inference, input validation of the inference API.

use crate::common::json::{numbers, read_json};
use candle_core::{Device, Tensor};
use dpmp::net::checkpoint::{self, read_tensors, write_tensors};
use dpmp::net::heads::HeadOutput;
use dpmp::net::{Arch, CovarianceDecoder, Model, ModelConfig, Network};
use dpmp::promp::codec::{decode_covariance, DiagEncoding};
use dpmp::promp::{Basis, PrompConfig};
use dpmp::train::losses::TrajectoryOperator;
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn tiny_config(arch: Arch) -> ModelConfig {
    let mut c = ModelConfig::new("tiny", arch);
    c.preprocess.input_size = 16;
    c.encoder_channels = vec![4, 8];
    c.latent_dim = 16;
    c.head_hidden = vec![32];
    c
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    #[test]
    fn candle_covariance_decoding_matches_codec(code in prop::collection::vec(-2.0f64..2.0, 36)) {
        let decoder = CovarianceDecoder::new(8, &Device::Cpu).unwrap();
        let values: Vec<f32> = code.iter().map(|&v| v as f32).collect();
        let tensor = Tensor::from_vec(values.clone(), (1, 1, 36), &Device::Cpu).unwrap();
        let cov = decoder.decode(&tensor).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let rounded: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
        let reference = decode_covariance(&rounded, DiagEncoding::Log).unwrap();
        for r in 0..8 {
            for c in 0..8 {
                let a = f64::from(cov[r * 8 + c]);
                let b = reference[(r, c)];
                prop_assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()) * 10.0, "({r},{c}) {a} vs {b}");
            }
        }
    }
}

#[test]
fn covariance_decoding_is_exact_to_1e6_on_unit_scale_codes() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let decoder = CovarianceDecoder::new(8, &Device::Cpu).unwrap();
    for _ in 0..20 {
        let code: Vec<f32> = (0..36).map(|_| rng.gen_range(-0.5f32..0.5)).collect();
        let t = Tensor::from_vec(code.clone(), 36, &Device::Cpu)
            .unwrap()
            .reshape((1, 36))
            .unwrap();
        let cov = decoder
            .decode(&t)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let reference = decode_covariance(
            &code.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(),
            DiagEncoding::Log,
        )
        .unwrap();
        let worst = (0..64)
            .map(|k| (f64::from(cov[k]) - reference[(k / 8, k % 8)]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "max abs error {worst}");
    }
}

/// Random head outputs and targets for the loss checks.
fn random_loss_inputs(rng: &mut ChaCha8Rng, b: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let (j, n) = (7, 8);
    let pm: Vec<f32> = (0..b * j * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let code: Vec<f32> = (0..b * j * 36).map(|_| rng.gen_range(-1.0..0.5)).collect();
    let tm: Vec<f32> = (0..b * j * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut tc = Vec::new();
    for _ in 0..b * j {
        let m = crate::common::net::random_spd(rng, n, 0.1);
        tc.extend(m.iter().flatten().map(|&v| v as f32));
    }
    (pm, code, tm, tc)
}

fn block(values: &[f32], offset: usize, n: usize) -> DMatrix<f64> {
    DMatrix::from_fn(n, n, |r, c| f64::from(values[offset + r * n + c]))
}

#[test]
fn eq7_and_eq8_match_nalgebra_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let basis = Basis::new(&PrompConfig::default()).unwrap();
    let op = TrajectoryOperator::new(&basis, &Device::Cpu).unwrap();
    let (b, j, n, alpha) = (3usize, 7usize, 8usize, 0.7);
    let (pm, code, tm, tc) = random_loss_inputs(&mut rng, b);
    let dev = Device::Cpu;
    let pred = HeadOutput {
        mean: Tensor::from_vec(pm.clone(), (b, j, n), &dev).unwrap(),
        code: Tensor::from_vec(code.clone(), (b, j, 36), &dev).unwrap(),
    };
    let tmean = Tensor::from_vec(tm.clone(), (b, j, n), &dev).unwrap();
    let tcov = Tensor::from_vec(tc.clone(), (b, j, n, n), &dev).unwrap();
    let eq7 = op.trajectory_loss(&pred, &tmean, &tcov, alpha).unwrap();
    let eq8 = op.final_step_loss(&pred, &tmean, &tcov, alpha).unwrap();

    let phi = basis.matrix();
    let t = phi.nrows();
    let last = phi.row(t - 1).transpose();
    let (mut ref7, mut ref8) = (0.0, 0.0);
    let mut ref_mean = vec![0.0; j];
    for bi in 0..b {
        for (ji, joint_mean) in ref_mean.iter_mut().enumerate() {
            let k = bi * j + ji;
            let mu_hat =
                DVector::from_iterator(n, pm[k * n..(k + 1) * n].iter().map(|&v| f64::from(v)));
            let mu =
                DVector::from_iterator(n, tm[k * n..(k + 1) * n].iter().map(|&v| f64::from(v)));
            let c: Vec<f64> = code[k * 36..(k + 1) * 36]
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            let sigma_hat = decode_covariance(&c, DiagEncoding::Log).unwrap();
            let sigma = block(&tc, k * n * n, n);
            let dm = phi * (&mu_hat - &mu);
            let dc = phi * (&sigma_hat - &sigma) * phi.transpose();
            let m = dm.norm_squared() / t as f64;
            let cv = dc.norm_squared() / (t * t) as f64;
            *joint_mean += m / b as f64;
            ref7 += (m + alpha * cv) / b as f64;
            let fm = last.dot(&(&mu_hat - &mu));
            let fv = (last.transpose() * (&sigma_hat - &sigma) * &last)[(0, 0)];
            ref8 += (fm * fm + alpha * fv * fv) / b as f64;
        }
    }
    let got7 = f64::from(eq7.total.to_scalar::<f32>().unwrap());
    let got8 = f64::from(eq8.total.to_scalar::<f32>().unwrap());
    assert!(
        (got7 - ref7).abs() < 1e-4 * ref7.abs().max(1e-3),
        "eq7 {got7} vs {ref7}"
    );
    assert!(
        (got8 - ref8).abs() < 1e-4 * ref8.abs().max(1e-3),
        "eq8 {got8} vs {ref8}"
    );
    let per_joint = eq7.mean.to_vec1::<f32>().unwrap();
    assert_eq!(per_joint.len(), j);
    for (got, want) in per_joint.iter().zip(&ref_mean) {
        assert!((f64::from(*got) - want).abs() < 1e-4 * want.max(1e-3));
    }
}

#[test]
fn eq7_gradient_matches_finite_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let basis = Basis::new(&PrompConfig::default()).unwrap();
    let op = TrajectoryOperator::new(&basis, &Device::Cpu).unwrap();
    let (pm, code, tm, tc) = random_loss_inputs(&mut rng, 1);
    let dev = Device::Cpu;
    let tmean = Tensor::from_vec(tm, (1, 7, 8), &dev).unwrap();
    let tcov = Tensor::from_vec(tc, (1, 7, 8, 8), &dev).unwrap();
    let loss_at = |code: &[f32]| -> (f64, Vec<f32>) {
        let var = candle_core::Var::from_vec(code.to_vec(), (1, 7, 36), &dev).unwrap();
        let pred = HeadOutput {
            mean: Tensor::from_vec(pm.clone(), (1, 7, 8), &dev).unwrap(),
            code: var.as_tensor().clone(),
        };
        let l = op.trajectory_loss(&pred, &tmean, &tcov, 1.0).unwrap().total;
        let g = l.backward().unwrap();
        let grad = g
            .get(var.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        (f64::from(l.to_scalar::<f32>().unwrap()), grad)
    };
    let (_, grad) = loss_at(&code);
    for k in [0usize, 5, 7, 20, 35, 100, 251] {
        let h = 1e-2f32;
        let mut up = code.clone();
        up[k] += h;
        let mut down = code.clone();
        down[k] -= h;
        let fd = (loss_at(&up).0 - loss_at(&down).0) / (2.0 * f64::from(h));
        let g = f64::from(grad[k]);
        assert!(
            (fd - g).abs() < 2e-2 * g.abs().max(1e-4) + 1e-6,
            "entry {k}: fd {fd} vs grad {g}"
        );
    }
}

fn predict_all(
    model: &Model,
    images: &[image::DynamicImage],
) -> Vec<(Vec<f64>, Vec<f64>, Vec<f32>)> {
    images
        .iter()
        .map(|im| {
            let p = model.predict(im, [2.0, 3.0, 9.0, 8.0], false).unwrap();
            (
                p.distribution.mean.as_slice().to_vec(),
                p.distribution.cov.as_slice().to_vec(),
                p.latent,
            )
        })
        .collect()
}

fn test_images() -> Vec<image::DynamicImage> {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    (0..3)
        .map(|_| {
            let im = image::RgbImage::from_fn(40, 30, |_, _| {
                image::Rgb([rng.gen(), rng.gen(), rng.gen()])
            });
            image::DynamicImage::ImageRgb8(im)
        })
        .collect()
}

#[test]
fn save_then_load_gives_bit_identical_outputs_for_every_arch() {
    for arch in [Arch::Ae, Arch::Vae, Arch::Cvae, Arch::Direct] {
        let dir = tempfile::tempdir().unwrap();
        let network = Network::new(tiny_config(arch), 42, &Device::Cpu).unwrap();
        checkpoint::save(&network, dir.path()).unwrap();
        let before = predict_all(&Model::from_network(network), &test_images());
        let loaded = Model::load(dir.path()).unwrap();
        assert_eq!(loaded.config().arch, arch);
        let after = predict_all(&loaded, &test_images());
        assert_eq!(before, after, "{arch:?}");
        assert_eq!(before[0].0.len(), 56);
        assert_eq!(before[0].2.len(), 16);
    }
}

#[test]
fn initialisation_is_deterministic_for_a_seed() {
    let a = Network::new(tiny_config(Arch::Cvae), 1, &Device::Cpu).unwrap();
    let b = Network::new(tiny_config(Arch::Cvae), 1, &Device::Cpu).unwrap();
    let c = Network::new(tiny_config(Arch::Cvae), 2, &Device::Cpu).unwrap();
    let flat = |n: &Network| -> Vec<f32> {
        n.named_vars()
            .iter()
            .flat_map(|(_, v)| {
                v.as_tensor()
                    .flatten_all()
                    .unwrap()
                    .to_vec1::<f32>()
                    .unwrap()
            })
            .collect()
    };
    assert_eq!(flat(&a), flat(&b));
    assert_ne!(flat(&a), flat(&c));
}

#[test]
fn wrong_shaped_missing_and_corrupt_weights_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let network = Network::new(tiny_config(Arch::Ae), 0, &Device::Cpu).unwrap();
    checkpoint::save(&network, dir.path()).unwrap();
    let path = dir.path().join(checkpoint::WEIGHTS_FILE);
    let original = read_tensors(&path).unwrap();
    let as_tensors = |map: &checkpoint::TensorMap| -> Vec<(String, Tensor)> {
        map.iter()
            .map(|(k, (s, v))| {
                (
                    k.clone(),
                    Tensor::from_slice(v, s.as_slice(), &Device::Cpu).unwrap(),
                )
            })
            .collect()
    };

    // Weights rewritten with their checksum recorded, as a trainer would:
    // the loader's own checks must name what is wrong.
    let config_path = dir.path().join(checkpoint::CONFIG_FILE);
    let rewrite = |map: &checkpoint::TensorMap| {
        write_tensors(&path, &as_tensors(map)).unwrap();
        let mut config: serde_json::Value = read_json(&config_path);
        config["weights_sha256"] =
            serde_json::json!(checkpoint::sha256_hex(&std::fs::read(&path).unwrap()));
        std::fs::write(&config_path, config.to_string()).unwrap();
    };

    // Wrong shape.
    let mut map = original.clone();
    let name = "heads.joint3.fc0.weight".to_string();
    map.insert(name.clone(), (vec![2, 2], vec![0.0; 4]));
    rewrite(&map);
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(msg.contains(&name) && msg.contains("shape"), "{msg}");

    // Missing tensor.
    let mut map = original.clone();
    map.remove("encoder.block1.bn.running_var");
    rewrite(&map);
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("encoder.block1.bn.running_var") && msg.contains("missing"),
        "{msg}"
    );

    // Non-finite value.
    let mut map = original.clone();
    map.get_mut("encoder.mu.bias").unwrap().1[2] = f32::NAN;
    rewrite(&map);
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("encoder.mu.bias") && msg.contains("finite"),
        "{msg}"
    );

    // Corrupt bytes.
    std::fs::write(&path, b"\x10\x00\x00\x00\x00\x00\x00\x00{not json").unwrap();
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("model.safetensors") && msg.contains("corrupt"),
        "{msg}"
    );

    // Malformed config.
    rewrite(&original);
    Model::load(dir.path()).unwrap();
    std::fs::write(dir.path().join("config.json"), "{\"format\": 3}").unwrap();
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("config.json"), "{msg}");
}

#[test]
fn predict_validates_the_box_and_scales_the_condition_with_image_size() {
    let model =
        Model::from_network(Network::new(tiny_config(Arch::Cvae), 0, &Device::Cpu).unwrap());
    let im = image::DynamicImage::ImageRgb8(image::RgbImage::new(320, 240));
    let e = model
        .predict(&im, [10.0, 10.0, 400.0, 20.0], false)
        .unwrap_err();
    assert_eq!(e.field(), Some("box[2]"));
    let e = model
        .predict(&im, [10.0, f64::INFINITY, 40.0, 20.0], false)
        .unwrap_err();
    assert_eq!(e.field(), Some("box[1]"));
    // The same relative box on a half-size image gives the same condition.
    let small = model
        .preprocess(&im, [150.0, 100.0, 170.0, 140.0], false)
        .unwrap();
    let big_image = image::DynamicImage::ImageRgb8(image::RgbImage::new(640, 480));
    let big = model
        .preprocess(&big_image, [300.0, 200.0, 340.0, 280.0], false)
        .unwrap();
    assert_eq!(small.condition, big.condition);
    assert!((small.condition[0] - 0.5).abs() < 1e-7 && (small.condition[1] - 0.5).abs() < 1e-7);
    let p = model
        .predict(&im, [150.0, 100.0, 170.0, 140.0], false)
        .unwrap();
    assert!(p.distribution.mean.iter().all(|v| v.is_finite()));
    // Block-diagonal covariance: joints uncoupled.
    assert_eq!(p.distribution.cov[(0, 8)], 0.0);
    assert!(p.distribution.cov[(0, 0)] > 0.0);
}

#[test]
fn preprocessing_is_identical_in_training_and_inference_paths() {
    let dir = tempfile::tempdir().unwrap();
    crate::common::net::write_dataset(dir.path(), 2, 3, 64, 48, 4);
    let config = tiny_config(Arch::Cvae);
    let data = dpmp::train::data::load_split(
        dir.path(),
        "train",
        &config.preprocess,
        dpmp::train::data::Targets::Joint,
    )
    .unwrap();
    let model = Model::from_network(Network::new(config, 0, &Device::Cpu).unwrap());
    for sample in &data.samples {
        let image = image::open(dir.path().join(format!("images/{}.png", sample.id))).unwrap();
        let record = read_json(&dir.path().join(format!("targets/{}.json", sample.id)));
        let b = numbers(&record["box"]);
        let bx = [b[0], b[1], b[2], b[3]];
        let served = model.preprocess(&image, bx, true).unwrap();
        assert_eq!(served, sample.prepared);
        // Painting the box again on the already-masked image changes nothing.
        let repainted = model.preprocess(&image, bx, false).unwrap();
        assert_eq!(repainted, sample.prepared);
    }
}

#[test]
fn model_is_send_and_sync_and_shareable_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Model>();
    let model = std::sync::Arc::new(Model::from_network(
        Network::new(tiny_config(Arch::Vae), 3, &Device::Cpu).unwrap(),
    ));
    let image = test_images().remove(0);
    let expected = predict_all(&model, std::slice::from_ref(&image));
    let handles: Vec<_> = (0..2)
        .map(|_| {
            let (model, image) = (model.clone(), image.clone());
            std::thread::spawn(move || predict_all(&model, &[image]))
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), expected);
    }
}

#[test]
fn weights_changed_after_training_fail_their_checksum() {
    let dir = tempfile::tempdir().unwrap();
    let network = Network::new(tiny_config(Arch::Cvae), 0, &Device::Cpu).unwrap();
    checkpoint::save(&network, dir.path()).unwrap();
    let config: serde_json::Value = read_json(&dir.path().join(checkpoint::CONFIG_FILE));
    let path = dir.path().join(checkpoint::WEIGHTS_FILE);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(config["weights_sha256"], checkpoint::sha256_hex(&bytes));
    Model::load(dir.path()).unwrap();
    // One exponent bit flipped in every 97th float of the data: finite
    // values that load without the checksum.
    let mut flipped = bytes.clone();
    let header = 8 + u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    for k in (header..flipped.len() - 4).step_by(4 * 97) {
        flipped[k + 3] ^= 0x01;
    }
    std::fs::write(&path, &flipped).unwrap();
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("model.safetensors") && msg.contains("weights_sha256"),
        "{msg}"
    );
}

#[test]
fn the_shipped_models_record_their_weights_checksum() {
    for name in ["default", "rgb-only"] {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("models")
            .join(name);
        let config: serde_json::Value = read_json(&dir.join(checkpoint::CONFIG_FILE));
        let bytes = std::fs::read(dir.join(checkpoint::WEIGHTS_FILE)).unwrap();
        assert_eq!(
            config["weights_sha256"],
            checkpoint::sha256_hex(&bytes),
            "{name}"
        );
    }
}
