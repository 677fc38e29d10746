//! The constraints that are linear in the whitened weights: joint position
//! limits (minus the margin) and velocity limits at the optimisation
//! phases, start / final configuration equalities, and the opt-in weight
//! bounds. They enter every QP as hard rows.
//!
//! Only rows that can become active are sent to Clarabel: a row whose value
//! at the current iterate plus its L1 norm times the trust-region radius
//! stays below its bound cannot be violated by any step in the box. Without
//! a trust region the rows near the bound are sent and the rest are checked
//! afterwards ([`LinearSet::violated`]) and added if needed.

use super::phases::PhaseRows;
use super::qp::Inequality;
use nalgebra::DVector;

/// Row screening margin (rad or rad/s) when there is no trust region.
pub const SCREEN_MARGIN: f64 = 0.05;

/// Largest slack (rad) of a position row sent by [`LinearSet::screen_banded`].
pub const SCREEN_BAND_POSITION: f64 = 0.2;
/// Largest slack of a velocity row sent by [`LinearSet::screen_banded`], as a
/// fraction of the velocity limit.
pub const SCREEN_BAND_VELOCITY: f64 = 0.2;

/// Which bound a row expresses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RowKind {
    /// `q_j <= upper_j`.
    PositionUpper,
    /// `q_j >= lower_j`.
    PositionLower,
    /// `dq_j/dt <= v_j`.
    VelocityUpper,
    /// `dq_j/dt >= -v_j`.
    VelocityLower,
}

/// One trajectory row: phase index, joint, kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RowRef {
    /// Index into [`PhaseRows`].
    pub phase: usize,
    /// Joint index.
    pub joint: usize,
    /// Bound.
    pub kind: RowKind,
}

/// Joint bounds as the optimiser uses them (margin already applied).
#[derive(Clone, Debug)]
pub struct LinearSet {
    /// Lower position bound per joint.
    pub lower: Vec<f64>,
    /// Upper position bound per joint.
    pub upper: Vec<f64>,
    /// Velocity bound per joint (rad/s).
    pub velocity: Vec<f64>,
    /// Required configuration at phase 0.
    pub start: Option<Vec<f64>>,
    /// Required configuration at phase 1.
    pub final_configuration: Option<Vec<f64>>,
    /// Also bound every weight by its joint's position limits.
    pub bound_weights: bool,
}

impl LinearSet {
    /// Signed excess `value - bound` of one row for weights `w` (> 0 = violated).
    pub fn excess(&self, rows: &PhaseRows, w: &DVector<f64>, r: RowRef) -> f64 {
        let j = r.joint;
        match r.kind {
            RowKind::PositionUpper => rows.joint_position(r.phase, j, w) - self.upper[j],
            RowKind::PositionLower => self.lower[j] - rows.joint_position(r.phase, j, w),
            RowKind::VelocityUpper => rows.joint_velocity(r.phase, j, w) - self.velocity[j],
            RowKind::VelocityLower => -self.velocity[j] - rows.joint_velocity(r.phase, j, w),
        }
    }

    /// The row as `a·z <= b` given the weights at `z = 0` (the prior mean).
    pub fn inequality(&self, rows: &PhaseRows, mean: &DVector<f64>, r: RowRef) -> Inequality {
        let excess0 = self.excess(rows, mean, r);
        let a = match r.kind {
            RowKind::PositionUpper => rows.position_row(r.phase, r.joint).clone(),
            RowKind::PositionLower => -rows.position_row(r.phase, r.joint),
            RowKind::VelocityUpper => rows.velocity_row(r.phase, r.joint).clone(),
            RowKind::VelocityLower => -rows.velocity_row(r.phase, r.joint),
        };
        Inequality {
            a,
            b: -excess0,
            penalty: None,
        }
    }

    /// How far a row can move per unit of trust-region radius.
    fn row_l1(rows: &PhaseRows, r: RowRef) -> f64 {
        match r.kind {
            RowKind::PositionUpper | RowKind::PositionLower => {
                rows.position_row_l1(r.phase, r.joint)
            }
            RowKind::VelocityUpper | RowKind::VelocityLower => {
                rows.velocity_row_l1(r.phase, r.joint)
            }
        }
    }

    /// Every row of `rows`.
    pub fn all_rows(rows: &PhaseRows) -> impl Iterator<Item = RowRef> + '_ {
        let kinds = [
            RowKind::PositionUpper,
            RowKind::PositionLower,
            RowKind::VelocityUpper,
            RowKind::VelocityLower,
        ];
        (0..rows.len()).flat_map(move |phase| {
            (0..rows.n_joints()).flat_map(move |joint| {
                kinds
                    .into_iter()
                    .map(move |kind| RowRef { phase, joint, kind })
            })
        })
    }

    /// Rows that a step within `radius` of `w` (the weights of the current
    /// iterate) could violate; `None` radius: rows within [`SCREEN_MARGIN`].
    pub fn screen(&self, rows: &PhaseRows, w: &DVector<f64>, radius: Option<f64>) -> Vec<RowRef> {
        Self::all_rows(rows)
            .filter(|&r| {
                let reach = radius.map_or(SCREEN_MARGIN, |d| d * Self::row_l1(rows, r) + 1e-9);
                self.excess(rows, w, r) + reach >= 0.0
            })
            .collect()
    }

    /// Like [`LinearSet::screen`], but a row also needs its slack within a
    /// fixed band ([`SCREEN_BAND_POSITION`] rad, [`SCREEN_BAND_VELOCITY`] of
    /// the velocity limit): rows far from their bound rarely become active
    /// in one step, and the caller adds any row a solution violates.
    pub fn screen_banded(
        &self,
        rows: &PhaseRows,
        w: &DVector<f64>,
        radius: Option<f64>,
    ) -> Vec<RowRef> {
        Self::all_rows(rows)
            .filter(|&r| {
                let band = match r.kind {
                    RowKind::PositionUpper | RowKind::PositionLower => SCREEN_BAND_POSITION,
                    RowKind::VelocityUpper | RowKind::VelocityLower => {
                        SCREEN_BAND_VELOCITY * self.velocity[r.joint]
                    }
                };
                let reach = radius
                    .map_or(SCREEN_MARGIN, |d| d * Self::row_l1(rows, r) + 1e-9)
                    .min(band);
                self.excess(rows, w, r) + reach >= 0.0
            })
            .collect()
    }

    /// Rows violated by more than `tolerance` at `w`.
    pub fn violated(&self, rows: &PhaseRows, w: &DVector<f64>, tolerance: f64) -> Vec<RowRef> {
        Self::all_rows(rows)
            .filter(|&r| self.excess(rows, w, r) > tolerance)
            .collect()
    }

    /// Equalities `a·z = b` for the start (phase index 0 of `ends`) and
    /// final (phase index 1) configurations.
    pub fn equalities(&self, ends: &PhaseRows, mean: &DVector<f64>) -> Vec<(DVector<f64>, f64)> {
        let mut out = Vec::new();
        for (p, target) in [(0, &self.start), (1, &self.final_configuration)] {
            if let Some(q) = target {
                let q0 = ends.position(p, mean);
                for j in 0..ends.n_joints() {
                    out.push((ends.position_row(p, j).clone(), q[j] - q0[j]));
                }
            }
        }
        out
    }

    /// Largest equality residual (rad) at `w`.
    pub fn equality_error(&self, ends: &PhaseRows, w: &DVector<f64>) -> f64 {
        let mut worst: f64 = 0.0;
        for (p, target) in [(0, &self.start), (1, &self.final_configuration)] {
            if let Some(q) = target {
                let at = ends.position(p, w);
                for (a, b) in at.iter().zip(q) {
                    worst = worst.max((a - b).abs());
                }
            }
        }
        worst
    }

    /// Weight-bound rows (opt-in): `lower_j <= w_{j,i} <= upper_j`, as
    /// `a·z <= b` through `w = μ + L z`.
    pub fn weight_bounds(
        &self,
        factor: &nalgebra::DMatrix<f64>,
        mean: &DVector<f64>,
        n_basis: usize,
    ) -> Vec<Inequality> {
        if !self.bound_weights {
            return Vec::new();
        }
        let mut out = Vec::new();
        for i in 0..mean.len() {
            let j = i / n_basis;
            let row = factor.row(i).transpose();
            out.push(Inequality {
                a: row.clone(),
                b: self.upper[j] - mean[i],
                penalty: None,
            });
            out.push(Inequality {
                a: -row,
                b: mean[i] - self.lower[j],
                penalty: None,
            });
        }
        out
    }

    /// Largest weight-bound excess at `w` (0 when the mode is off).
    pub fn weight_bound_excess(&self, w: &DVector<f64>, n_basis: usize) -> f64 {
        if !self.bound_weights {
            return 0.0;
        }
        w.iter()
            .enumerate()
            .map(|(i, &v)| {
                let j = i / n_basis;
                (v - self.upper[j]).max(self.lower[j] - v)
            })
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::whiten::Whitening;
    use crate::promp::{example::example_distribution, Basis, PrompConfig};

    #[test]
    fn rows_are_exact_and_screening_never_drops_a_row_a_step_could_violate() {
        let basis = Basis::new(&PrompConfig {
            n_samples: 30,
            ..Default::default()
        })
        .unwrap();
        let dist = example_distribution(&basis, 20, 2).unwrap();
        let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
        let rows = PhaseRows::new(&basis, &wh, 7, 4.0, basis.phases());
        let set = LinearSet {
            lower: vec![-2.0; 7],
            upper: vec![2.0; 7],
            velocity: vec![1.0; 7],
            start: None,
            final_configuration: None,
            bound_weights: false,
        };
        let n = wh.dim();
        let zk = DVector::from_fn(n, |i, _| (i as f64 * 1.3).cos() * 0.5);
        let wk = wh.weights(&zk);
        let radius = 0.7;
        let kept = set.screen(&rows, &wk, Some(radius));
        for r in LinearSet::all_rows(&rows) {
            let ineq = set.inequality(&rows, &dist.mean, r);
            // a·z - b equals the excess at any z.
            let lhs = ineq.a.dot(&zk) - ineq.b;
            assert!((lhs - set.excess(&rows, &wk, r)).abs() < 1e-9);
            if !kept.contains(&r) {
                // Worst corner of the box cannot violate it.
                let corner = DVector::from_fn(n, |i, _| zk[i] + radius * ineq.a[i].signum());
                assert!(ineq.a.dot(&corner) <= ineq.b + 1e-9);
            }
        }
        assert!(kept.len() < LinearSet::all_rows(&rows).count());
    }
}
