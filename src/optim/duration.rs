//! The shortest duration that the limits allow.
//!
//! A trajectory's `k`-th time derivative is `ψ⁽ᵏ⁾(z) w / Tᵏ`: stretching
//! the same weights over a longer duration `T` divides every velocity,
//! acceleration and jerk by `T`, `T²`, `T³`, and changes neither the path
//! (positions, clearance, goal) nor the end conditions (a zero velocity
//! stays zero). So if some weights meet the limits at `T`, the same weights
//! meet them at every longer duration: feasibility of the *linear* part of
//! the problem — position, velocity, acceleration and jerk limits, rest at
//! the ends, start and final configuration, weight bounds — is monotone in
//! `T`, and the shortest feasible duration is found by bisection.
//!
//! Feasibility at one duration is decided by Clarabel (the solver of
//! record): a QP towards the prior mean over the end conditions, with limit
//! rows generated at the grid and dense verification phases until none is
//! violated, or a certificate of primal infeasibility.

use super::linear::{LinearSet, RowKind, RowRef};
use super::phases::{Derivative, PhaseRows};
use super::problem::Problem;
use super::qp::{Qp, QpFailure, QpSettings};
use super::request::MAX_DURATION_S;
use super::working_set::{thin_in_time, Candidate};
use nalgebra::DVector;

/// Relative width of the final bisection bracket.
pub const DURATION_RELATIVE_TOLERANCE: f64 = 1e-3;

/// Relative margin added to the bisection's result: at the exact shortest
/// duration the feasible set is a sliver that an iterative solver may miss;
/// 1 % longer leaves every rate limit 1–3 % of room.
pub const DURATION_MARGIN: f64 = 1e-2;

/// Rounds of row generation before a feasibility check gives up (counted
/// as infeasible: the bisection then errs on the long, safe side).
const MAX_GENERATION_ROUNDS: usize = 30;

/// Rows violated by less than this count as met (rad, rad/s, ...).
const ROW_TOLERANCE: f64 = 1e-9;

/// Why the duration is too short, and the shortest that works.
#[derive(Clone, Debug, PartialEq)]
pub struct DurationDiagnosis {
    /// The limit that cannot hold, in words naming the request field.
    pub reason: String,
    /// The shortest feasible duration (s) plus [`DURATION_MARGIN`], rounded
    /// up to the millisecond;
    /// `None` when even [`MAX_DURATION_S`] is too short.
    pub min_duration_s: Option<f64>,
}

impl Problem {
    /// `Some` when the velocity, acceleration or jerk limits cannot hold
    /// together with the end conditions over the requested duration (then
    /// no trajectory is feasible, whatever the obstacles and the goal);
    /// `None` when they can, or when the position limits and end conditions
    /// alone are already incompatible (no duration helps).
    pub fn duration_diagnosis(&self) -> Option<DurationDiagnosis> {
        if self.linear_feasible(&self.linear, self.duration) {
            return None;
        }
        let positions_only = LinearSet {
            velocity: vec![f64::INFINITY; self.linear.velocity.len()],
            acceleration: None,
            jerk: None,
            ..self.linear.clone()
        };
        if !self.linear_feasible(&positions_only, MAX_DURATION_S) {
            return None;
        }
        let reason = self.binding_limit();
        let min_duration_s = self.shortest_duration();
        Some(DurationDiagnosis {
            reason: match min_duration_s {
                Some(d) => format!(
                    "duration_s: {reason} cannot hold over {:.3} s; the shortest feasible duration is {d:.3} s (min_duration_s)",
                    self.duration
                ),
                None => format!(
                    "duration_s: {reason} cannot hold even over {MAX_DURATION_S} s"
                ),
            },
            min_duration_s,
        })
    }

    /// Which rate limit makes the requested duration infeasible, in words:
    /// the first that is infeasible on its own, or all of them together.
    fn binding_limit(&self) -> String {
        let fields = [
            (
                Derivative::Velocity,
                "the velocity limits (velocity_scaling)",
            ),
            (
                Derivative::Acceleration,
                "the acceleration limits (acceleration_limits, acceleration_scaling)",
            ),
            (Derivative::Jerk, "the jerk limits (jerk_limits)"),
        ];
        for (d, words) in fields {
            if self.linear.rate_bound(d, 0).is_none() {
                continue;
            }
            let only = self.only_rate_limit(d);
            if !self.linear_feasible(&only, self.duration) {
                return format!("{words} with the boundary conditions");
            }
        }
        "the velocity, acceleration and jerk limits together".into()
    }

    /// The linear set with every rate limit but `d`'s lifted.
    fn only_rate_limit(&self, d: Derivative) -> LinearSet {
        let keep = |k: Derivative, v: Option<Vec<f64>>| if k == d { v } else { None };
        LinearSet {
            velocity: if d == Derivative::Velocity {
                self.linear.velocity.clone()
            } else {
                vec![f64::INFINITY; self.linear.velocity.len()]
            },
            acceleration: keep(Derivative::Acceleration, self.linear.acceleration.clone()),
            jerk: keep(Derivative::Jerk, self.linear.jerk.clone()),
            ..self.linear.clone()
        }
    }

    /// Bisection over durations longer than the (infeasible) requested one.
    fn shortest_duration(&self) -> Option<f64> {
        let mut lo = self.duration;
        let mut hi = (2.0 * lo).min(MAX_DURATION_S);
        while !self.linear_feasible(&self.linear, hi) {
            if hi >= MAX_DURATION_S {
                return None;
            }
            lo = hi;
            hi = (2.0 * hi).min(MAX_DURATION_S);
        }
        while hi - lo > DURATION_RELATIVE_TOLERANCE * hi {
            let mid = 0.5 * (lo + hi);
            if self.linear_feasible(&self.linear, mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some((hi * (1.0 + DURATION_MARGIN) * 1000.0).ceil() / 1000.0)
    }

    /// Whether some weights meet `set` over a motion of `duration` seconds
    /// at the grid and the dense verification phases.
    pub(crate) fn linear_feasible(&self, set: &LinearSet, duration: f64) -> bool {
        let mut phases = self.basis.phases().to_vec();
        phases.extend_from_slice(&self.dense_phases);
        let n = self.robot.dof();
        let timing = (duration, self.warp);
        let rows = PhaseRows::new(&self.basis, &self.whitening, n, timing, &phases);
        let ends = PhaseRows::new(&self.basis, &self.whitening, n, timing, &[0.0, 1.0]);
        let mean = &self.prior.mean;
        let mut qp = Qp::new(self.whitening.dim());
        qp.equalities = set.equalities(&ends, mean);
        qp.inequalities = set.weight_bounds(self.whitening.factor(), mean, self.prior.n_basis);
        let mut added = std::collections::HashSet::<RowRef>::new();
        for _ in 0..MAX_GENERATION_ROUNDS {
            let z = match qp.solve(&QpSettings::default()) {
                Ok(sol) => sol.z,
                Err(QpFailure::Infeasible) => return false,
                Err(_) => return false,
            };
            let w = self.whitening.weights(&z);
            let violated: Vec<RowRef> = set
                .violated(&rows, &w, ROW_TOLERANCE)
                .into_iter()
                .filter(|r| !added.contains(r))
                .collect();
            if violated.is_empty() {
                return within_tolerance(set, &rows, &w);
            }
            for r in thinned(set, &rows, &w, &violated) {
                added.insert(r);
                qp.inequalities.push(set.inequality(&rows, mean, r));
            }
        }
        false
    }
}

/// The violated rows `violated` thinned in time ([`thin_in_time`]): the
/// local maxima of each bound's violation, and a stride of the rest.
fn thinned(
    set: &LinearSet,
    rows: &PhaseRows,
    w: &DVector<f64>,
    violated: &[RowRef],
) -> Vec<RowRef> {
    let candidates: Vec<Candidate<(usize, RowKind)>> = violated
        .iter()
        .map(|&r| Candidate {
            key: (r.joint, r.kind),
            phase: rows.phases()[r.phase],
            score: set.excess(rows, w, r),
            in_band: true,
        })
        .collect();
    thin_in_time(&candidates)
        .into_iter()
        .map(|k| violated[k])
        .collect()
}

/// Every row of `set` met at `w` to the verifier's tolerance.
fn within_tolerance(set: &LinearSet, rows: &PhaseRows, w: &DVector<f64>) -> bool {
    set.violated(rows, w, super::tolerances::FEASIBILITY_TOLERANCE)
        .is_empty()
}
