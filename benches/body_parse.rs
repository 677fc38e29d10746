//! What reading a request body costs before any planning: the
//! duplicate-key walk and the typed parse of `/v1/optimize`, on bodies at
//! the service's 16 MiB limit shaped to be expensive.
//!
//! - `body_parse/long_key/*`: a 1 MB key over 20,000 array elements and an
//!   8 MB key over 80,000 (the duplicate-key walk once copied the key per
//!   element: 0.5 s and ~25 s).
//! - `body_parse/optimize/*`: `parse_json::<OptimizeRequest>` (walk + typed
//!   parse) of 16 MiB bodies: a flat prior mean, covariance rows of one, a
//!   cloud obstacle's points, spheres, objects of one key each, a long
//!   string. Each is refused or
//!   parsed; the bound is 100 ms of CPU for any of them.
//!
//! `cargo bench --bench body_parse`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use dpmp::fixtures::bodies::repeated;
use dpmp::optim::OptimizeRequest;
use dpmp::service::extract::parse_json;
use std::time::Duration;

const MIB: usize = 1 << 20;

fn long_key(c: &mut Criterion) {
    let mut group = c.benchmark_group("body_parse/long_key");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    for (name, key, elements) in [("1MB_x_20k", MIB, 20_000), ("8MB_x_80k", 8 * MIB, 80_000)] {
        let body = format!(
            "{{\"{}\": {}}}",
            "k".repeat(key),
            repeated("0", 2 * elements)
        );
        group.bench_function(name, |b| {
            b.iter(|| dpmp::strict_json::find_duplicate_key(black_box(body.as_bytes())))
        });
    }
    group.finish();
}

fn optimize_bodies(c: &mut Criterion) {
    let fill = 16 * MIB - 256;
    let sphere = r#"{"id":"s","type":"sphere","center":[0.5,0.5,0.5],"radius":0.01}"#;
    let bodies = [
        (
            "prior_mean",
            format!(r#"{{"prior": {{"mean": {}}}}}"#, repeated("0", fill)),
        ),
        (
            "cov_rows_of_one",
            format!(
                r#"{{"prior": {{"mean": [], "cov": {}}}}}"#,
                repeated("[0]", fill)
            ),
        ),
        (
            "cloud_points",
            format!(
                r#"{{"obstacles": [{{"id": "c", "type": "points", "radius": 0.01, "points": {}}}]}}"#,
                repeated("[0.5,0.5,0.5]", fill)
            ),
        ),
        (
            "spheres",
            format!(r#"{{"obstacles": {}}}"#, repeated(sphere, fill)),
        ),
        (
            "one_key_objects",
            format!(r#"{{"via_points": {}}}"#, repeated(r#"{"a":0}"#, fill)),
        ),
        (
            "long_string",
            format!(r#"{{"obstacles": [{{"id": "{}"}}]}}"#, "i".repeat(fill)),
        ),
    ];
    let mut group = c.benchmark_group("body_parse/optimize");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    for (name, body) in &bodies {
        group.bench_function(*name, |b| {
            b.iter(|| parse_json::<OptimizeRequest>(black_box(body.as_bytes())).is_ok())
        });
    }
    group.finish();
}

criterion_group!(benches, long_key, optimize_bodies);
criterion_main!(benches);
