//! The trajectory as an affine function of the whitened coordinates at a
//! set of phases: `q_j(z_p) = ψ_pᵀ w_j` and `dq_j/dt = ψ'_pᵀ w_j / T_d`,
//! with `w = μ + L z`, so each joint position or velocity at a phase is one
//! row `a·z + c`.
//!
//! The optimisation set starts as the request's `n_samples` grid and grows
//! by the phases that dense verification flags.

use super::whiten::Whitening;
use crate::promp::Basis;
use nalgebra::{DMatrix, DVector};

/// Basis rows (and their whitened constraint rows) at a set of phases.
#[derive(Clone, Debug)]
pub struct PhaseRows {
    n_joints: usize,
    n_basis: usize,
    duration: f64,
    phases: Vec<f64>,
    psi: Vec<DVector<f64>>,
    dpsi: Vec<DVector<f64>>,
    /// Row `p * n_joints + j`: `∂q_j(z_p)/∂z`.
    pos: Vec<DVector<f64>>,
    /// Row `p * n_joints + j`: `∂(dq_j/dt)(z_p)/∂z`.
    vel: Vec<DVector<f64>>,
    /// L1 norms of `pos` and `vel` rows (how far a row can move per unit
    /// of trust region).
    pos_l1: Vec<f64>,
    vel_l1: Vec<f64>,
}

impl PhaseRows {
    /// Rows at `phases` for `n_joints` joints of `basis`, velocities for a
    /// motion of `duration` seconds.
    pub fn new(
        basis: &Basis,
        whitening: &Whitening,
        n_joints: usize,
        duration: f64,
        phases: &[f64],
    ) -> PhaseRows {
        let mut rows = PhaseRows {
            n_joints,
            n_basis: basis.n_basis(),
            duration,
            phases: Vec::new(),
            psi: Vec::new(),
            dpsi: Vec::new(),
            pos: Vec::new(),
            vel: Vec::new(),
            pos_l1: Vec::new(),
            vel_l1: Vec::new(),
        };
        for &p in phases {
            rows.push(basis, whitening, p);
        }
        rows
    }

    /// Add one phase (no-op when it is already present to 1e-12).
    pub fn push(&mut self, basis: &Basis, whitening: &Whitening, phase: f64) {
        if self.phases.iter().any(|p| (p - phase).abs() < 1e-12) {
            return;
        }
        let psi = basis.row_at(phase);
        let dpsi = basis.derivative_row_at(phase) / self.duration;
        let l = whitening.factor();
        let nb = self.n_basis;
        for j in 0..self.n_joints {
            let block = l.rows(j * nb, nb);
            let pos = block.tr_mul(&psi);
            let vel = block.tr_mul(&dpsi);
            self.pos_l1.push(pos.lp_norm(1));
            self.vel_l1.push(vel.lp_norm(1));
            self.pos.push(pos);
            self.vel.push(vel);
        }
        self.phases.push(phase);
        self.psi.push(psi);
        self.dpsi.push(dpsi);
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

    /// `∂q_j/∂z` at phase index `p`.
    pub fn position_row(&self, p: usize, j: usize) -> &DVector<f64> {
        &self.pos[p * self.n_joints + j]
    }

    /// `∂(dq_j/dt)/∂z` at phase index `p`.
    pub fn velocity_row(&self, p: usize, j: usize) -> &DVector<f64> {
        &self.vel[p * self.n_joints + j]
    }

    /// `|∂q_j/∂z|₁` at phase index `p`.
    pub fn position_row_l1(&self, p: usize, j: usize) -> f64 {
        self.pos_l1[p * self.n_joints + j]
    }

    /// `|∂(dq_j/dt)/∂z|₁` at phase index `p`.
    pub fn velocity_row_l1(&self, p: usize, j: usize) -> f64 {
        self.vel_l1[p * self.n_joints + j]
    }

    /// Number of joints.
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// `∂q/∂z` at phase index `p` (`n_joints x dim z`).
    pub fn position_jacobian(&self, p: usize) -> DMatrix<f64> {
        let n = self.pos.first().map_or(0, |r| r.len());
        DMatrix::from_fn(self.n_joints, n, |j, c| self.pos[p * self.n_joints + j][c])
    }

    /// Joint positions at phase index `p` for weights `w`.
    pub fn position(&self, p: usize, w: &DVector<f64>) -> Vec<f64> {
        self.apply(&self.psi[p], w)
    }

    /// Joint velocities (rad/s) at phase index `p` for weights `w`.
    pub fn velocity(&self, p: usize, w: &DVector<f64>) -> Vec<f64> {
        self.apply(&self.dpsi[p], w)
    }

    /// Position (rad) of joint `j` at phase index `p` for weights `w`.
    pub fn joint_position(&self, p: usize, j: usize, w: &DVector<f64>) -> f64 {
        self.apply_joint(&self.psi[p], j, w)
    }

    /// Velocity (rad/s) of joint `j` at phase index `p` for weights `w`.
    pub fn joint_velocity(&self, p: usize, j: usize, w: &DVector<f64>) -> f64 {
        self.apply_joint(&self.dpsi[p], j, w)
    }

    fn apply_joint(&self, row: &DVector<f64>, j: usize, w: &DVector<f64>) -> f64 {
        let nb = self.n_basis;
        row.dot(&w.rows(j * nb, nb))
    }

    fn apply(&self, row: &DVector<f64>, w: &DVector<f64>) -> Vec<f64> {
        (0..self.n_joints)
            .map(|j| self.apply_joint(row, j, w))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::promp::{example::example_distribution, PrompConfig};

    #[test]
    fn rows_reproduce_positions_and_velocities_of_the_weights() {
        let basis = Basis::new(&PrompConfig::default()).unwrap();
        let dist = example_distribution(&basis, 20, 5).unwrap();
        let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
        let rows = PhaseRows::new(&basis, &wh, 7, 4.0, &[0.0, 0.31, 1.0]);
        let z = DVector::from_fn(wh.dim(), |i, _| (i as f64 * 0.37).sin());
        let w = wh.weights(&z);
        let w0 = wh.weights(&DVector::zeros(wh.dim()));
        for p in 0..rows.len() {
            let q = rows.position(p, &w);
            let q0 = rows.position(p, &w0);
            let v = rows.velocity(p, &w);
            let v0 = rows.velocity(p, &w0);
            for j in 0..7 {
                assert!((q0[j] + rows.position_row(p, j).dot(&z) - q[j]).abs() < 1e-9);
                assert!((v0[j] + rows.velocity_row(p, j).dot(&z) - v[j]).abs() < 1e-9);
            }
        }
        // Velocity = central difference of positions / duration.
        let eps = 1e-6;
        let r = PhaseRows::new(&basis, &wh, 7, 4.0, &[0.5 - eps, 0.5, 0.5 + eps]);
        let (a, b) = (r.position(0, &w), r.position(2, &w));
        let v = r.velocity(1, &w);
        for j in 0..7 {
            let fd = (b[j] - a[j]) / (2.0 * eps) / 4.0;
            assert!((fd - v[j]).abs() < 1e-5 * (1.0 + v[j].abs()), "joint {j}");
        }
        let mean = dist.trajectory_mean(&basis);
        let q_end = rows.position(2, &w0);
        assert!((q_end[3] - mean[(149, 3)]).abs() < 1e-9);
    }
}
