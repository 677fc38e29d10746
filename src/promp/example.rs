//! A self-contained example prior: joint-space demonstrations shaped like
//! the paper's real ones (same home start, a final configuration and
//! per-joint final spread matching the published statistics), for demos,
//! documentation and tests that must not depend on external data.

use super::{fit_weights, Basis, WeightDistribution};
use crate::Result;
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// The paper's home configuration (rad).
pub const HOME: [f64; 7] = [0.0348, -1.0102, -0.1525, -2.5334, -0.1583, 2.8798, 0.0543];
/// Mean final configuration over the 25 published targets (rad).
pub const TYPICAL_FINAL: [f64; 7] = [0.10, -0.032, -0.155, -1.812, -0.101, 3.239, 0.091];
/// Median final standard deviation per joint over the published targets (rad).
pub const FINAL_STD: [f64; 7] = [0.04, 0.05, 0.04, 0.11, 0.09, 0.22, 0.34];
/// Spread of the demonstrations' start configurations (rad).
pub const START_STD: f64 = 0.005;

/// Minimum-jerk profile `s(x) = 10x³ - 15x⁴ + 6x⁵`.
pub fn minimum_jerk(x: f64) -> f64 {
    x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)
}

/// `n_demos` joint-space demonstrations (`n_samples x 7`) from (near) home
/// to (near) `final_q`, minimum-jerk in time with a smooth random bulge.
pub fn demonstrations(
    final_q: &[f64; 7],
    n_demos: usize,
    n_samples: usize,
    seed: u64,
) -> Vec<DMatrix<f64>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n_demos)
        .map(|_| {
            let start: Vec<f64> = HOME
                .iter()
                .map(|h| h + START_STD * normal(&mut rng))
                .collect();
            let end: Vec<f64> = final_q
                .iter()
                .zip(FINAL_STD)
                .map(|(f, s)| f + s * normal(&mut rng))
                .collect();
            let bulge: Vec<f64> = (0..7).map(|_| 0.1 * normal(&mut rng)).collect();
            DMatrix::from_fn(n_samples, 7, |t, j| {
                let x = t as f64 / (n_samples - 1) as f64;
                start[j]
                    + (end[j] - start[j]) * minimum_jerk(x)
                    + bulge[j] * (std::f64::consts::PI * x).sin().powi(2)
            })
        })
        .collect()
}

fn normal(rng: &mut impl rand::Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// The weight distribution of [`demonstrations`] fitted in `basis`.
pub fn example_distribution(
    basis: &Basis,
    n_demos: usize,
    seed: u64,
) -> Result<WeightDistribution> {
    let demos = demonstrations(&TYPICAL_FINAL, n_demos, basis.n_samples(), seed);
    let weights: Vec<DVector<f64>> = demos
        .iter()
        .map(|d| fit_weights(basis, d))
        .collect::<Result<_>>()?;
    WeightDistribution::from_demonstrations(&weights, 7, basis.n_basis())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::PrompConfig;

    #[test]
    fn example_prior_starts_at_home_and_ends_near_the_typical_final() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let d = example_distribution(&basis, 50, 1).unwrap();
        let mean = d.trajectory_mean(&basis);
        let std = d.trajectory_std(&basis, 0.0);
        for j in 0..7 {
            assert!((mean[(0, j)] - HOME[j]).abs() < 0.01);
            assert!(
                (mean[(149, j)] - TYPICAL_FINAL[j]).abs()
                    < 3.0 * FINAL_STD[j] / 50f64.sqrt() + 0.01
            );
            assert!(
                std[(149, j)] > 0.5 * FINAL_STD[j] && std[(149, j)] < 1.5 * FINAL_STD[j],
                "joint {j}"
            );
        }
    }
}
