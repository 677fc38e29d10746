//! The constraints that are linear in the whitened weights: joint position
//! limits (minus the margin) and velocity, acceleration and jerk limits at
//! the optimisation phases, start / final configuration equalities, rest at
//! both ends (velocity and acceleration zero), and the opt-in weight
//! bounds. They enter every QP as hard rows.
//!
//! Only rows that can become active are sent to Clarabel: a row whose value
//! at the current iterate plus its L1 norm times the trust-region radius
//! stays below its bound cannot be violated by any step in the box. Without
//! a trust region the rows near the bound are sent and the rest are checked
//! afterwards ([`LinearSet::violated`]) and added if needed.

use crate::optim::problem::phases::{Derivative, PhaseRows};
use crate::optim::qp::Inequality;
use nalgebra::DVector;

/// Row screening margin (rad or rad/s) when there is no trust region.
pub const SCREEN_MARGIN: f64 = 0.05;

/// Largest slack (rad) of a position row sent by [`LinearSet::screen_banded`].
pub const SCREEN_BAND_POSITION: f64 = 0.2;
/// Largest slack of a velocity, acceleration or jerk row sent by
/// [`LinearSet::screen_banded`], as a fraction of its limit.
pub const SCREEN_BAND_VELOCITY: f64 = 0.2;

/// Fraction of an acceleration or jerk limit the QP rows keep inside it:
/// an active limit peaks between two sampled phases, and this keeps the
/// peak within the limit at 10× the optimisation sampling too.
pub const RATE_BUFFER: f64 = 1e-3;

/// Which bound a row expresses: the upper or lower bound of one time
/// derivative of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RowKind {
    /// Position, velocity, acceleration or jerk.
    pub derivative: Derivative,
    /// `value <= bound` (else `value >= lower bound`).
    pub upper: bool,
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

/// Joint bounds as the optimiser uses them (margin and scaling applied).
#[derive(Clone, Debug)]
pub struct LinearSet {
    /// Lower position bound per joint.
    pub lower: Vec<f64>,
    /// Upper position bound per joint.
    pub upper: Vec<f64>,
    /// Velocity bound per joint (rad/s).
    pub velocity: Vec<f64>,
    /// Acceleration bound per joint (rad/s²), if any.
    pub acceleration: Option<Vec<f64>>,
    /// Jerk bound per joint (rad/s³), if any.
    pub jerk: Option<Vec<f64>>,
    /// Required configuration at phase 0.
    pub start: Option<Vec<f64>>,
    /// Required configuration at phase 1.
    pub final_configuration: Option<Vec<f64>>,
    /// Required configurations at waypoints: `(index in the ends rows,
    /// configuration)`.
    pub via: Vec<(usize, Vec<f64>)>,
    /// Velocity and acceleration zero at both ends (checked; the timing
    /// makes it hold).
    pub rest: bool,
    /// Also bound every weight by its joint's position limits.
    pub bound_weights: bool,
}

impl LinearSet {
    /// The symmetric bound of derivative `d` of joint `j` (velocity and
    /// above; `None` when that derivative is not limited).
    pub fn rate_bound(&self, d: Derivative, j: usize) -> Option<f64> {
        match d {
            Derivative::Position => None,
            Derivative::Velocity => Some(self.velocity[j]),
            Derivative::Acceleration => self.acceleration.as_ref().map(|a| a[j]),
            Derivative::Jerk => self.jerk.as_ref().map(|a| a[j]),
        }
    }

    /// The kinds of row this set has: position and velocity always,
    /// acceleration and jerk when limited.
    pub fn kinds(&self) -> Vec<RowKind> {
        self.derivatives()
            .into_iter()
            .flat_map(|derivative| [true, false].map(|upper| RowKind { derivative, upper }))
            .collect()
    }

    /// The derivatives this set bounds: position and velocity always,
    /// acceleration and jerk when limited.
    fn derivatives(&self) -> Vec<Derivative> {
        Derivative::ALL
            .into_iter()
            .filter(|&d| d == Derivative::Position || self.rate_bound(d, 0).is_some())
            .collect()
    }

    /// The bound a row holds: the rate limit, less [`RATE_BUFFER`] of it
    /// for acceleration and jerk.
    fn row_bound(&self, d: Derivative, j: usize) -> Option<f64> {
        let bound = self.rate_bound(d, j)?;
        Some(match d {
            Derivative::Acceleration | Derivative::Jerk => bound * (1.0 - RATE_BUFFER),
            _ => bound,
        })
    }

    /// Signed excess `value - bound` of one row for weights `w` (> 0 =
    /// violated); acceleration and jerk rows are measured against their
    /// buffered bound.
    pub fn excess(&self, rows: &PhaseRows, w: &DVector<f64>, r: RowRef) -> f64 {
        let value = rows.value(r.kind.derivative, r.phase, r.joint, w);
        self.excess_of(value, r)
    }

    /// [`LinearSet::excess`] of row `r` given the value of its derivative.
    fn excess_of(&self, value: f64, r: RowRef) -> f64 {
        let (d, j) = (r.kind.derivative, r.joint);
        match (self.row_bound(d, j), r.kind.upper) {
            (None, true) => value - self.upper[j],
            (None, false) => self.lower[j] - value,
            (Some(b), true) => value - b,
            (Some(b), false) => -b - value,
        }
    }

    /// Calls `f` with every row of `rows` and its excess at `w`, in the
    /// order of [`LinearSet::all_rows`]. Each derivative is evaluated once
    /// per phase and joint and gives both its upper and its lower row; the
    /// loops are plain (this pass runs several times per SCP iteration over
    /// thousands of rows).
    fn for_each_excess(&self, rows: &PhaseRows, w: &DVector<f64>, mut f: impl FnMut(RowRef, f64)) {
        let derivatives = self.derivatives();
        let n_joints = rows.n_joints();
        // (upper, lower) bound of every (derivative, joint).
        let bounds: Vec<(f64, f64)> = derivatives
            .iter()
            .flat_map(|&d| {
                (0..n_joints).map(move |j| match self.row_bound(d, j) {
                    None => (self.upper[j], self.lower[j]),
                    Some(b) => (b, -b),
                })
            })
            .collect();
        for phase in 0..rows.len() {
            for joint in 0..n_joints {
                for (k, &derivative) in derivatives.iter().enumerate() {
                    let value = rows.value(derivative, phase, joint, w);
                    let (upper_bound, lower_bound) = bounds[k * n_joints + joint];
                    let row = |upper| RowRef {
                        phase,
                        joint,
                        kind: RowKind { derivative, upper },
                    };
                    f(row(true), value - upper_bound);
                    f(row(false), lower_bound - value);
                }
            }
        }
    }

    /// The rows of `rows` whose excess at `w` passes `keep`.
    fn rows_where(
        &self,
        rows: &PhaseRows,
        w: &DVector<f64>,
        mut keep: impl FnMut(RowRef, f64) -> bool,
    ) -> Vec<RowRef> {
        let mut kept = Vec::new();
        self.for_each_excess(rows, w, |r, excess| {
            if keep(r, excess) {
                kept.push(r);
            }
        });
        kept
    }

    /// The row as `a·z <= b` given the weights at `z = 0` (the prior mean).
    pub fn inequality(&self, rows: &PhaseRows, mean: &DVector<f64>, r: RowRef) -> Inequality {
        let excess0 = self.excess(rows, mean, r);
        let a = rows.row(r.kind.derivative, r.phase, r.joint);
        Inequality {
            a: if r.kind.upper { a.clone() } else { -a },
            b: -excess0,
            penalty: None,
        }
    }

    /// Every row of `rows`: by phase, then joint, then kind, with each
    /// derivative's upper row right before its lower row
    /// ([`LinearSet::for_each_excess`] keeps that order).
    pub fn all_rows<'a>(&self, rows: &'a PhaseRows) -> impl Iterator<Item = RowRef> + 'a {
        // A fixed array (Copy) so that the nested closures allocate nothing.
        let mut kinds = [RowKind {
            derivative: Derivative::Position,
            upper: true,
        }; 8];
        let listed = self.kinds();
        kinds[..listed.len()].copy_from_slice(&listed);
        let n_kinds = listed.len();
        (0..rows.len()).flat_map(move |phase| {
            (0..rows.n_joints()).flat_map(move |joint| {
                (0..n_kinds).map(move |k| RowRef {
                    phase,
                    joint,
                    kind: kinds[k],
                })
            })
        })
    }

    /// Rows that a step within `radius` of `w` (the weights of the current
    /// iterate) could violate; `None` radius: rows within [`SCREEN_MARGIN`].
    pub fn screen(&self, rows: &PhaseRows, w: &DVector<f64>, radius: Option<f64>) -> Vec<RowRef> {
        self.rows_where(rows, w, |r, excess| excess + reach(rows, r, radius) >= 0.0)
    }

    /// Like [`LinearSet::screen`], but a row also needs its slack within a
    /// fixed band ([`SCREEN_BAND_POSITION`] rad, [`SCREEN_BAND_VELOCITY`] of
    /// the rate limit): rows far from their bound rarely become active
    /// in one step, and the caller adds any row a solution violates.
    pub fn screen_banded(
        &self,
        rows: &PhaseRows,
        w: &DVector<f64>,
        radius: Option<f64>,
    ) -> Vec<RowRef> {
        self.rows_where(rows, w, |r, excess| {
            let band = self
                .rate_bound(r.kind.derivative, r.joint)
                .map_or(SCREEN_BAND_POSITION, |b| SCREEN_BAND_VELOCITY * b);
            excess + reach(rows, r, radius).min(band) >= 0.0
        })
    }

    /// Rows violated by more than `tolerance` at `w`.
    pub fn violated(&self, rows: &PhaseRows, w: &DVector<f64>, tolerance: f64) -> Vec<RowRef> {
        self.rows_where(rows, w, |_, excess| excess > tolerance)
    }

    /// The derivatives each end must hold at a value: position at the
    /// start / final configuration and at each via point, velocity and
    /// acceleration at zero at both ends when the motion is rest-to-rest.
    /// `(phase index in ends, derivative, target per joint)`.
    fn end_conditions(&self, n_joints: usize) -> Vec<(usize, Derivative, Vec<f64>)> {
        let mut out = Vec::new();
        for (p, target) in [(0, &self.start), (1, &self.final_configuration)] {
            if let Some(q) = target {
                out.push((p, Derivative::Position, q.clone()));
            }
            if self.rest {
                for d in [Derivative::Velocity, Derivative::Acceleration] {
                    out.push((p, d, vec![0.0; n_joints]));
                }
            }
        }
        for (p, q) in &self.via {
            out.push((*p, Derivative::Position, q.clone()));
        }
        out
    }

    /// Equalities `a·z = b` for the start and final configuration at
    /// `ends` (phases 0 and 1) and the via points (the phases after them). Rest needs no row: the resting timing
    /// ([`TimeWarp`](crate::optim::problem::phases::TimeWarp)) makes every trajectory rest
    /// at the ends; [`LinearSet::equality_error`] still checks it.
    pub fn equalities(&self, ends: &PhaseRows, mean: &DVector<f64>) -> Vec<(DVector<f64>, f64)> {
        let mut out = Vec::new();
        let conditions = self.end_conditions(ends.n_joints());
        for (p, d, target) in conditions
            .into_iter()
            .filter(|(_, d, _)| *d == Derivative::Position)
        {
            let at_mean = ends.values(d, p, mean);
            for j in 0..ends.n_joints() {
                out.push((ends.row(d, p, j).clone(), target[j] - at_mean[j]));
            }
        }
        out
    }

    /// Largest end-condition residual at `w`: rad for configurations,
    /// rad/s and rad/s² for rest.
    pub fn equality_error(&self, ends: &PhaseRows, w: &DVector<f64>) -> f64 {
        let mut worst: f64 = 0.0;
        for (p, d, target) in self.end_conditions(ends.n_joints()) {
            for (a, b) in ends.values(d, p, w).iter().zip(&target) {
                worst = worst.max((a - b).abs());
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

/// How far row `r` can move in a step of `radius` (L1 norm times radius);
/// [`SCREEN_MARGIN`] without a trust region.
fn reach(rows: &PhaseRows, r: RowRef, radius: Option<f64>) -> f64 {
    radius.map_or(SCREEN_MARGIN, |d| {
        d * rows.row_l1(r.kind.derivative, r.phase, r.joint) + 1e-9
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::example_distribution;
    use crate::optim::problem::whiten::Whitening;
    use crate::promp::{Basis, PrompConfig};

    #[test]
    fn rows_are_exact_and_screening_never_drops_a_row_a_step_could_violate() {
        let basis = Basis::new(&PrompConfig {
            n_samples: 30,
            ..Default::default()
        })
        .unwrap();
        let dist = example_distribution(&basis, 20, 2).unwrap();
        let wh = Whitening::new(&dist, Whitening::default_lambda(&dist)).unwrap();
        let timing = (4.0, crate::optim::problem::phases::TimeWarp::MinimumJerk);
        let rows = PhaseRows::new(&basis, &wh, 7, timing, basis.phases());
        let set = LinearSet {
            lower: vec![-2.0; 7],
            upper: vec![2.0; 7],
            velocity: vec![1.0; 7],
            acceleration: Some(vec![3.0; 7]),
            jerk: Some(vec![30.0; 7]),
            start: None,
            final_configuration: None,
            via: Vec::new(),
            rest: true,
            bound_weights: false,
        };
        let n = wh.dim();
        let zk = DVector::from_fn(n, |i, _| (i as f64 * 1.3).cos() * 0.5);
        let wk = wh.weights(&zk);
        let radius = 0.7;
        let kept = set.screen(&rows, &wk, Some(radius));
        assert_eq!(set.kinds().len(), 8);
        for r in set.all_rows(&rows) {
            let ineq = set.inequality(&rows, &dist.mean, r);
            // a·z - b equals the excess at any z, and the excess is
            // measured against the buffered bound.
            let lhs = ineq.a.dot(&zk) - ineq.b;
            assert!((lhs - set.excess(&rows, &wk, r)).abs() < 1e-9);
            let d = r.kind.derivative;
            if let (Some(b), true) = (set.rate_bound(d, r.joint), r.kind.upper) {
                let value = rows.value(d, r.phase, r.joint, &wk);
                let buffer = if d == Derivative::Velocity {
                    0.0
                } else {
                    RATE_BUFFER
                };
                assert!((set.excess(&rows, &wk, r) - (value - b * (1.0 - buffer))).abs() < 1e-9);
            }
            if !kept.contains(&r) {
                // Worst corner of the box cannot violate it.
                let corner = DVector::from_fn(n, |i, _| zk[i] + radius * ineq.a[i].signum());
                assert!(ineq.a.dot(&corner) <= ineq.b + 1e-9);
            }
        }
        assert!(kept.len() < set.all_rows(&rows).count());
        // The one-evaluation-per-derivative pass agrees row by row.
        let rows_seen: Vec<RowRef> = set.all_rows(&rows).collect();
        let mut pass = Vec::new();
        set.for_each_excess(&rows, &wk, |r, e| pass.push((r, e)));
        assert_eq!(pass.len(), rows_seen.len());
        for ((r, e), seen) in pass.into_iter().zip(rows_seen) {
            assert_eq!(r, seen);
            assert!((e - set.excess(&rows, &wk, r)).abs() < 1e-12);
        }
    }
}
