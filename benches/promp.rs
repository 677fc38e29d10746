//! ProMP core benchmarks: basis construction, fitting a 150 x 7 trajectory,
//! decoding a 7-joint annotation, conditioning on start + goal.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use dpmp::fixtures::demonstrations as example;
use dpmp::promp::{annotation, fit_weights, Basis, PrompConfig, ViaPoint};

fn benches(c: &mut Criterion) {
    let config = PrompConfig::default();
    c.bench_function("basis_new_8x150", |b| {
        b.iter(|| Basis::new(black_box(&config)))
    });

    let basis = Basis::new(&config).expect("default basis");
    let demo = example::demonstrations(&example::TYPICAL_FINAL, 1, 150, 3).remove(0);
    c.bench_function("fit_150x7", |b| {
        b.iter(|| fit_weights(&basis, black_box(&demo)))
    });

    let dist = example::example_distribution(&basis, 10, 1).expect("example prior");
    let joints = annotation::joints_from_distribution(&dist).expect("encode");
    c.bench_function("decode_annotation_7_joints", |b| {
        b.iter(|| annotation::prior_from_joints(black_box(&joints), 8))
    });

    let vias = [
        ViaPoint {
            phase: 0.0,
            q: example::HOME.to_vec(),
            noise_var: 1e-6,
        },
        ViaPoint {
            phase: 1.0,
            q: example::TYPICAL_FINAL.to_vec(),
            noise_var: 1e-6,
        },
    ];
    c.bench_function("condition_start_goal", |b| {
        b.iter(|| dist.condition(&basis, black_box(&vias)))
    });
}

criterion_group!(promp, benches);
criterion_main!(promp);
