//! Throughput of the synthetic data generator: one configuration of five
//! targets (plant, 50 demonstrations with IK and clearance checks, one
//! render, five noisy boxed images), and the render alone.

use criterion::{criterion_group, criterion_main, Criterion};
use dpmp::robot::Robot;
use dpmp::synth::generate::{config_rng, Generator};
use dpmp::synth::plant::sample_plant;
use dpmp::synth::render::render_plant;
use dpmp::synth::settings::SynthSettings;

fn bench(c: &mut Criterion) {
    let g = Generator::new(SynthSettings::new(1, 5), Robot::panda().unwrap()).unwrap();
    let mut group = c.benchmark_group("synth");
    group.sample_size(10);
    let mut config = 0;
    group.bench_function("config_5_targets", |b| {
        b.iter(|| {
            config += 1;
            g.config(1, config).unwrap()
        })
    });
    let s = g.settings();
    let mut rng = config_rng(1, 0);
    let plant = sample_plant(&s.plant, g.camera(), 4.0, 5, &g.placement(), &mut rng).unwrap();
    group.bench_function("render_640x480", |b| {
        b.iter(|| render_plant(&plant, g.camera(), &s.render, &mut rng))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
