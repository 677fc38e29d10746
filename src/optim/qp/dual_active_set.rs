//! A dual active-set QP solver (Goldfarb & Idnani, 1983) for the inner
//! iterations of the SCP.
//!
//! It solves
//!
//! ```text
//! minimise ½|x - c|² + Σ_soft u_i · max(0, a_i·x - b_i)
//! subject to a_i·x ≤ b_i            (hard rows)
//! ```
//!
//! which is the SCP subproblem in whitened coordinates after the equalities
//! are eliminated ([`NullSpace`](crate::optim::qp::nullspace::NullSpace)): the Hessian
//! is the identity, and an L1-penalised soft row is a row whose multiplier
//! is bounded above by its penalty `u_i` (the dual of `max(0, ·)`). So the
//! L1 model stays exact with no slack variables.
//!
//! # The method
//!
//! The iterate is always the optimum of the problem restricted to its
//! *active* rows held as equalities (dual feasible), and each step makes one
//! more row primal feasible while the dual objective grows, so the method
//! cannot cycle except through exact ties. By the KKT conditions
//! `x = c - Σ λ_i a_i`. Every row is in one of three states:
//!
//! - *inactive*: `λ = 0`, the row must hold (`a·x ≤ b`);
//! - *saturated* (soft rows only): `λ = u`, the row is broken (`a·x ≥ b`)
//!   and its fixed contribution `-u a` is folded into a shifted centre;
//! - *active*: `a·x = b` with `0 ≤ λ ≤ u`, held in a QR factorisation of
//!   the active normals. A saturated row that becomes satisfied re-enters
//!   in the reverse sense: normal `-a`, multiplier `ν = u - λ`.
//!
//! [`DualActiveSet::add_row`] raises the multiplier of the most violated
//! row; the primal step keeps the active rows at equality (`z`, the part of
//! the row's normal outside their span) and moves their multipliers along
//! `-r`. The step length is the smallest of: the full step (the row holds
//! and becomes active), an active multiplier reaching 0 or its bound (that
//! row leaves, and the step goes on), and the new row's own multiplier
//! reaching its bound (it saturates). A hard row whose normal lies in the
//! span of the active hard rows, with no multiplier able to give way, proves
//! the hard rows incompatible.
//!
//! # Numerics
//!
//! The active normals `N = J [R; 0]` are kept as an orthogonal `J` and an
//! upper-triangular `R`, updated by Givens rotations when a row joins or
//! leaves (O(n²) each, no refactorisation), and refactored from scratch
//! every [`Settings::refactor_every`] updates to stop drift. A normal whose
//! component outside the active span is below [`DEPENDENCE_TOLERANCE`] of
//! its length counts as dependent (near-parallel rows from neighbouring
//! phases), so `R` keeps a well-bounded diagonal. The iterate is recomputed
//! from the multipliers after every row, not accumulated.

use nalgebra::{DMatrix, DVector};
use std::time::Instant;

/// A normal whose part outside the span of the active normals is below this
/// fraction of its length is treated as lying in that span.
pub const DEPENDENCE_TOLERANCE: f64 = 1e-9;

/// One row `a·x ≤ b`.
#[derive(Clone, Debug)]
pub struct Row {
    /// Normal.
    pub a: DVector<f64>,
    /// Right-hand side.
    pub b: f64,
    /// Bound on the multiplier: the L1 penalty of a soft row, `None` for a
    /// hard row.
    pub cap: Option<f64>,
}

/// Settings of one solve.
#[derive(Clone, Debug)]
pub struct Settings {
    /// A row is violated when `(a·x - b) / |a|` exceeds this.
    pub tolerance: f64,
    /// Most multiplier steps before giving up (cycling guard); 0 means
    /// `20 (rows + dim) + 100`.
    pub max_steps: usize,
    /// Refactor the active set's QR after this many updates.
    pub refactor_every: usize,
    /// Every row's cap is multiplied by this (> 0): the same rows serve a
    /// family of problems whose objective is scaled (the SCP's proximal
    /// trust term), without copying them.
    pub cap_scale: f64,
    /// Give up ([`Failure::OutOfTime`]) at the first step begun after this
    /// instant: a solve over thousands of rows takes thousands of steps, and
    /// a request's deadline bounds all of its work.
    pub deadline: Option<Instant>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            tolerance: 1e-11,
            max_steps: 0,
            refactor_every: 64,
            cap_scale: 1.0,
            deadline: None,
        }
    }
}

/// Why a solve produced no solution.
#[derive(Clone, Debug, PartialEq)]
pub enum Failure {
    /// The hard rows cannot all hold; `row` is the one that could not be
    /// added.
    Infeasible {
        /// Index of the row.
        row: usize,
    },
    /// The step limit was reached (cycling or a badly scaled problem).
    MaxSteps,
    /// [`Settings::deadline`] passed.
    OutOfTime,
    /// A row or the centre has the wrong length or a non-finite entry.
    BadInput(String),
}

/// The optimum.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Minimiser.
    pub x: DVector<f64>,
    /// Multiplier of each row (0 inactive, the cap when saturated).
    pub multipliers: Vec<f64>,
    /// Rows held at equality at the optimum, in the order they joined.
    pub active: Vec<usize>,
    /// Soft rows broken at the optimum (multiplier at the cap).
    pub saturated: Vec<usize>,
    /// `½|x - c|² + Σ u_i max(0, a_i·x - b_i)`.
    pub objective: f64,
    /// Multiplier steps taken (full and partial).
    pub steps: usize,
    /// The [`Settings::cap_scale`] the caps were multiplied by.
    pub cap_scale: f64,
}

impl Solution {
    /// This optimum as the warm start of a neighbouring problem.
    pub fn warm_start(&self) -> WarmStart {
        WarmStart {
            saturated: self.saturated.clone(),
            active: self.active.clone(),
        }
    }

    /// The largest violation of the optimality conditions of `x` and the
    /// multipliers for the problem (`centre`, `rows`): stationarity
    /// `|x - c + Σ λ_i a_i|∞`, hard-row feasibility, multipliers within
    /// `[0, cap]`, and complementarity (`λ = 0` where a row is slack, `λ =
    /// cap` where a soft row is broken), each in the row's own units.
    pub fn kkt_residual(&self, centre: &DVector<f64>, rows: &[Row]) -> f64 {
        let mut gradient = &self.x - centre;
        let mut worst: f64 = 0.0;
        for (row, &lambda) in rows.iter().zip(&self.multipliers) {
            gradient.axpy(lambda, &row.a, 1.0);
            let s = (row.a.dot(&self.x) - row.b) / row.a.norm().max(f64::MIN_POSITIVE);
            let cap = row.cap.map_or(f64::INFINITY, |u| u * self.cap_scale);
            worst = worst.max(-lambda).max(lambda - cap);
            if row.cap.is_none() {
                worst = worst.max(s);
            }
            worst = worst.max(lambda.min(-s).min(cap - lambda));
            if s > 0.0 {
                worst = worst.max((cap - lambda).min(s));
            }
        }
        worst.max(gradient.amax())
    }
}

/// The state of one row.
#[derive(Clone, Copy, Debug, PartialEq)]
enum State {
    Inactive,
    Saturated,
    Active,
}

/// An active row: index, sense (`+1`: normal `a`, multiplier `λ`; `-1`:
/// normal `-a`, multiplier `u - λ`), multiplier in that sense.
#[derive(Clone, Copy, Debug)]
struct ActiveRow {
    row: usize,
    sign: f64,
    mult: f64,
}

/// What ended one multiplier step.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Event {
    /// The new row holds: it joins the active set.
    Full,
    /// Active row `k` (position in the active list) reached multiplier 0.
    Release(usize),
    /// Active row `k` reached its cap.
    Cap(usize),
    /// The new row's multiplier reached its cap.
    NewCap,
}

/// A guess of the optimal row states, e.g. a previous solve's.
#[derive(Clone, Debug, Default)]
pub struct WarmStart {
    /// Soft rows to start saturated (multiplier at the cap). Any set is a
    /// valid (dual-feasible) start; a good one saves two steps per row.
    pub saturated: Vec<usize>,
    /// Rows to make feasible before any other, in this order.
    pub active: Vec<usize>,
}

/// Solve the problem of the module docs from `warm` (indices out of range
/// and hard rows in `warm.saturated` are ignored): with a good guess the
/// solve takes about one step per changed row.
pub fn solve(
    centre: &DVector<f64>,
    rows: &[Row],
    settings: &Settings,
    warm: &WarmStart,
) -> Result<Solution, Failure> {
    check_input(centre, rows, settings)?;
    let mut solver = DualActiveSet::new(centre, rows, settings);
    for &i in &warm.saturated {
        if solver.cap(i).is_some() && solver.state[i] == State::Inactive {
            solver.settle(i, false, true);
        }
    }
    solver.recompute_x();
    for &p in warm.active.iter().filter(|&&p| p < rows.len()) {
        if let Some(sign) = solver.violation_sense(p) {
            solver.add_row(p, sign)?;
        }
    }
    while let Some((p, sign)) = solver.most_violated() {
        solver.add_row(p, sign)?;
    }
    Ok(solver.into_solution())
}

fn check_input(centre: &DVector<f64>, rows: &[Row], settings: &Settings) -> Result<(), Failure> {
    let n = centre.len();
    if !(settings.cap_scale.is_finite() && settings.cap_scale > 0.0) {
        return Err(Failure::BadInput(format!(
            "cap_scale must be finite and > 0, got {}",
            settings.cap_scale
        )));
    }
    if !centre.iter().all(|v| v.is_finite()) {
        return Err(Failure::BadInput("centre has a non-finite entry".into()));
    }
    for (i, row) in rows.iter().enumerate() {
        if row.a.len() != n {
            return Err(Failure::BadInput(format!(
                "row {i} has {} coefficients, expected {n}",
                row.a.len()
            )));
        }
        let cap_ok = row.cap.is_none_or(|u| u.is_finite() && u >= 0.0);
        if !row.a.iter().all(|v| v.is_finite()) || !row.b.is_finite() || !cap_ok {
            return Err(Failure::BadInput(format!("row {i} has a non-finite entry")));
        }
    }
    Ok(())
}

/// The solver's state between steps.
struct DualActiveSet<'a> {
    rows: &'a [Row],
    centre: &'a DVector<f64>,
    settings: &'a Settings,
    /// `c - Σ_{saturated or reversed} u_i a_i`.
    shifted: DVector<f64>,
    /// `shifted - Σ_active mult_k sign_k a_k`.
    x: DVector<f64>,
    state: Vec<State>,
    active: Vec<ActiveRow>,
    /// Orthogonal factor (`n x n`).
    j: DMatrix<f64>,
    /// Upper-triangular factor; the leading `active.len()` columns are used.
    r: DMatrix<f64>,
    norms: Vec<f64>,
    steps: usize,
    max_steps: usize,
    updates: usize,
}

impl<'a> DualActiveSet<'a> {
    fn new(centre: &'a DVector<f64>, rows: &'a [Row], settings: &'a Settings) -> Self {
        let n = centre.len();
        let max_steps = if settings.max_steps == 0 {
            20 * (rows.len() + n) + 100
        } else {
            settings.max_steps
        };
        DualActiveSet {
            rows,
            centre,
            settings,
            shifted: centre.clone(),
            x: centre.clone(),
            state: vec![State::Inactive; rows.len()],
            active: Vec::new(),
            j: DMatrix::identity(n, n),
            r: DMatrix::zeros(n, n),
            norms: rows.iter().map(|r| r.a.norm()).collect(),
            steps: 0,
            max_steps,
            updates: 0,
        }
    }

    fn dim(&self) -> usize {
        self.centre.len()
    }

    /// Row `i`'s multiplier bound (scaled), `None` for a hard row.
    fn cap(&self, i: usize) -> Option<f64> {
        self.rows[i].cap.map(|u| u * self.settings.cap_scale)
    }

    /// The sense in which row `i` is violated beyond the tolerance, if it is.
    fn violation_sense(&self, i: usize) -> Option<f64> {
        let v = self.scaled_violation(i);
        (v > self.settings.tolerance).then(|| match self.state[i] {
            State::Saturated => -1.0,
            _ => 1.0,
        })
    }

    /// How far row `i` breaks its state's requirement, per unit normal:
    /// `a·x - b` for an inactive row, `b - a·x` for a saturated one, 0 for
    /// an active one.
    fn scaled_violation(&self, i: usize) -> f64 {
        let row = &self.rows[i];
        let norm = self.norms[i];
        if norm == 0.0 {
            // 0 ≤ b: an unsatisfiable zero row is reported as violated.
            return match self.state[i] {
                State::Inactive => -row.b,
                _ => 0.0,
            };
        }
        let s = row.a.dot(&self.x) - row.b;
        match self.state[i] {
            State::Inactive => s / norm,
            State::Saturated => -s / norm,
            State::Active => 0.0,
        }
    }

    /// The most violated row (per unit normal) and its sense; ties go to
    /// the lower index.
    fn most_violated(&self) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for i in 0..self.rows.len() {
            let v = self.scaled_violation(i);
            if v > self.settings.tolerance && best.is_none_or(|(_, bv)| v > bv) {
                best = Some((i, v));
            }
        }
        best.and_then(|(i, _)| self.violation_sense(i).map(|s| (i, s)))
    }

    /// Raise the multiplier of row `p` (in sense `sign`) until the row holds
    /// or its multiplier reaches its cap, releasing active rows on the way.
    fn add_row(&mut self, p: usize, sign: f64) -> Result<(), Failure> {
        let normal = &self.rows[p].a * sign;
        let rhs = self.rows[p].b * sign;
        let cap = self.cap(p);
        let mut mult = 0.0;
        loop {
            self.steps += 1;
            if self.steps > self.max_steps {
                return Err(Failure::MaxSteps);
            }
            if self.settings.deadline.is_some_and(|d| Instant::now() >= d) {
                return Err(Failure::OutOfTime);
            }
            let (d, dependent) = self.rotated(&normal);
            let k = self.active.len();
            let r_dir = self.back_substitute(&d);
            let z = if dependent {
                None
            } else {
                Some(self.j.columns(k, self.dim() - k) * d.rows(k, self.dim() - k))
            };
            let violation = normal.dot(&self.x) - rhs;
            let full = z
                .as_ref()
                .map(|_| violation.max(0.0) / d.rows(k, self.dim() - k).norm_squared());
            let (t, event) = self.step_length(&r_dir, full, cap.map(|u| u - mult));
            let Some(event) = event else {
                return Err(Failure::Infeasible { row: p });
            };
            for (a, &rk) in self.active.iter_mut().zip(r_dir.iter()) {
                a.mult -= t * rk;
            }
            mult += t;
            if let Some(z) = &z {
                self.x.axpy(-t, z, 1.0);
            }
            match event {
                Event::Full => {
                    self.push_active(p, sign, mult, &d);
                    self.recompute_x();
                    return Ok(());
                }
                Event::NewCap => {
                    self.flip_to_bound(p, sign);
                    self.recompute_x();
                    return Ok(());
                }
                Event::Release(k) => self.remove_active(k, false),
                Event::Cap(k) => self.remove_active(k, true),
            }
            self.recompute_x_with(&normal, mult);
        }
    }

    /// The smallest step among the full step, active multipliers reaching
    /// 0 or their cap, and the new multiplier reaching its cap (`room`).
    fn step_length(
        &self,
        r_dir: &DVector<f64>,
        full: Option<f64>,
        room: Option<f64>,
    ) -> (f64, Option<Event>) {
        let mut best = (f64::INFINITY, None);
        let mut consider = |t: f64, e: Event| {
            if t < best.0 {
                best = (t.max(0.0), Some(e));
            }
        };
        for (k, (a, &rk)) in self.active.iter().zip(r_dir.iter()).enumerate() {
            if rk > 0.0 {
                consider(a.mult / rk, Event::Release(k));
            } else if rk < 0.0 {
                if let Some(u) = self.cap(a.row) {
                    consider((u - a.mult) / -rk, Event::Cap(k));
                }
            }
        }
        if let Some(t) = full {
            consider(t, Event::Full);
        }
        if let Some(t) = room {
            consider(t, Event::NewCap);
        }
        best
    }

    /// `Jᵀ normal`, and whether the normal lies in the active span.
    fn rotated(&self, normal: &DVector<f64>) -> (DVector<f64>, bool) {
        let d = self.j.tr_mul(normal);
        let k = self.active.len();
        let outside = d.rows(k, self.dim() - k).norm();
        let dependent = outside <= DEPENDENCE_TOLERANCE * normal.norm().max(f64::MIN_POSITIVE);
        (d, dependent)
    }

    /// `R⁻¹ d[..k]`: how the active multipliers fall per unit of the new one.
    fn back_substitute(&self, d: &DVector<f64>) -> DVector<f64> {
        let k = self.active.len();
        let mut out = DVector::zeros(k);
        for i in (0..k).rev() {
            let mut s = d[i];
            let row = self.r.view((i, i + 1), (1, k - i - 1));
            for (r, o) in row.iter().zip(out.rows(i + 1, k - i - 1).iter()) {
                s -= r * o;
            }
            out[i] = s / self.r[(i, i)];
        }
        out
    }

    /// Row `p` joins the active set; `d = Jᵀ normal`.
    fn push_active(&mut self, p: usize, sign: f64, mult: f64, d: &DVector<f64>) {
        let k = self.active.len();
        let n = self.dim();
        let mut d = d.clone();
        for i in (k + 1..n).rev() {
            let (c, s) = givens(d[i - 1], d[i]);
            d[i - 1] = c * d[i - 1] + s * d[i];
            d[i] = 0.0;
            rotate_columns(&mut self.j, i - 1, i, c, s);
        }
        for i in 0..=k {
            self.r[(i, k)] = d[i];
        }
        self.active.push(ActiveRow {
            row: p,
            sign,
            mult: mult.max(0.0),
        });
        self.state[p] = State::Active;
        self.count_update();
    }

    /// Active row `k` leaves: at multiplier 0 (`capped == false`) or at its
    /// cap.
    fn remove_active(&mut self, k: usize, capped: bool) {
        let ActiveRow { row, sign, .. } = self.active.remove(k);
        let last = self.active.len();
        let n = self.dim();
        // Shift the columns after `k` one to the left (column-major: each
        // column's leading `c + 2` entries are one contiguous copy).
        let data = self.r.as_mut_slice();
        for c in k..last {
            data.copy_within((c + 1) * n..(c + 1) * n + (c + 2).min(n), c * n);
        }
        for i in 0..self.dim() {
            self.r[(i, last)] = 0.0;
        }
        for c in k..last {
            let (cs, sn) = givens(self.r[(c, c)], self.r[(c + 1, c)]);
            for col in c..last {
                let (top, bottom) = (self.r[(c, col)], self.r[(c + 1, col)]);
                self.r[(c, col)] = cs * top + sn * bottom;
                self.r[(c + 1, col)] = -sn * top + cs * bottom;
            }
            self.r[(c + 1, c)] = 0.0;
            rotate_columns(&mut self.j, c, c + 1, cs, sn);
        }
        // Sense +1 at 0 or sense -1 at its cap: λ = 0, inactive.
        // Sense +1 at its cap or sense -1 at 0: λ = u, saturated.
        let saturated = (sign > 0.0) == capped;
        self.settle(row, sign < 0.0, saturated);
        self.count_update();
    }

    /// Row `p`, not active, moves to the other bound of its multiplier.
    fn flip_to_bound(&mut self, p: usize, sign: f64) {
        self.settle(p, sign < 0.0, sign > 0.0);
    }

    /// Put row `i` in the inactive or saturated state and keep the shifted
    /// centre consistent; `was_shifted`: its `-u a` is in the centre now
    /// (it was saturated, or active in the reverse sense).
    fn settle(&mut self, i: usize, was_shifted: bool, saturated: bool) {
        let u = self.cap(i).unwrap_or(0.0);
        match (was_shifted, saturated) {
            (false, true) => self.shifted.axpy(-u, &self.rows[i].a, 1.0),
            (true, false) => self.shifted.axpy(u, &self.rows[i].a, 1.0),
            _ => {}
        }
        self.state[i] = if saturated {
            State::Saturated
        } else {
            State::Inactive
        };
    }

    fn count_update(&mut self) {
        self.updates += 1;
        if self.updates >= self.settings.refactor_every {
            self.refactor();
        }
    }

    /// Rebuild `J` and `R` from the active normals.
    fn refactor(&mut self) {
        self.updates = 0;
        let n = self.dim();
        let k = self.active.len();
        if k == 0 {
            self.j = DMatrix::identity(n, n);
            self.r.fill(0.0);
            return;
        }
        let normals = DMatrix::from_fn(n, k, |i, c| {
            let a = &self.active[c];
            a.sign * self.rows[a.row].a[i]
        });
        let qr = normals.qr();
        let mut qt = DMatrix::identity(n, n);
        qr.q_tr_mul(&mut qt);
        self.j = qt.transpose();
        self.r.fill(0.0);
        let r = qr.r();
        for c in 0..k {
            for i in 0..=c.min(n - 1) {
                self.r[(i, c)] = r[(i, c)];
            }
        }
    }

    /// `x = shifted - Σ_active mult sign a`.
    fn recompute_x(&mut self) {
        self.x.copy_from(&self.shifted);
        for a in &self.active {
            self.x.axpy(-a.mult * a.sign, &self.rows[a.row].a, 1.0);
        }
    }

    /// [`Self::recompute_x`] with the pending row's contribution.
    fn recompute_x_with(&mut self, normal: &DVector<f64>, mult: f64) {
        self.recompute_x();
        self.x.axpy(-mult, normal, 1.0);
    }

    fn into_solution(self) -> Solution {
        let mut multipliers = vec![0.0; self.rows.len()];
        for (i, s) in self.state.iter().enumerate() {
            if *s == State::Saturated {
                multipliers[i] = self.cap(i).unwrap_or(0.0);
            }
        }
        for a in &self.active {
            let u = self.cap(a.row).unwrap_or(0.0);
            multipliers[a.row] = if a.sign > 0.0 { a.mult } else { u - a.mult };
        }
        let objective = 0.5 * (&self.x - self.centre).norm_squared()
            + self
                .rows
                .iter()
                .filter_map(|r| {
                    r.cap
                        .map(|u| u * self.settings.cap_scale * (r.a.dot(&self.x) - r.b).max(0.0))
                })
                .sum::<f64>();
        Solution {
            active: self.active.iter().map(|a| a.row).collect(),
            saturated: (0..self.rows.len())
                .filter(|&i| self.state[i] == State::Saturated)
                .collect(),
            x: self.x,
            multipliers,
            objective,
            steps: self.steps,
            cap_scale: self.settings.cap_scale,
        }
    }
}

/// `(c, s)` with `c a + s b = √(a² + b²)` and `-s a + c b = 0`.
fn givens(a: f64, b: f64) -> (f64, f64) {
    if b == 0.0 {
        return (1.0, 0.0);
    }
    // Moderate magnitudes (normals and multipliers): no overflow guard
    // needed, and `hypot` is several times slower.
    let h = (a * a + b * b).sqrt();
    (a / h, b / h)
}

/// Columns `(u, v)` of `m` (`u < v`) become `(c u + s v, -s u + c v)`.
/// The columns are contiguous (column-major storage): a plain loop over
/// two slices, which the compiler vectorises.
fn rotate_columns(m: &mut DMatrix<f64>, u: usize, v: usize, c: f64, s: f64) {
    debug_assert!(u < v);
    let n = m.nrows();
    let (left, right) = m.as_mut_slice().split_at_mut(v * n);
    let (cu, cv) = (&mut left[u * n..(u + 1) * n], &mut right[..n]);
    for (x, y) in cu.iter_mut().zip(cv.iter_mut()) {
        let (a, b) = (*x, *y);
        *x = c * a + s * b;
        *y = -s * a + c * b;
    }
}
