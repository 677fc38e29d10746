//! Inference speed: one 640x480 JPEG (decode, box painting, resize,
//! normalisation, network, covariance decoding) per iteration, with the
//! default-size cVAE (the shipped `models/default` when present, else a
//! freshly initialised network of the same size). Target: <= 10 ms.

use criterion::{criterion_group, criterion_main, Criterion};
use dpmp::net::{Arch, Model, ModelConfig, Network};
use std::hint::black_box;
use std::path::Path;

fn model() -> Model {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
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
            let p = model
                .predict(&image, [300.0, 200.0, 340.0, 250.0], false)
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

criterion_group!(benches, inference);
criterion_main!(benches);
