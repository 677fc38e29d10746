//! `dpmp prior fit` end to end: demonstrations sampled from a known weight
//! distribution (Panda, written as CSV at several rates and as JSON) are
//! fitted back. Checked against independent computations: the fitted mean
//! trajectory against the sample mean of the recordings, the covariance
//! against the known distribution (within sampling error), the annotation
//! files against the prior they were written from (round trip), and
//! `prior.json` is a request `dpmp optimize` solves. Bad recordings are
//! errors naming the file and the column, and nothing is written.

use crate::common::cli::{arg, dpmp, dpmp_ok, stderr};
use crate::common::json::read_json;
use dpmp::promp::{annotation, Basis, PrompConfig, WeightDistribution};
use dpmp::robot::Robot;
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use std::fmt::Write as _;
use std::path::Path;

const DEMOS: usize = 200;

/// The known distribution: the example prior with half its spread.
fn known() -> (Basis, WeightDistribution) {
    let basis = Basis::new(&PrompConfig::default()).unwrap();
    let mut dist = dpmp::fixtures::example_distribution(&basis, 30, 5).unwrap();
    dist.cov *= 0.25;
    (basis, dist)
}

/// Joint positions of weights `w` at phase `z`.
fn positions(basis: &Basis, w: &DVector<f64>, z: f64) -> Vec<f64> {
    let psi = basis.row_at(z);
    (0..7).map(|j| psi.dot(&w.rows(j * 8, 8))).collect()
}

fn within_limits(robot: &Robot, basis: &Basis, w: &DVector<f64>) -> bool {
    (0..=100).all(|k| {
        positions(basis, w, k as f64 / 100.0)
            .iter()
            .zip(robot.limits())
            .all(|(q, l)| *q > l.lower && *q < l.upper)
    })
}

/// Write demonstration `k` (weights `w`) as CSV (or JSON for k = 0), at a
/// rate and duration that vary with `k`.
fn write_demo(dir: &Path, k: usize, basis: &Basis, w: &DVector<f64>, robot: &Robot) {
    let rate = [30.0, 100.0, 250.0][k % 3];
    let duration = 6.0 + (k % 5) as f64 * 0.5;
    let n = (rate * duration) as usize + 1;
    let times: Vec<f64> = (0..n).map(|i| 10.0 + i as f64 / rate).collect();
    let rows: Vec<Vec<f64>> = times
        .iter()
        .map(|t| positions(basis, w, (t - 10.0) / (times[n - 1] - 10.0)))
        .collect();
    let names = robot.joint_names();
    if k == 0 {
        let mut value = serde_json::json!({ "time": times });
        for (j, name) in names.iter().enumerate() {
            value[name] = rows.iter().map(|r| r[j]).collect::<Vec<_>>().into();
        }
        std::fs::write(dir.join("d000.json"), value.to_string()).unwrap();
        return;
    }
    // Joints in reverse order and an extra column, as an export might have.
    let mut text = String::from("time,effort");
    for name in names.iter().rev() {
        write!(text, ",{name}").unwrap();
    }
    text.push('\n');
    for (t, r) in times.iter().zip(&rows) {
        write!(text, "{t},0").unwrap();
        for q in r.iter().rev() {
            write!(text, ",{q}").unwrap();
        }
        text.push('\n');
    }
    std::fs::write(dir.join(format!("d{k:03}.csv")), text).unwrap();
}

/// Sampled weights inside the joint limits, written as demonstrations.
fn sample_demos(dir: &Path) -> (Basis, WeightDistribution, Vec<DVector<f64>>) {
    let (basis, dist) = known();
    let robot = Robot::panda().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut weights = Vec::new();
    while weights.len() < DEMOS {
        let w = dist.sample(&mut rng, 1).remove(0);
        if within_limits(&robot, &basis, &w) {
            write_demo(dir, weights.len(), &basis, &w, &robot);
            weights.push(w);
        }
    }
    (basis, dist, weights)
}

#[test]
fn prior_fit_recovers_the_distribution_the_demonstrations_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let demos = dir.path().join("demos");
    std::fs::create_dir(&demos).unwrap();
    let (basis, known, weights) = sample_demos(&demos);
    let out = dir.path().join("prior");
    let plot = dir.path().join("prior.png");
    let o = dpmp_ok(&[
        "prior",
        "fit",
        "--demos",
        arg(&demos),
        "--out",
        arg(&out),
        "--plot",
        arg(&plot),
    ]);
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["demonstrations"], DEMOS);
    assert_eq!(report["demos"][1]["samples"], 651); // d001.csv: 100 Hz for 6.5 s
    assert!(
        report["max_rms_residual_rad"].as_f64().unwrap() < 1e-6,
        "{report}"
    );
    assert!(std::fs::metadata(&plot).unwrap().len() > 10_000);

    // prior.json is an optimise request; its mean is the recordings' mean.
    let request: dpmp::optim::OptimizeRequest =
        serde_json::from_value(read_json(&out.join("prior.json"))).unwrap();
    let dpmp::optim::request::PriorSpec::Full { mean, cov } = &request.prior else {
        panic!("a full prior");
    };
    let n = 56;
    let fitted = WeightDistribution::new(
        DVector::from_column_slice(mean),
        DMatrix::from_fn(n, n, |r, c| cov[r][c]),
        7,
        8,
    )
    .unwrap();
    let sample_mean = weights.iter().fold(DVector::zeros(n), |a, w| a + w) / DEMOS as f64;
    let recorded_mean = DMatrix::from_fn(150, 7, |t, j| {
        positions(&basis, &sample_mean, basis.phases()[t])[j]
    });
    let mean_error = (fitted.trajectory_mean(&basis) - recorded_mean).amax();
    assert!(mean_error < 1e-3, "mean trajectory off by {mean_error} rad");

    // The spread: within sampling error of the known distribution (200
    // draws: ~5 % on a standard deviation; the limits truncate a little).
    let fitted_std = fitted.trajectory_std(&basis, 0.0);
    let known_std = known.trajectory_std(&basis, 0.0);
    for t in 0..150 {
        for j in 0..7 {
            let (f, k) = (fitted_std[(t, j)], known_std[(t, j)]);
            if k > 1e-3 {
                assert!((f / k - 1.0).abs() < 0.2, "t {t} joint {j}: {f} vs {k}");
            }
        }
    }

    // The annotation files decode to the same per-joint blocks.
    let prior = annotation::load_dir(&out, 0).unwrap();
    for j in 0..7 {
        let (m, c) = prior.distribution.joint_block(j);
        let (fm, fc) = fitted.joint_block(j);
        assert!(
            (m - fm).amax() < 1e-9 && (c - fc).amax() < 1e-9,
            "joint {j}"
        );
    }

    // dpmp optimize solves the written request.
    let o = dpmp_ok(&["optimize", "--request", arg(&out.join("prior.json"))]);
    let answer: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(answer["status"], "optimal", "{}", answer["reason"]);
}

/// Turns a good CSV text into a bad one.
type Corruption = fn(String) -> String;

#[test]
fn bad_demonstrations_name_the_file_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let robot = Robot::panda().unwrap();
    let (basis, dist) = known();
    let cases: [(&str, Corruption, &str); 3] = [
        (
            "no_joint5.csv",
            |t| t.replacen("panda_joint5", "panda_joint5_effort", 1),
            "column 'panda_joint5' is missing",
        ),
        (
            "text.csv",
            |t| {
                let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
                let mut cells: Vec<&str> = lines[4].split(',').collect();
                cells[2] = "zero"; // panda_joint7 (the joints are written in reverse)
                lines[4] = cells.join(",");
                lines.join("\n")
            },
            "line 5, column 'panda_joint7': 'zero'",
        ),
        (
            "backwards.csv",
            |t| {
                let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
                lines.swap(3, 4);
                lines.join("\n")
            },
            "time must increase",
        ),
    ];
    for (name, corrupt, expected) in cases {
        let demos = dir.path().join(name.trim_end_matches(".csv"));
        std::fs::create_dir_all(&demos).unwrap();
        for k in 1..=2 {
            write_demo(&demos, k, &basis, &dist.mean, &robot);
        }
        let good = std::fs::read_to_string(demos.join("d001.csv")).unwrap();
        std::fs::write(demos.join(name), corrupt(good)).unwrap();
        let out = dir.path().join(format!("out-{name}"));
        let o = dpmp(&["prior", "fit", "--demos", arg(&demos), "--out", arg(&out)]);
        assert!(!o.status.success());
        let err = stderr(&o);
        assert!(
            err.contains(name) && err.contains(expected),
            "{name}: {err}"
        );
        assert!(!out.exists(), "{name}: output written");
    }
}
