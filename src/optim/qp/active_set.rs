//! A [`Qp`] solved by the [dual active-set method](crate::optim::qp::dual_active_set)
//! instead of Clarabel: the SCP's intermediate iterations.
//!
//! The active-set solver takes an identity Hessian and linear rows only, so
//! the three things a `Qp` has beyond that are translated:
//!
//! - **equalities** are eliminated by the same [`NullSpace`] as Clarabel's
//!   path (the cost and the ball stay isotropic);
//! - **the trust ball** `|z - z_k| ≤ Δ` becomes a proximal term: the
//!   ball-constrained optimum is the optimum of
//!   `|z - c|² + μ|z - z_k|² + Σρ s` for the ball's multiplier `μ`, whose
//!   Hessian is again a multiple of the identity. `μ` is found by a secant
//!   search on `1/|z(μ) - z_k|` (linear in `μ` while the active set stays,
//!   [`TRUST_FILL`] of the radius is close enough: the ball only limits the
//!   step), each solve warm-started from the previous active set;
//! - **a goal cone** `|g0 + G z| ≤ r (+ s)` becomes soft tangent half-spaces
//!   `n̂·(g0 + G z) ≤ r`, the first at the residual direction at `z_k` (the
//!   cone's linearisation there), more generated where a solution breaks the
//!   cone (at most [`MAX_CONE_CUTS`]). The objective and slacks reported are
//!   the exact cone's.
//!
//! The final QP of a solve is always Clarabel's (see `scp`): this path only
//! has to produce good steps.

use crate::optim::qp::dual_active_set::{self as das, Row};
use crate::optim::qp::nullspace::NullSpace;
use crate::optim::qp::{Cone, Qp, QpFailure, QpSolution};
use crate::optim::tolerances::{CONE_TOLERANCE, TRUST_FILL, TRUST_OVERSHOOT};
use nalgebra::DVector;
use std::time::Instant;

/// Tangent cuts per cone at most.
pub const MAX_CONE_CUTS: usize = 6;
/// Proximal solves per QP at most.
const MAX_PROXIMAL_SOLVES: usize = 12;
/// Largest proximal weight tried: the step it allows is about
/// `1e-12` of the unconstrained one, already nothing; beyond it the weight
/// would overflow (a trust radius near 0 asks for an infinite weight) and
/// scale the caps to 0.
const MAX_PROXIMAL_WEIGHT: f64 = 1e12;

/// One solve of the active-set path at a proximal weight.
struct Proximal {
    sol: das::Solution,
    mu: f64,
}

impl Qp {
    /// Solve with the dual active-set method (see the module docs). `warm`:
    /// a guess of the row states by inequality index (e.g. the previous
    /// generation round's). The duals are on Clarabel's scale (`|z - c|² + Σρ s`).
    /// Past `deadline` it fails with [`QpFailure::OutOfTime`].
    pub fn solve_active_set(
        &self,
        warm: &das::WarmStart,
        mu_hint: f64,
        deadline: Option<Instant>,
    ) -> Result<QpSolution, QpFailure> {
        if self.equalities.is_empty() {
            return self.solve_active_set_free(warm, mu_hint, deadline);
        }
        let space = NullSpace::new(&self.equalities, self.dim()).ok_or(QpFailure::Infeasible)?;
        let mut sol = self
            .restricted_to(&space)
            .solve_active_set_free(warm, mu_hint, deadline)?;
        sol.z = space.lift(&sol.z);
        sol.objective += space.distance_squared(&self.center);
        Ok(sol)
    }

    fn solve_active_set_free(
        &self,
        warm: &das::WarmStart,
        mu_hint: f64,
        deadline: Option<Instant>,
    ) -> Result<QpSolution, QpFailure> {
        let reference = self.trust.as_ref().map_or(&self.center, |(c, _)| c);
        let mut cuts: Vec<Row> = self
            .cones
            .iter()
            .filter_map(|cone| tangent_cut(cone, &(&cone.offset + &cone.matrix * reference)))
            .collect();
        let mut warm = warm.clone();
        let mut mu = mu_hint;
        let mut steps = 0;
        loop {
            let inner = self.proximal_solve(&cuts, warm, mu, deadline, &mut steps)?;
            let broken: Vec<Row> = self
                .cones
                .iter()
                .filter_map(|cone| {
                    let v = &cone.offset + &cone.matrix * &inner.sol.x;
                    (v.norm() > cone.radius + CONE_TOLERANCE)
                        .then(|| tangent_cut(cone, &v))
                        .flatten()
                })
                .collect();
            if broken.is_empty() || cuts.len() + broken.len() > MAX_CONE_CUTS * self.cones.len() {
                return Ok(self.active_set_solution(inner, cuts.len(), steps));
            }
            warm = inner.sol.warm_start();
            mu = inner.mu;
            cuts.extend(broken);
        }
    }

    /// The rows (inequalities, then cuts; caps at the penalties) and the
    /// centre of the problem with proximal weight `mu`; the caps are scaled
    /// by [`cap_scale`] to the active-set solver's `½|x - c_μ|² + Σ u s`.
    fn active_set_rows(&self, cuts: &[Row]) -> Vec<Row> {
        self.inequalities
            .iter()
            .map(|ineq| Row {
                a: ineq.a.clone(),
                b: ineq.b,
                cap: ineq.penalty,
            })
            .chain(cuts.iter().cloned())
            .collect()
    }

    /// The cost centre `(c + μ z_k) / (1 + μ)` with proximal weight `mu`.
    fn proximal_centre(&self, mu: f64) -> DVector<f64> {
        match &self.trust {
            Some((zk, _)) if mu > 0.0 => (&self.center + zk * mu) / (1.0 + mu),
            _ => self.center.clone(),
        }
    }

    /// The optimum within the trust ball, to within [`TRUST_FILL`]`Δ ..
    /// (1 + `[`TRUST_OVERSHOOT`]`)Δ` of its radius: the first solve at
    /// `mu_hint` (the previous QP's multiplier), then a safeguarded secant
    /// search on `1/|z(μ) - z_k|` (linear in `μ` while the row states stay)
    /// with the unconstrained model `|z(μ) - z_k| ∝ 1/(1 + μ)` until the
    /// target is bracketed; each solve warm-started from the last.
    fn proximal_solve(
        &self,
        cuts: &[Row],
        warm: das::WarmStart,
        mu_hint: f64,
        deadline: Option<Instant>,
        steps: &mut usize,
    ) -> Result<Proximal, QpFailure> {
        let rows = self.active_set_rows(cuts);
        let mut solve_at = |mu: f64, warm: &das::WarmStart| -> Result<Proximal, QpFailure> {
            let settings = das::Settings {
                cap_scale: cap_scale(mu),
                deadline,
                ..das::Settings::default()
            };
            let sol = das::solve(&self.proximal_centre(mu), &rows, &settings, warm)
                .map_err(active_set_failure)?;
            *steps += sol.steps;
            Ok(Proximal { sol, mu })
        };
        let Some((zk, radius)) = &self.trust else {
            return solve_at(0.0, &warm);
        };
        let step = |p: &Proximal| (&p.sol.x - zk).norm();
        let mut last = solve_at(bounded_weight(mu_hint), &warm)?;
        // (μ, step) of the largest μ whose step is too long, and of the
        // smallest whose step is too short.
        let mut lo: Option<(f64, f64)> = None;
        let mut hi: Option<(f64, f64)> = None;
        for _ in 0..MAX_PROXIMAL_SOLVES {
            let d = step(&last);
            if d > (1.0 + TRUST_OVERSHOOT) * radius {
                lo = Some((last.mu, d));
            } else if d >= TRUST_FILL * radius || last.mu == 0.0 {
                return Ok(last);
            } else {
                hi = Some((last.mu, d));
            }
            if last.mu >= MAX_PROXIMAL_WEIGHT {
                return Ok(last);
            }
            let mu = next_mu(lo, hi, *radius);
            let mu = if mu.is_nan() {
                MAX_PROXIMAL_WEIGHT
            } else {
                mu.clamp(0.0, MAX_PROXIMAL_WEIGHT)
            };
            last = solve_at(mu, &last.sol.warm_start())?;
        }
        Ok(last)
    }

    /// The [`QpSolution`] of an active-set solve: slacks and objective of
    /// the original problem (exact cones), duals on Clarabel's scale.
    fn active_set_solution(&self, inner: Proximal, n_cuts: usize, steps: usize) -> QpSolution {
        let z = inner.sol.x;
        let inequality_slacks: Vec<f64> = self
            .inequalities
            .iter()
            .map(|ineq| {
                ineq.penalty
                    .map_or(0.0, |_| (ineq.a.dot(&z) - ineq.b).max(0.0))
            })
            .collect();
        let cone_slacks: Vec<f64> = self
            .cones
            .iter()
            .map(|c| ((&c.offset + &c.matrix * &z).norm() - c.radius).max(0.0))
            .collect();
        let objective = (&z - &self.center).norm_squared()
            + self
                .inequalities
                .iter()
                .zip(&inequality_slacks)
                .map(|(ineq, s)| ineq.penalty.unwrap_or(0.0) * s)
                .sum::<f64>()
            + self
                .cones
                .iter()
                .zip(&cone_slacks)
                .map(|(c, s)| c.penalty * s)
                .sum::<f64>();
        let dual_scale = 2.0 * (1.0 + inner.mu);
        let m = self.inequalities.len();
        let row_states = das::WarmStart {
            saturated: inner
                .sol
                .saturated
                .iter()
                .copied()
                .filter(|&i| i < m)
                .collect(),
            active: inner
                .sol
                .active
                .iter()
                .copied()
                .filter(|&i| i < m)
                .collect(),
        };
        QpSolution {
            row_states: Some(row_states),
            proximal_weight: inner.mu,
            inequality_duals: inner.sol.multipliers[..self.inequalities.len()]
                .iter()
                .map(|l| l * dual_scale)
                .collect(),
            rows: self.inequalities.len() + n_cuts,
            variables: z.len(),
            z,
            inequality_slacks,
            cone_slacks,
            objective,
            ipm_iterations: 0,
            active_set_steps: steps,
            clarabel: None,
        }
    }
}

/// A proximal weight in `[0, MAX_PROXIMAL_WEIGHT]` (NaN, the model's
/// answer to a trust radius of 0, counts as the largest).
fn bounded_weight(mu: f64) -> f64 {
    if mu.is_nan() {
        MAX_PROXIMAL_WEIGHT
    } else {
        mu.clamp(0.0, MAX_PROXIMAL_WEIGHT)
    }
}

/// The caps' scale with proximal weight `mu`: `|z - c|² + μ|z - z_k|² + Σρ s`
/// is `2 (1 + μ)` times `½|z - c_μ|² + Σ ρ / (2 (1 + μ)) s`.
fn cap_scale(mu: f64) -> f64 {
    1.0 / (2.0 * (1.0 + mu))
}

/// The next proximal weight to try, aiming at a step of `radius`: the
/// secant on `1/step` inside a bracket (bisection when it lands near an
/// end), else the unconstrained model from the nearer side.
fn next_mu(lo: Option<(f64, f64)>, hi: Option<(f64, f64)>, radius: f64) -> f64 {
    let model = |(mu, d): (f64, f64)| ((1.0 + mu) * d / radius - 1.0).max(0.0);
    match (lo, hi) {
        (Some((m_lo, d_lo)), Some((m_hi, d_hi))) => {
            let (i_lo, i_hi) = (1.0 / d_lo, 1.0 / d_hi.max(f64::MIN_POSITIVE));
            let secant = m_lo + (m_hi - m_lo) * (1.0 / radius - i_lo) / (i_hi - i_lo);
            let width = m_hi - m_lo;
            if secant > m_lo + 0.1 * width && secant < m_hi - 0.1 * width {
                secant
            } else {
                0.5 * (m_lo + m_hi)
            }
        }
        // Too long only: the model underestimates μ when rows saturate, so
        // at least double it.
        (Some(l), None) => model(l).max(2.0 * l.0 + 1.0),
        // Too short only: the model, never below 0.
        (None, Some(h)) => model(h).min(0.5 * h.0),
        (None, None) => 0.0,
    }
}

/// The soft half-space `n̂·(offset + M z) ≤ r` tangent to `cone` in the
/// direction of `v` (none when `v` is 0: every direction is as good, and
/// the cone holds there).
fn tangent_cut(cone: &Cone, v: &DVector<f64>) -> Option<Row> {
    let norm = v.norm();
    (norm > 0.0).then(|| {
        let n = v / norm;
        Row {
            a: cone.matrix.tr_mul(&n),
            b: cone.radius - n.dot(&cone.offset),
            cap: Some(cone.penalty),
        }
    })
}

fn active_set_failure(f: das::Failure) -> QpFailure {
    match f {
        das::Failure::Infeasible { .. } => QpFailure::Infeasible,
        das::Failure::MaxSteps => QpFailure::Numerical("active set: step limit reached".into()),
        das::Failure::OutOfTime => QpFailure::OutOfTime,
        das::Failure::BadInput(what) => QpFailure::Numerical(format!("active set: {what}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_proximal_weight_never_scales_the_caps_to_zero() {
        // A trust radius of almost nothing asks the model for an overflowing
        // weight; bounded, the caps keep a positive scale.
        for radius in [1e-300, f64::MIN_POSITIVE, 0.0] {
            let asked = next_mu(Some((1e300, 1.0)), None, radius);
            let mu = bounded_weight(asked);
            assert!((0.0..=MAX_PROXIMAL_WEIGHT).contains(&mu), "{asked} -> {mu}");
            assert!(cap_scale(mu) > 0.0 && cap_scale(mu).is_finite());
        }
        assert_eq!(bounded_weight(f64::NAN), MAX_PROXIMAL_WEIGHT);
        assert_eq!(bounded_weight(-1.0), 0.0);
        assert_eq!(bounded_weight(3.0), 3.0);
        assert_eq!(cap_scale(f64::INFINITY), 0.0, "what the bound prevents");
    }
}
