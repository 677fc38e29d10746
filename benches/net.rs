//! Inference speed: one 640x480 JPEG (decode, box painting, resize,
//! normalisation, network, covariance decoding) per iteration, with the
//! default-size cVAE (the shipped `models/default` when present, else a
//! freshly initialised network of the same size). Target: <= 10 ms.
//! Also one tp1 training step (batch 5), and the whole plan pipeline
//! (`dpmp::plan`) on generated plants, same run (`cargo bench --bench net --
//! plan`): the box-only `models/rgb-only` without and with the aligned
//! depth image (what depth itself costs), and the depth-conditioned
//! `models/default` with depth.

use criterion::{criterion_group, criterion_main, Criterion};
use dpmp::net::{Arch, Model, ModelConfig, Network};
use std::hint::black_box;
use std::path::Path;

/// The shipped default model (depth-conditioned).
fn model() -> Model {
    model_at("models/default")
}

/// A shipped model (`dir` relative to the repository), or a freshly
/// initialised default-size cVAE when it is absent.
fn model_at(dir: &str) -> Model {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    if shipped.join("model.safetensors").exists() {
        if let Ok(model) = Model::load(&shipped) {
            return model;
        }
    }
    let config = ModelConfig::new("bench", Arch::Cvae);
    Model::from_network(Network::new(config, 0, &candle_core::Device::Cpu).expect("network"))
}

fn jpeg_640x480() -> Vec<u8> {
    let image = image::RgbImage::from_fn(640, 480, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, ((x * y) % 251) as u8])
    });
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
        .encode_image(&image)
        .expect("encode");
    bytes
}

fn inference(c: &mut Criterion) {
    let model = model();
    let jpeg = jpeg_640x480();
    let mut group = c.benchmark_group("net");
    group.sample_size(50);
    group.bench_function("predict_640x480_jpeg", |b| {
        b.iter(|| {
            let image = image::load_from_memory(black_box(&jpeg)).expect("decode");
            // A typical berry depth, read only by a depth-conditioned model.
            let p = model
                .predict_with_depth(&image, [300.0, 200.0, 340.0, 250.0], false, Some(0.45))
                .expect("predict");
            black_box(p.distribution.mean[0])
        })
    });
    let image = image::load_from_memory(&jpeg).expect("decode");
    group.bench_function("preprocess_only", |b| {
        b.iter(|| model.preprocess(black_box(&image), [300.0, 200.0, 340.0, 250.0], false))
    });
    group.finish();
}

/// One tp1 training step of the default-size cVAE (batch 5: encoder and
/// decoder forward, reconstruction loss, backward) — the cost that
/// dominates training.
fn tp1_step(c: &mut Criterion) {
    let device = candle_core::Device::Cpu;
    let network = Network::new(ModelConfig::new("bench", Arch::Cvae), 0, &device).expect("network");
    let images = candle_core::Tensor::randn(0f32, 0.5, (5, 3, 128, 128), &device).expect("images");
    let conditions =
        candle_core::Tensor::zeros((5, 2), candle_core::DType::F32, &device).expect("conditions");
    let mut group = c.benchmark_group("train");
    group.sample_size(10);
    group.bench_function("tp1_step_batch5", |b| {
        b.iter(|| {
            let enc = network.encode(&images, true).expect("encode");
            let features = network.features(&enc.mu, &conditions).expect("features");
            let recon = network.decode(&features).expect("decode").expect("decoder");
            let loss = dpmp::train::losses::reconstruction_loss(&recon, &images).expect("loss");
            black_box(loss.backward().expect("backward"))
        })
    });
    group.finish();
}

/// Plants in the plan benchmark.
const PLAN_PLANTS: usize = 10;

/// The plan pipeline on generated plants (each with its scene as
/// obstacles), one iteration plans all of them: the JPEG alone, then the
/// JPEG and its 16-bit depth PNG (decode, back-projection, the goal it
/// implies).
fn plan(c: &mut Criterion) {
    use dpmp::plan::{predict_and_optimize, PlanFields, PlanParts, PlanRequest};
    use dpmp::robot::Robot;
    use dpmp::synth::generate::Generator;
    use dpmp::synth::settings::SynthSettings;
    use std::sync::Arc;
    let robot = Arc::new(Robot::panda().expect("panda"));
    let box_only = Arc::new(model_at("models/rgb-only"));
    let depth_model = Arc::new(model());
    let settings = SynthSettings::new(PLAN_PLANTS, 1);
    let generator = Generator::new(settings, (*robot).clone()).expect("generator");
    let plants: Vec<_> = (0..PLAN_PLANTS)
        .map(|k| {
            let out = generator.config(21, k).expect("plant");
            let mut jpeg = Vec::new();
            image::DynamicImage::ImageRgb8(out.images[0].clone())
                .write_to(
                    &mut std::io::Cursor::new(&mut jpeg),
                    image::ImageFormat::Jpeg,
                )
                .expect("jpeg");
            let depth = out.depths[0]
                .as_ref()
                .expect("depth")
                .encode_png()
                .expect("png");
            let record = out.records[0].clone();
            let task = dpmp::optim::Task {
                obstacles: record.scene.obstacles(),
                clearance_m: 0.02,
                ..Default::default()
            };
            (jpeg, depth, record.bbox, task)
        })
        .collect();
    let run = |model: &Arc<Model>, with_depth: bool| {
        for (jpeg, depth, bbox, task) in &plants {
            let image = image::load_from_memory(jpeg).expect("decode");
            let depth = with_depth.then(|| {
                dpmp::perception::DepthImage::decode_png(depth, 0.001, "depth").expect("depth")
            });
            let parts = PlanParts {
                mask_applied: true,
                depth,
                ..PlanParts::new(image, *bbox, task.clone())
            };
            let input = PlanRequest::new(parts, &PlanFields::json()).expect("plan request");
            black_box(
                predict_and_optimize(model, &robot, input, &Default::default()).expect("plan"),
            );
        }
    };
    let mut group = c.benchmark_group("plan");
    group.sample_size(10);
    group.bench_function("without_depth_10_plants", |b| {
        b.iter(|| run(&box_only, false))
    });
    group.bench_function("with_depth_10_plants", |b| b.iter(|| run(&box_only, true)));
    group.bench_function("depth_model_10_plants", |b| {
        b.iter(|| run(&depth_model, true))
    });
    group.finish();
}

criterion_group!(benches, inference, tp1_step, plan);
criterion_main!(benches);
