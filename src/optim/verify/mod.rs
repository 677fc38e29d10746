//! Dense verification: every constraint evaluated at `verify_factor` times
//! the optimisation sampling, with real forward kinematics and distances to
//! the robot's mesh hulls, plus the continuous-motion clearance bound
//! between the samples ([`crate::optim::verify::continuous`]) and every
//! joint's peaks and troughs between them against its position limits
//! ([`crate::optim::verify::limits`]). The report the user sees always
//! comes from here.
//!
//! The checks live on [`Verifier`] (a problem's [`Problem::verifier`]), apart
//! from the problem's data and from the solver that asks them; the public
//! [`Problem::evaluate`] is a [`Verifier::verify`]'s report.

pub mod continuous;
pub mod limits;

use crate::optim::problem::linear::RATE_BUFFER;
use crate::optim::problem::phases::Derivative;
use crate::optim::problem::Problem;
use crate::optim::report::{Closest, TrajectoryReport};
use crate::optim::solution::SolveControl;
use crate::optim::tolerances::FEASIBILITY_TOLERANCE;
use crate::scene::Clearance;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// A dense check: the report plus the phases where something is violated.
#[derive(Clone, Debug)]
pub struct Verification {
    /// Figures over the dense phases.
    pub report: TrajectoryReport,
    /// Phases with a violated limit, velocity or clearance: dense samples,
    /// joint peaks between them, and the certificate's uncertified
    /// intervals (sorted, each once).
    pub flagged: Vec<f64>,
    /// Why the clearance part was not finished (the caller's deadline or
    /// cancel flag): the report then has no clearance figures, a warning
    /// says so, and it is never feasible.
    pub interrupted: Option<crate::optim::stop_reason::Interruption>,
}

/// The dense and continuous checks of a [`Problem`]'s trajectories: what
/// the SCP asks before it calls an iterate `optimal`, and what every
/// answer's report comes from. It reads the problem, never changes it.
#[derive(Clone, Copy, Debug)]
pub struct Verifier<'a> {
    problem: &'a Problem,
}

impl Problem {
    /// The verifier of this problem's trajectories.
    pub fn verifier(&self) -> Verifier<'_> {
        Verifier { problem: self }
    }

    /// Dense verification of any candidate weights (length must be the
    /// prior's dimension; other lengths give an all-violated report).
    pub fn evaluate(&self, weights: &[f64]) -> TrajectoryReport {
        self.evaluate_with(weights, &SolveControl::default())
    }

    /// [`Problem::evaluate`] that stops at `ctl`'s deadline or cancel flag
    /// (see [`Verification::interrupted`]).
    pub fn evaluate_with(&self, weights: &[f64], ctl: &SolveControl) -> TrajectoryReport {
        self.verifier()
            .verify(&DVector::from_column_slice(weights), ctl)
            .report
    }
}

impl Verifier<'_> {
    /// Dense verification with the violated phases. The limit, rate and
    /// goal figures are matrix products and always computed; the clearance
    /// part (forward kinematics and distances at every dense phase, then the
    /// continuous certificate) checks `ctl` as it goes and stops with it.
    pub fn verify(&self, w: &DVector<f64>, ctl: &SolveControl) -> Verification {
        if w.len() != self.problem.prior.dim() || w.iter().any(|v| !v.is_finite()) {
            return Verification {
                report: TrajectoryReport {
                    max_joint_limit_violation_rad: f64::INFINITY,
                    max_velocity_ratio: f64::INFINITY,
                    warnings: vec!["weights have the wrong length or are not finite".into()],
                    ..Default::default()
                },
                flagged: Vec::new(),
                interrupted: None,
            };
        }
        let wm = self.problem.weight_matrix(w);
        let q = &self.problem.dense[0] * &wm;
        let qd = &self.problem.dense[1] * &wm;
        let mut flagged = vec![false; self.problem.dense_phases.len()];
        let limit = self.limit_violation(&q, &mut flagged);
        let peaks = self.limit_peaks(&wm, &qd);
        let ratio = self.rate_ratio(Derivative::Velocity, &qd, &mut flagged);
        let mut limited_ratio = |d: Derivative| {
            self.problem.linear.rate_bound(d, 0).map(|_| {
                let m = &self.problem.dense[d.order()] * &wm;
                self.rate_ratio(d, &m, &mut flagged)
            })
        };
        let acceleration_ratio = limited_ratio(Derivative::Acceleration);
        let jerk_ratio = limited_ratio(Derivative::Jerk);
        let dense = self.dense_clearance(&q, &mut flagged, ctl);
        let certificate = match &dense {
            Some((Some(_), _, per_phase)) => {
                self.continuous_certificate(&wm, &q, &qd, per_phase, ctl)
            }
            _ => None,
        };
        let interrupted = match (&dense, &certificate) {
            (None, _) => ctl.stop_reason(),
            (Some((Some(_), ..)), None) => ctl.stop_reason(),
            _ => None,
        };
        let (min_clearance, closest, _) = dense.unwrap_or((None, None, Vec::new()));
        let mut report = TrajectoryReport {
            min_clearance_m: min_clearance,
            closest,
            continuous_clearance_m: certificate.as_ref().map(|c| c.clearance_m),
            continuous_margin_m: certificate.as_ref().map(|c| c.margin_m),
            max_joint_limit_violation_rad: limit.max(peaks.excess),
            max_velocity_ratio: ratio,
            max_acceleration_ratio: acceleration_ratio,
            max_jerk_ratio: jerk_ratio,
            verified_samples: if interrupted.is_some() {
                0
            } else {
                self.problem.dense_phases.len()
            },
            equality_error_rad: self.problem.linear.equality_error(&self.problem.ends, w),
            weight_bound_excess: self
                .problem
                .linear
                .weight_bound_excess(w, self.problem.prior.n_basis)
                .max(0.0),
            ..Default::default()
        };
        for c in &self.problem.end_constraints {
            let q = self.problem.ends.position(c.phase(), w);
            c.report(&self.problem.robot, &q, &mut report);
        }
        let mut flagged: Vec<f64> = flagged
            .iter()
            .zip(&self.problem.dense_phases)
            .filter(|(f, _)| **f)
            .map(|(_, p)| *p)
            .collect();
        flagged.extend(peaks.flagged);
        if let Some(c) = certificate {
            flagged.extend(c.flagged);
        }
        flagged.sort_by(f64::total_cmp);
        flagged.dedup();
        if let Some(why) = interrupted {
            report.min_clearance_m = None;
            report.closest = None;
            report.continuous_clearance_m = None;
            report.continuous_margin_m = None;
            report.warnings.push(format!(
                "clearance not verified: dense verification stopped ({why})"
            ));
            flagged.clear();
        }
        Verification {
            report,
            flagged,
            interrupted,
        }
    }

    fn limit_violation(&self, q: &DMatrix<f64>, flagged: &mut [bool]) -> f64 {
        let mut worst: f64 = 0.0;
        for (p, flag) in flagged.iter_mut().enumerate() {
            for j in 0..q.ncols() {
                let v = q[(p, j)];
                let excess =
                    (v - self.problem.linear.upper[j]).max(self.problem.linear.lower[j] - v);
                if excess > FEASIBILITY_TOLERANCE {
                    *flag = true;
                }
                worst = worst.max(excess);
            }
        }
        worst
    }

    /// Largest `|value| / bound` of derivative `d` (`values`: one row per
    /// dense phase); flags the phases above 1.
    ///
    /// Acceleration and jerk phases are flagged once they use more than half
    /// of the QP rows' [`RATE_BUFFER`]: the rows then join there, so that
    /// the peaks between verification samples stay within the limit too.
    fn rate_ratio(&self, d: Derivative, values: &DMatrix<f64>, flagged: &mut [bool]) -> f64 {
        let flag_above = match d {
            Derivative::Acceleration | Derivative::Jerk => 1.0 - 0.5 * RATE_BUFFER,
            _ => 1.0 + FEASIBILITY_TOLERANCE,
        };
        let mut worst: f64 = 0.0;
        for (p, flag) in flagged.iter_mut().enumerate() {
            for j in 0..values.ncols() {
                let bound = self
                    .problem
                    .linear
                    .rate_bound(d, j)
                    .unwrap_or(f64::INFINITY);
                let ratio = values[(p, j)].abs() / bound;
                if ratio > flag_above {
                    *flag = true;
                }
                worst = worst.max(ratio);
            }
        }
        worst
    }

    /// Closest pair per dense phase (pairs within the activation distance
    /// via the broad phase; the exact minimum when nothing is that close):
    /// the minimum, where it occurs, and each phase's distance (`None`: at
    /// least the activation distance). `None` when `ctl` stopped it.
    fn dense_clearance(
        &self,
        q: &DMatrix<f64>,
        flagged: &mut [bool],
        ctl: &SolveControl,
    ) -> Option<DenseClearance> {
        if self.problem.scene.is_empty() {
            return Some((None, None, Vec::new()));
        }
        let rows: Vec<Vec<f64>> = (0..q.nrows())
            .map(|p| q.row(p).iter().cloned().collect())
            .collect();
        let near: Vec<Option<Clearance>> = per_row_unless_stopped(&rows, ctl, |qp| {
            let frames = self.problem.robot.fk(qp);
            self.problem.scene.closest_within(
                &self.problem.robot,
                &frames,
                self.problem.activation_m,
            )
        })?;
        let per_phase: Vec<Option<Clearance>> = if near.iter().any(|c| c.is_some()) {
            near
        } else {
            per_row_unless_stopped(&rows, ctl, |qp| {
                let frames = self.problem.robot.fk(qp);
                self.problem
                    .scene
                    .min_clearance(&self.problem.robot, &frames)
            })?
        };
        let mut best: Option<(usize, &Clearance)> = None;
        for (p, c) in per_phase.iter().enumerate() {
            if let Some(c) = c {
                if c.distance < self.problem.clearance_m - FEASIBILITY_TOLERANCE {
                    flagged[p] = true;
                }
                if best.is_none_or(|(_, b)| c.distance < b.distance) {
                    best = Some((p, c));
                }
            }
        }
        let distances = per_phase
            .iter()
            .map(|c| c.as_ref().map(|c| c.distance))
            .collect();
        Some(match best {
            None => (None, None, distances),
            Some((p, c)) => (
                Some(c.distance),
                Some(Closest {
                    link: c.link_name(&self.problem.robot).to_string(),
                    obstacle: c.obstacle_id(&self.problem.scene).to_string(),
                    time_s: self.problem.dense_phases[p] * self.problem.duration,
                }),
                distances,
            ),
        })
    }
}

/// The closest distance, where it occurs, and each dense phase's distance.
type DenseClearance = (Option<f64>, Option<Closest>, Vec<Option<f64>>);

/// `f` of every row in parallel, or `None` once `ctl` says stop (the rows
/// not yet started are skipped, so a stop takes effect within one row).
pub(crate) fn per_row_unless_stopped<R, T, F>(
    rows: &[R],
    ctl: &SolveControl,
    f: F,
) -> Option<Vec<T>>
where
    R: Sync,
    T: Send,
    F: Fn(&R) -> T + Sync,
{
    let one = |row: &R| (!ctl.should_stop()).then(|| f(row));
    if ctl.parallel() {
        rows.par_iter().map(one).collect()
    } else {
        rows.iter().map(one).collect()
    }
}
