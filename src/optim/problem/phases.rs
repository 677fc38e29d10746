//! The trajectory as an affine function of the whitened coordinates at a
//! set of times: the `k`-th time derivative of joint `j` at time fraction
//! `τ_p` (position, velocity, acceleration, jerk) is a fixed combination of
//! the basis derivatives there, applied to `w_j`, with `w = μ + L z`, so
//! each one is a row `a·z + c`.
//!
//! **Timing.** The ProMP gives the path as a function of the phase `s`;
//! the [`TimeWarp`] says when the robot is where: `q(t) = Ψ(s(t/T)) w`. With
//! `boundary: free` the phase runs at constant speed, `s = τ` (the paper's
//! timing). With `boundary: rest` it ramps up over the first quarter of the
//! time (smoothstep speed), runs at constant speed `4/3`, and ramps down
//! over the last quarter ([`TimeWarp::Ramped`]): `ds/dτ` and `d²s/dτ²`
//! vanish at both ends, so every trajectory starts and ends with zero
//! velocity and acceleration, for any weights, without a constraint row and
//! without moving the path (positions, clearance, goal) by a millimetre. By the
//! chain rule (`s_k = dᵏs/dτᵏ`):
//! `q̇ = ψ⁽¹⁾ s₁ w / T`, `q̈ = (ψ⁽²⁾ s₁² + ψ⁽¹⁾ s₂) w / T²`,
//! `q⃛ = (ψ⁽³⁾ s₁³ + 3 ψ⁽²⁾ s₁ s₂ + ψ⁽¹⁾ s₃) w / T³`.
//!
//! The optimisation set starts as the request's `n_samples` grid and grows
//! by the phases that dense verification flags.

use crate::optim::problem::whiten::Whitening;
use crate::promp::Basis;
use nalgebra::{DMatrix, DVector};

/// Which time derivative of the joint trajectory a row is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Derivative {
    /// `q` (rad).
    Position = 0,
    /// `dq/dt` (rad/s).
    Velocity = 1,
    /// `d²q/dt²` (rad/s²).
    Acceleration = 2,
    /// `d³q/dt³` (rad/s³).
    Jerk = 3,
}

impl Derivative {
    /// All four, in order.
    pub const ALL: [Derivative; 4] = [
        Derivative::Position,
        Derivative::Velocity,
        Derivative::Acceleration,
        Derivative::Jerk,
    ];

    /// The order of the derivative (0 to 3).
    pub fn order(self) -> usize {
        self as usize
    }

    /// The word a message uses.
    pub fn name(self) -> &'static str {
        match self {
            Derivative::Position => "position",
            Derivative::Velocity => "velocity",
            Derivative::Acceleration => "acceleration",
            Derivative::Jerk => "jerk",
        }
    }
}

/// How the phase of the ProMP advances with time (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TimeWarp {
    /// `s = τ`: the ends move at whatever speed the weights give.
    Identity,
    /// `s = 10τ³ − 15τ⁴ + 6τ⁵`: rest at both ends.
    MinimumJerk,
    /// Rest at both ends by ramps over the first and last [`RAMP`] of the
    /// time: `ds/dτ = v·m(τ/RAMP)` with the smoothstep `m(x) = 3x² − 2x³`,
    /// then constant `v = 1 / (1 − RAMP)` in between (a trapezoid with
    /// smooth corners: `s` is C², its jerk is bounded).
    #[default]
    Ramped,
}

/// Fraction of the duration each ramp of [`TimeWarp::Ramped`] takes.
pub const RAMP: f64 = 0.25;

/// `[s, ds/dτ, d²s/dτ², d³s/dτ³]` of the start ramp of
/// [`TimeWarp::Ramped`] at `tau` in `[0, RAMP]`.
fn ramp(tau: f64) -> [f64; 4] {
    let v = 1.0 / (1.0 - RAMP);
    let x = tau / RAMP;
    [
        v * RAMP * (x * x * x - 0.5 * x * x * x * x),
        v * x * x * (3.0 - 2.0 * x),
        v * 6.0 * x * (1.0 - x) / RAMP,
        v * (6.0 - 12.0 * x) / (RAMP * RAMP),
    ]
}

impl TimeWarp {
    /// `[s, ds/dτ, d²s/dτ², d³s/dτ³]` at `tau` in [0, 1].
    pub fn at(self, tau: f64) -> [f64; 4] {
        match self {
            TimeWarp::Identity => [tau, 1.0, 0.0, 0.0],
            TimeWarp::MinimumJerk => {
                let (t2, t3) = (tau * tau, tau * tau * tau);
                [
                    t3 * (10.0 - 15.0 * tau + 6.0 * t2),
                    30.0 * t2 * (1.0 - tau) * (1.0 - tau),
                    60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau),
                    60.0 * (1.0 - 6.0 * tau + 6.0 * t2),
                ]
            }
            TimeWarp::Ramped if tau < RAMP => ramp(tau),
            TimeWarp::Ramped if tau > 1.0 - RAMP => {
                let [s, s1, s2, s3] = ramp(1.0 - tau);
                [1.0 - s, s1, -s2, s3]
            }
            TimeWarp::Ramped => {
                let v = 1.0 / (1.0 - RAMP);
                [0.5 * v * RAMP + v * (tau - RAMP), v, 0.0, 0.0]
            }
        }
    }

    /// The basis rows of the trajectory's time derivatives at time fraction
    /// `tau` of a `duration`-second motion: index `k` maps the weights of
    /// one joint to `dᵏq/dtᵏ` (chain rule, module docs).
    pub fn time_rows(self, basis: &Basis, tau: f64, duration: f64) -> [DVector<f64>; 4] {
        let [s, s1, s2, s3] = self.at(tau);
        let [p0, p1, p2, p3] = basis.rows_at(s);
        let t = duration;
        // Element by element: one allocation per row, no temporaries.
        let n = p0.len();
        let v = DVector::from_fn(n, |i, _| p1[i] * (s1 / t));
        let a = DVector::from_fn(n, |i, _| (p2[i] * (s1 * s1) + p1[i] * s2) / (t * t));
        let j = DVector::from_fn(n, |i, _| {
            (p3[i] * (s1 * s1 * s1) + p2[i] * (3.0 * s1 * s2) + p1[i] * s3) / (t * t * t)
        });
        [p0, v, a, j]
    }
}

/// Basis rows (and their whitened constraint rows) at a set of phases.
#[derive(Clone, Debug)]
pub struct PhaseRows {
    n_joints: usize,
    n_basis: usize,
    duration: f64,
    warp: TimeWarp,
    phases: Vec<f64>,
    /// `basis[k][p]`: the basis row of `dᵏq/dtᵏ` at `τ_p` ([`TimeWarp::time_rows`]).
    basis: [Vec<DVector<f64>>; 4],
    /// `rows[k][p * n_joints + j]`: `∂(dᵏq_j/dtᵏ)(z_p)/∂z`.
    rows: [Vec<DVector<f64>>; 4],
    /// L1 norms of `rows` (how far a row can move per unit of trust region).
    l1: [Vec<f64>; 4],
    /// Clearance (m) the optimiser keeps at each phase beyond the
    /// request's: zero, except where the verification found the trajectory
    /// too close between the phases ([`PhaseRows::raise_margin`]).
    margins: Vec<f64>,
    /// Per joint, the columns of the whitening factor where its rows are
    /// not zero ([`nonzero_columns`]): a row is computed on those only (a
    /// smoothness prior's factor is block diagonal, a learned one lower
    /// triangular).
    columns: Vec<std::ops::Range<usize>>,
}

/// Per joint `j`, the smallest column range holding every non-zero entry
/// of rows `j·n_basis .. (j+1)·n_basis` of `factor` (empty for zero rows).
fn nonzero_columns(
    factor: &nalgebra::DMatrix<f64>,
    n_joints: usize,
    n_basis: usize,
) -> Vec<std::ops::Range<usize>> {
    (0..n_joints)
        .map(|j| {
            let block = factor.rows(j * n_basis, n_basis);
            let used = |c: &usize| block.column(*c).iter().any(|x| *x != 0.0);
            let first = (0..block.ncols()).find(used).unwrap_or(0);
            let end = (0..block.ncols()).rev().find(used).map_or(first, |c| c + 1);
            first..end
        })
        .collect()
}

impl PhaseRows {
    /// Rows at time fractions `phases` for `n_joints` joints of `basis`,
    /// time derivatives for a motion of `duration` seconds timed by `warp`.
    pub fn new(
        basis: &Basis,
        whitening: &Whitening,
        n_joints: usize,
        (duration, warp): (f64, TimeWarp),
        phases: &[f64],
    ) -> PhaseRows {
        let mut rows = PhaseRows {
            n_joints,
            n_basis: basis.n_basis(),
            duration,
            warp,
            phases: Vec::new(),
            basis: Default::default(),
            rows: Default::default(),
            l1: Default::default(),
            margins: Vec::new(),
            columns: nonzero_columns(whitening.factor(), n_joints, basis.n_basis()),
        };
        for &p in phases {
            rows.push(basis, whitening, p);
        }
        rows
    }

    /// Add one phase (no-op when it is already present to 1e-12); returns
    /// its index. `whitening` is the one [`PhaseRows::new`] was given (its
    /// zero pattern is read there).
    pub fn push(&mut self, basis: &Basis, whitening: &Whitening, phase: f64) -> usize {
        if let Some(i) = self.phases.iter().position(|p| (p - phase).abs() < 1e-12) {
            return i;
        }
        let l = whitening.factor();
        let nb = self.n_basis;
        for (k, psi) in self
            .warp
            .time_rows(basis, phase, self.duration)
            .into_iter()
            .enumerate()
        {
            for j in 0..self.n_joints {
                let cols = self.columns[j].clone();
                let mut row = DVector::zeros(l.ncols());
                row.rows_mut(cols.start, cols.len())
                    .copy_from(&l.view((j * nb, cols.start), (nb, cols.len())).tr_mul(&psi));
                self.l1[k].push(row.lp_norm(1));
                self.rows[k].push(row);
            }
            self.basis[k].push(psi);
        }
        self.phases.push(phase);
        self.margins.push(0.0);
        self.phases.len() - 1
    }

    /// The extra clearance (m) kept at phase `p`.
    pub fn margin(&self, p: usize) -> f64 {
        self.margins[p]
    }

    /// Raise phase `p`'s extra clearance by `by` (m), to at most `cap`;
    /// returns whether it changed.
    pub fn raise_margin(&mut self, p: usize, by: f64, cap: f64) -> bool {
        let raised = (self.margins[p] + by).min(cap);
        let changed = raised > self.margins[p];
        if changed {
            self.margins[p] = raised;
        }
        changed
    }

    /// Number of phases.
    pub fn len(&self) -> usize {
        self.phases.len()
    }

    /// Whether there is no phase.
    pub fn is_empty(&self) -> bool {
        self.phases.is_empty()
    }

    /// The phases, in insertion order.
    pub fn phases(&self) -> &[f64] {
        &self.phases
    }

    /// Duration of the motion (s).
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// `∂(dᵏq_j/dtᵏ)/∂z` at phase index `p`.
    pub fn row(&self, d: Derivative, p: usize, j: usize) -> &DVector<f64> {
        &self.rows[d.order()][p * self.n_joints + j]
    }

    /// `|∂(dᵏq_j/dtᵏ)/∂z|₁` at phase index `p`.
    pub fn row_l1(&self, d: Derivative, p: usize, j: usize) -> f64 {
        self.l1[d.order()][p * self.n_joints + j]
    }

    /// `∂q_j/∂z` at phase index `p`.
    pub fn position_row(&self, p: usize, j: usize) -> &DVector<f64> {
        self.row(Derivative::Position, p, j)
    }

    /// Number of joints.
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// `∂q/∂z` at phase index `p` (`n_joints x dim z`).
    pub fn position_jacobian(&self, p: usize) -> DMatrix<f64> {
        let pos = &self.rows[0];
        let n = pos.first().map_or(0, |r| r.len());
        DMatrix::from_fn(self.n_joints, n, |j, c| pos[p * self.n_joints + j][c])
    }

    /// `∂q/∂z · z` at phase index `p`: the joint positions' part linear in
    /// the whitened weights `z` (the positions less the prior mean's).
    pub fn linear_position(&self, p: usize, z: &DVector<f64>) -> DVector<f64> {
        DVector::from_fn(self.n_joints, |j, _| self.position_row(p, j).dot(z))
    }

    /// `(∂q/∂z)ᵀ g` at phase index `p`: a joint-space gradient `g` (one
    /// entry per joint) as a gradient over the whitened weights.
    pub fn position_gradient(&self, p: usize, g: &DVector<f64>) -> DVector<f64> {
        let mut out = DVector::zeros(self.position_row(p, 0).len());
        for (j, gj) in g.iter().enumerate() {
            out.axpy(*gj, self.position_row(p, j), 1.0);
        }
        out
    }

    /// Joint positions at phase index `p` for weights `w`.
    pub fn position(&self, p: usize, w: &DVector<f64>) -> Vec<f64> {
        self.values(Derivative::Position, p, w)
    }

    /// The `d` derivative of every joint at phase index `p` for weights `w`.
    pub fn values(&self, d: Derivative, p: usize, w: &DVector<f64>) -> Vec<f64> {
        (0..self.n_joints).map(|j| self.value(d, p, j, w)).collect()
    }

    /// The `d` derivative of joint `j` at phase index `p` for weights `w`.
    pub fn value(&self, d: Derivative, p: usize, j: usize, w: &DVector<f64>) -> f64 {
        let nb = self.n_basis;
        self.basis[d.order()][p].dot(&w.rows(j * nb, nb))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::example_distribution;
    use crate::promp::{PrompConfig, WeightDistribution};
    use nalgebra::DMatrix;

    #[test]
    fn a_phase_is_added_once_and_its_margin_rises_to_the_cap() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 5).unwrap();
        let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
        let mut rows = PhaseRows::new(&basis, &wh, 7, (4.0, TimeWarp::Ramped), &[0.0, 0.5]);
        assert_eq!(rows.push(&basis, &wh, 0.25), 2);
        assert_eq!(rows.push(&basis, &wh, 0.5 + 1e-13), 1, "present to 1e-12");
        assert_eq!(rows.len(), 3);
        assert!((0..3).all(|p| rows.margin(p) == 0.0));
        assert!(rows.raise_margin(2, 0.002, 0.005));
        assert!(rows.raise_margin(2, 0.002, 0.005));
        assert_eq!(rows.margin(2), 0.004);
        assert!(rows.raise_margin(2, 0.002, 0.005), "raised to the cap");
        assert_eq!(rows.margin(2), 0.005);
        assert!(!rows.raise_margin(2, 0.002, 0.005), "at the cap: unchanged");
        assert!(
            !rows.raise_margin(0, 0.0, 0.005),
            "a zero deficit changes nothing"
        );
        assert_eq!((rows.margin(0), rows.margin(1)), (0.0, 0.0));
    }

    /// Rows computed on the factor's non-zero columns only equal the full
    /// product bit for bit, for a dense (lower-triangular) factor and a
    /// block-diagonal one (independent joints), whose rows use only their
    /// own joint's columns.
    #[test]
    fn rows_on_the_nonzero_columns_equal_the_full_product() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let nb = basis.n_basis();
        let dense = example_distribution(&basis, 20, 5).unwrap();
        let blocks: Vec<DMatrix<f64>> = (0..7)
            .map(|j| dense.cov.view((j * nb, j * nb), (nb, nb)).into_owned())
            .collect();
        let means: Vec<DVector<f64>> = (0..7).map(|j| dense.mean.rows(j * nb, nb).into()).collect();
        let diagonal = WeightDistribution::from_joint_blocks(&means, &blocks).unwrap();
        for (dist, block_diagonal) in [(dense, false), (diagonal, true)] {
            let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
            let phases = [0.0, 0.17, 0.5, 0.93, 1.0];
            let rows = PhaseRows::new(&basis, &wh, 7, (3.0, TimeWarp::Ramped), &phases);
            for j in 0..7 {
                let expected = if block_diagonal { j * nb } else { 0 }..(j + 1) * nb;
                assert_eq!(rows.columns[j], expected, "joint {j}");
            }
            for d in Derivative::ALL {
                for p in 0..phases.len() {
                    for j in 0..7 {
                        let full = wh
                            .factor()
                            .rows(j * nb, nb)
                            .tr_mul(&rows.basis[d.order()][p]);
                        assert_eq!(rows.row(d, p, j), &full, "{d:?} phase {p} joint {j}");
                    }
                }
            }
        }
    }

    #[test]
    fn rows_reproduce_every_derivative_of_the_weights() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 5).unwrap();
        let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
        let rows = PhaseRows::new(&basis, &wh, 7, (4.0, TimeWarp::Identity), &[0.0, 0.31, 1.0]);
        let z = DVector::from_fn(wh.dim(), |i, _| (i as f64 * 0.37).sin());
        let w = wh.weights(&z);
        let w0 = wh.weights(&DVector::zeros(wh.dim()));
        for d in Derivative::ALL {
            for p in 0..rows.len() {
                for j in 0..7 {
                    let affine = rows.value(d, p, j, &w0) + rows.row(d, p, j).dot(&z);
                    let direct = rows.value(d, p, j, &w);
                    assert!(
                        (affine - direct).abs() < 1e-9 * (1.0 + direct.abs()),
                        "{d:?}"
                    );
                }
            }
        }
        // Each derivative = central difference of the one below / duration,
        // with either timing.
        let eps = 1e-5;
        for warp in [TimeWarp::Identity, TimeWarp::MinimumJerk, TimeWarp::Ramped] {
            for tau in [0.03, 0.2, 0.5, 0.93] {
                let taus = [tau - eps, tau, tau + eps];
                let r = PhaseRows::new(&basis, &wh, 7, (4.0, warp), &taus);
                for (lower, upper) in Derivative::ALL.into_iter().zip(&Derivative::ALL[1..]) {
                    let (a, b) = (r.values(lower, 0, &w), r.values(lower, 2, &w));
                    let v = r.values(*upper, 1, &w);
                    for j in 0..7 {
                        let fd = (b[j] - a[j]) / (2.0 * eps) / 4.0;
                        let tol = 1e-4 * (1.0 + v[j].abs());
                        assert!((fd - v[j]).abs() < tol, "{warp:?} {upper:?} joint {j}");
                    }
                }
            }
        }
        // The resting timings rest at both ends, whatever the weights, and
        // keep the path's end points.
        for warp in [TimeWarp::MinimumJerk, TimeWarp::Ramped] {
            let ends = PhaseRows::new(&basis, &wh, 7, (4.0, warp), &[0.0, 1.0]);
            for p in 0..2 {
                for d in [Derivative::Velocity, Derivative::Acceleration] {
                    assert!(ends.values(d, p, &w).iter().all(|v| v.abs() < 1e-12));
                }
                assert_eq!(ends.position(p, &w), rows.position(2 * p, &w));
            }
        }
        let mean = dist.trajectory_mean(&basis);
        let q_end = rows.position(2, &w0);
        assert!((q_end[3] - mean[(149, 3)]).abs() < 1e-9);
    }

    /// `linear_position` is `J z` and `position_gradient` is `Jᵀ g` for the
    /// phase's position Jacobian `J`, built independently as a matrix.
    #[test]
    fn the_position_products_match_the_jacobian() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 5).unwrap();
        let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
        let phases = [0.0, 0.27, 0.8];
        let rows = PhaseRows::new(&basis, &wh, 7, (4.0, TimeWarp::MinimumJerk), &phases);
        let z = DVector::from_fn(wh.dim(), |i, _| (i as f64 * 0.61).cos());
        let g = DVector::from_fn(7, |j, _| j as f64 - 2.5);
        for p in 0..phases.len() {
            let jac = rows.position_jacobian(p);
            let (jz, jtg) = (&jac * &z, jac.tr_mul(&g));
            let qz = rows.linear_position(p, &z);
            let grad = rows.position_gradient(p, &g);
            assert!((qz - &jz).amax() < 1e-12 * (1.0 + jz.amax()));
            assert!((grad - &jtg).amax() < 1e-12 * (1.0 + jtg.amax()));
        }
    }
}

#[cfg(test)]
mod warp_tests {
    use super::*;

    #[test]
    fn every_timing_runs_from_0_to_1_with_its_derivatives_consistent() {
        for warp in [TimeWarp::Identity, TimeWarp::MinimumJerk, TimeWarp::Ramped] {
            assert!(warp.at(0.0)[0].abs() < 1e-15 && (warp.at(1.0)[0] - 1.0).abs() < 1e-15);
            let h = 1e-6;
            for k in 1..200 {
                let tau = k as f64 / 200.0;
                let (a, b, c) = (warp.at(tau - h), warp.at(tau), warp.at(tau + h));
                for order in 0..3 {
                    let fd = (c[order] - a[order]) / (2.0 * h);
                    let scale = 1.0 + b[order + 1].abs();
                    // s''' jumps at the ramp ends of the ramped timing.
                    let at_jump =
                        order == 2 && [RAMP, 1.0 - RAMP].iter().any(|j| (tau - j).abs() < 2.0 * h);
                    assert!(
                        at_jump || (fd - b[order + 1]).abs() < 1e-4 * scale,
                        "{warp:?} τ {tau} order {order}"
                    );
                }
                assert!(b[1] >= 0.0, "{warp:?}: the phase never runs backwards");
            }
        }
    }
}
