//! The prior without demonstrations: a Gaussian over the weights whose
//! Mahalanobis distance is the trajectory's integrated squared
//! acceleration (the smoothness prior of CHOMP and STOMP), conditioned on
//! where the motion starts and ends.
//!
//! For one joint with weights `w` the motion is `q(τ) = ψ(s(τ))ᵀ w` on the
//! normalised time `τ = t / T ∈ [0, 1]`, where the time warp `s(τ)` is the
//! optimiser's (`optim::problem::phases::TimeWarp`: ramps to rest at both
//! ends for `boundary: rest`, `s = τ` for `free`). Its acceleration is
//! `q̈(t) = a(τ)ᵀ w / T²` with `a = ψ''(s) ṡ² + ψ'(s) s̈`, so
//!
//! ```text
//! ∫₀ᵀ q̈(t)² dt = T⁻³ ∫₀¹ (a(τ)ᵀ w)² dτ = T⁻³ wᵀ R w,   R = ∫₀¹ a(τ) a(τ)ᵀ dτ.
//! ```
//!
//! `R` ([`SmoothnessPrior::acceleration_gram`]) is computed by Gauss–Legendre
//! quadrature on the basis' exact derivatives. Its null space is the
//! constant motion (the normalised basis sums to one), so the Gaussian
//! with precision `s R` is improper; conditioned on the start (and, when
//! given, the end) configuration it is proper:
//!
//! - mean: the smoothest motion meeting the conditions, `argmin wᵀ R w`
//!   subject to `A w = b` (eliminating the equalities);
//! - covariance: `N (Nᵀ s R N)⁻¹ Nᵀ` with `N` an orthonormal basis of the
//!   null space of `A`.
//!
//! On every trajectory meeting the conditions the Mahalanobis distance to
//! that mean is then `s (wᵀ R w − μᵀ R μ)`: minimising it (what the
//! optimiser does) minimises the integrated squared acceleration, and with
//! nothing else binding the answer is the mean itself.
//!
//! The scale `s` does not move the optimum; it sets how far prior draws
//! (the optimiser's restarts) reach. It is chosen so that the prior
//! conditioned on a start and an end has a standard deviation of
//! [`MID_MOTION_STD_RAD`] at mid-motion: draws bend the motion by about
//! that much, as far as a detour around a shelf board or a berry truss
//! needs.

use super::basis::Basis;
use super::config::PrompConfig;
use super::distribution::WeightDistribution;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// Standard deviation (rad) of the smoothness prior at mid-motion, with
/// both ends fixed at rest.
pub const MID_MOTION_STD_RAD: f64 = 0.5;

/// Basis functions per joint of [`smooth_basis_config`]. The start and end
/// configurations take two of each joint's weights; twelve leave ten for
/// the shape of the motion: room for a path out of a shelf, around a board
/// and in again (three bends, each about three functions wide at the
/// basis' overlap), where the paper's eight leave six, while the QP stays
/// at 84 weights.
pub const SMOOTH_N_BASIS: usize = 12;

/// Standard deviation of [`smooth_basis_config`]'s Gaussians as a multiple
/// of the spacing of their centres.
pub const SMOOTH_WIDTH_PER_SPACING: f64 = 1.0;

/// The basis the smoothness prior uses when a request does not choose one:
/// [`SMOOTH_N_BASIS`] functions whose standard deviation is the spacing of
/// their centres ([`SMOOTH_WIDTH_PER_SPACING`]), on the paper's 150 phase
/// samples. At the paper's overlap (1.85 spacings) the prior's precision
/// on the free weights has a condition number of 1.4e7: most of its
/// variance lies in weight directions that cancel in the motion, and the
/// smoothest motion is only found to ~1e-8 rad. At one spacing it is ~40.
pub fn smooth_basis_config() -> PrompConfig {
    smooth_basis_config_with(SMOOTH_N_BASIS)
}

/// The smoothness prior's basis with `n_basis` functions (at least 2),
/// spread as [`smooth_basis_config`]'s: each Gaussian's standard deviation
/// the spacing of their centres.
pub fn smooth_basis_config_with(n_basis: usize) -> PrompConfig {
    let sigma = SMOOTH_WIDTH_PER_SPACING / (n_basis.max(2) - 1) as f64;
    PrompConfig {
        n_basis,
        width: (sigma * sigma * 1e9).round() / 1e9,
        n_samples: PrompConfig::default().n_samples,
    }
}

/// Gauss–Legendre panels on [0, 1] for the Gram matrix.
const PANELS: usize = 128;

/// How the phase advances with normalised time: `[s, ṡ, s̈, s⃛]` at `τ`
/// (the optimiser's time warp).
pub type Warp<'a> = &'a dyn Fn(f64) -> [f64; 4];

/// Where a motion must start and end, for [`SmoothnessPrior::conditioned`].
#[derive(Clone, Debug)]
pub struct EndConditions<'a> {
    /// The start configuration, one value per joint.
    pub start: &'a [f64],
    /// The end configuration, when the goal is one.
    pub end: Option<&'a [f64]>,
}

/// The smoothness prior on one basis: the acceleration Gram matrix `R` and
/// the scale `s` ([`MID_MOTION_STD_RAD`]).
#[derive(Clone, Debug)]
pub struct SmoothnessPrior {
    basis: Basis,
    gram: DMatrix<f64>,
    scale: f64,
}

impl SmoothnessPrior {
    /// The prior on `config`'s basis (validated) for motions timed by
    /// `warp`.
    pub fn new(config: &PrompConfig, warp: Warp) -> Result<SmoothnessPrior> {
        let basis = Basis::new(config)?;
        let gram = acceleration_gram(&basis, warp);
        let mut prior = SmoothnessPrior {
            basis,
            gram,
            scale: 1.0,
        };
        prior.scale = prior.unit_scale_mid_variance()? / (MID_MOTION_STD_RAD * MID_MOTION_STD_RAD);
        Ok(prior)
    }

    /// `R = ∫₀¹ a(τ) a(τ)ᵀ dτ` (`n_basis x n_basis`).
    pub fn acceleration_gram(&self) -> &DMatrix<f64> {
        &self.gram
    }

    /// The scale `s`: one joint's precision is `s R`.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// `∫₀¹ (a(τ)ᵀ w)² dτ` of one joint's weights (`wᵀ R w`); divide by
    /// `T³` for the integral over time of the squared acceleration.
    pub fn phase_acceleration_cost(&self, weights: &[f64]) -> f64 {
        let w = DVector::from_column_slice(weights);
        (w.transpose() * &self.gram * &w)[(0, 0)]
    }

    /// The prior over `ends.start.len()` joints conditioned on `ends`
    /// (see the module docs). Errors name `start` or the end configuration
    /// when the lengths differ or a value is not finite.
    pub fn conditioned(&self, ends: &EndConditions) -> Result<WeightDistribution> {
        let dof = ends.start.len();
        check_configuration("start", ends.start, dof)?;
        if let Some(end) = ends.end {
            check_configuration("options.final_configuration", end, dof)?;
        }
        let rows = self.condition_rows(ends.end.is_some());
        let null = self.null_space(&rows)?;
        let nb = self.basis.n_basis();
        let reduced = null.transpose() * &self.gram * &null;
        let reduced = reduced
            .cholesky()
            .ok_or_else(|| singular("the conditioned precision"))?;
        let block_cov = &null * reduced.inverse() * null.transpose() / self.scale;
        // The particular solution of A w = b of least norm, then the step
        // in null(A) that minimises the cost: w = p − N (NᵀRN)⁻¹ NᵀR p.
        let pinv = rows
            .clone()
            .pseudo_inverse(1e-12)
            .map_err(|_| singular("the end conditions"))?;
        let mut mean = DVector::zeros(dof * nb);
        let mut cov = DMatrix::zeros(dof * nb, dof * nb);
        for j in 0..dof {
            let particular = &pinv * condition_values(ends, j, rows.nrows());
            let step = reduced.solve(&(null.transpose() * (&self.gram * &particular)));
            let w = particular - &null * step;
            mean.rows_mut(j * nb, nb).copy_from(&w);
            cov.view_mut((j * nb, j * nb), (nb, nb))
                .copy_from(&block_cov);
        }
        WeightDistribution::new(mean, super::psd::symmetrize(&cov), dof, nb)
    }

    /// The rows of `A` (one joint): the position at the start and, with an
    /// end configuration, at the end (rest, when asked, is the warp's).
    fn condition_rows(&self, with_end: bool) -> DMatrix<f64> {
        let mut rows = vec![self.basis.row_at(0.0)];
        if with_end {
            rows.push(self.basis.row_at(1.0));
        }
        let nb = self.basis.n_basis();
        DMatrix::from_fn(rows.len(), nb, |r, c| rows[r][c])
    }

    /// An orthonormal basis of the null space of `rows`.
    fn null_space(&self, rows: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let (m, nb) = rows.shape();
        if m >= nb {
            return Err(Error::invalid(
                "promp.n_basis",
                format!(
                    "the smooth prior needs more than {m} basis functions per joint (the start and end conditions take {m}), got {nb}"
                ),
            ));
        }
        let svd = rows
            .transpose()
            .try_svd(true, false, 5.0 * f64::EPSILON, 10_000)
            .ok_or_else(|| singular("the end conditions"))?;
        let u = svd.u.ok_or_else(|| singular("the end conditions"))?;
        if svd.singular_values.min() <= 1e-10 * svd.singular_values.max() {
            return Err(singular("the end conditions"));
        }
        let complete = complete_basis(&u, &DMatrix::identity(nb, nb));
        Ok(complete.columns(m, nb - m).into_owned())
    }

    /// `ψ(½)ᵀ Σ ψ(½)` of the unit-scale prior with both ends fixed.
    fn unit_scale_mid_variance(&self) -> Result<f64> {
        let rows = self.condition_rows(true);
        let null = self.null_space(&rows)?;
        let inner = (null.transpose() * &self.gram * &null)
            .try_inverse()
            .ok_or_else(|| singular("the conditioned precision"))?;
        let mid = null.transpose() * self.basis.row_at(0.5);
        Ok((mid.transpose() * inner * mid)[(0, 0)])
    }
}

/// `R = ∫₀¹ a(τ) a(τ)ᵀ dτ`, `a = ψ''(s) ṡ² + ψ'(s) s̈`, by 4-point
/// Gauss–Legendre quadrature on [`PANELS`] panels.
fn acceleration_gram(basis: &Basis, warp: Warp) -> DMatrix<f64> {
    const NODES: [f64; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const WEIGHTS: [f64; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    let nb = basis.n_basis();
    let h = 1.0 / PANELS as f64;
    let mut gram = DMatrix::zeros(nb, nb);
    for panel in 0..PANELS {
        let centre = (panel as f64 + 0.5) * h;
        for (x, wt) in NODES.iter().zip(WEIGHTS) {
            let a = time_acceleration_row(basis, warp, centre + 0.5 * h * x);
            gram.ger(0.5 * h * wt, &a, &a, 1.0);
        }
    }
    super::psd::symmetrize(&gram)
}

/// `a(τ) = ψ''(s) ṡ² + ψ'(s) s̈`: the acceleration row at normalised time
/// `tau` (times `T²`).
pub fn time_acceleration_row(basis: &Basis, warp: Warp, tau: f64) -> DVector<f64> {
    let [s, ds, dds, _] = warp(tau);
    let [_, d1, d2, _] = basis.rows_at(s);
    d2 * (ds * ds) + d1 * dds
}

/// `u`'s columns followed by those of `full` orthogonal to them.
fn complete_basis(u: &DMatrix<f64>, full: &DMatrix<f64>) -> DMatrix<f64> {
    let nb = full.nrows();
    let mut cols: Vec<DVector<f64>> = u.column_iter().map(|c| c.into_owned()).collect();
    for c in full.column_iter() {
        if cols.len() == nb {
            break;
        }
        let mut v = c.into_owned();
        // Twice: classical Gram-Schmidt loses orthogonality once.
        for _ in 0..2 {
            for b in &cols {
                let along = b.dot(&v);
                v -= b * along;
            }
        }
        let norm = v.norm();
        if norm > 1e-8 {
            cols.push(v / norm);
        }
    }
    DMatrix::from_columns(&cols)
}

/// The right-hand side of joint `j`'s conditions (the order of
/// [`SmoothnessPrior::condition_rows`]).
fn condition_values(ends: &EndConditions, j: usize, m: usize) -> DVector<f64> {
    let mut values = DVector::zeros(m);
    values[0] = ends.start[j];
    if let Some(end) = ends.end {
        values[1] = end[j];
    }
    values
}

fn check_configuration(field: &str, values: &[f64], dof: usize) -> Result<()> {
    if values.len() != dof {
        return Err(Error::invalid(
            field,
            format!("expected {dof} joint values, got {}", values.len()),
        ));
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            format!("{field}[{k}]"),
            "must be a finite number",
        ));
    }
    Ok(())
}

fn singular(what: &str) -> Error {
    Error::Numerical(format!("smooth prior: {what} is singular"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identity(tau: f64) -> [f64; 4] {
        [tau, 1.0, 0.0, 0.0]
    }

    #[test]
    fn the_gram_matrix_is_the_integral_of_the_squared_second_derivative() {
        // Against a composite Simpson rule on a fine grid, and constant
        // motions cost nothing.
        let prior = SmoothnessPrior::new(&smooth_basis_config(), &identity).unwrap();
        let basis = Basis::new(&smooth_basis_config()).unwrap();
        let n = 4000;
        let nb = basis.n_basis();
        let mut simpson = DMatrix::zeros(nb, nb);
        for k in 0..=n {
            let z = k as f64 / n as f64;
            let a = basis.second_derivative_row_at(z);
            let wt = if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            simpson.ger(wt / (3.0 * n as f64), &a, &a, 1.0);
        }
        let gram = prior.acceleration_gram();
        assert!(
            (gram - &simpson).amax() < 1e-7 * gram.amax(),
            "{}",
            (gram - &simpson).amax()
        );
        let ones = vec![1.0; nb];
        assert!(prior.phase_acceleration_cost(&ones) < 1e-9 * gram.amax());
    }

    #[test]
    fn the_smooth_basis_gives_a_well_conditioned_prior() {
        let c = smooth_basis_config();
        c.validate().unwrap();
        // A warp to rest at both ends: the minimum-jerk polynomial.
        let rest = |t: f64| {
            let (t2, t3) = (t * t, t * t * t);
            [
                t3 * (10.0 - 15.0 * t + 6.0 * t2),
                30.0 * t2 * (1.0 - t) * (1.0 - t),
                60.0 * t * (1.0 - t) * (1.0 - 2.0 * t),
                60.0 * (1.0 - 6.0 * t + 6.0 * t2),
            ]
        };
        for warp in [&identity as Warp, &rest] {
            let prior = SmoothnessPrior::new(&c, warp).unwrap();
            let null = prior.null_space(&prior.condition_rows(true)).unwrap();
            let eig =
                (null.transpose() * prior.acceleration_gram() * &null).symmetric_eigenvalues();
            assert!(eig.max() / eig.min() < 1e3, "{eig}");
        }
    }

    #[test]
    fn the_conditioned_mean_meets_its_conditions_and_the_mid_std_is_the_scale() {
        let prior = SmoothnessPrior::new(&smooth_basis_config(), &identity).unwrap();
        let basis = Basis::new(&smooth_basis_config()).unwrap();
        let start = [0.1, -0.4, 0.3];
        let end = [0.9, 0.2, -0.5];
        let ends = EndConditions {
            start: &start,
            end: Some(&end),
        };
        let dist = prior.conditioned(&ends).unwrap();
        let nb = basis.n_basis();
        let (p0, p1) = (basis.row_at(0.0), basis.row_at(1.0));
        for j in 0..3 {
            let w = dist.mean.rows(j * nb, nb);
            assert!((p0.dot(&w) - start[j]).abs() < 1e-10);
            assert!((p1.dot(&w) - end[j]).abs() < 1e-10);
            let (_, block) = dist.joint_block(j);
            let mid = basis.row_at(0.5);
            let std = (mid.transpose() * &block * &mid)[(0, 0)].sqrt();
            assert!((std - MID_MOTION_STD_RAD).abs() < 1e-9, "{std}");
            // No variance at the conditioned ends.
            assert!((p0.transpose() * &block * &p0)[(0, 0)].abs() < 1e-12);
        }
    }

    #[test]
    fn too_few_basis_functions_or_a_bad_start_are_refused_naming_the_field() {
        let few = PrompConfig {
            n_basis: 2,
            width: 0.5,
            n_samples: 150,
        };
        let prior = SmoothnessPrior::new(&few, &identity);
        let e = prior.map(|_| ()).unwrap_err();
        assert!(e.to_string().contains("promp.n_basis"), "{e}");
        let prior = SmoothnessPrior::new(&smooth_basis_config(), &identity).unwrap();
        let e = prior
            .conditioned(&EndConditions {
                start: &[0.0, f64::NAN],
                end: None,
            })
            .unwrap_err();
        assert!(e.to_string().contains("start[1]"), "{e}");
    }
}
