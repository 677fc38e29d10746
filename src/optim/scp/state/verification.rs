//! The run's verification steps: certify-then-verify a converged
//! iterate, screen one before certifying once the run has dipped between
//! its phases, and add the phases a verification flagged (with their
//! raised margins) to the optimisation set.

use super::{Flow, Phase, Scp};
use crate::optim::report::{FinalQp, TrajectoryReport};
use crate::optim::solution::timed;
use crate::optim::stop_reason::StopReason;
use crate::optim::tolerances::{MAX_CLEARANCE_MARGIN_M, MAX_MARGIN_STEP_M};
use crate::optim::verify::Verification;

impl Scp<'_> {
    /// Step 1: a converged feasible iterate is certified by Clarabel, then
    /// verified densely; `optimal` when verification passes, otherwise the
    /// flagged phases join the optimisation set.
    pub(super) fn finish_or_certify(&mut self) -> Flow {
        if !(self.phase.converged() && self.eval.feasible()) {
            return Flow::Continue;
        }
        let (final_qp, unverified) = match &self.phase {
            Phase::Centre => (FinalQp::not_needed(), Phase::Descend),
            Phase::Certified(final_qp) => (final_qp.clone(), Phase::Certify),
            _ if self.dipped && !self.screened_here() => return self.screen(),
            _ => {
                self.start_certifying();
                return Flow::Continue;
            }
        };
        let p = self.problem;
        let v = match self.screened.take() {
            Some((w, v)) if w == self.eval.w => {
                self.stats.screens.1 += 1;
                v
            }
            _ => self.verify_here(),
        };
        if let Some(why) = v.interrupted {
            return self.stopped_early(why, Some(v));
        }
        if v.flagged.is_empty() && p.is_feasible(&v.report) {
            self.stats.final_penalty = self.rho;
            let mut sol = self.solution(StopReason::Converged, Some(v), None, &[]);
            sol.report.final_qp = Some(final_qp);
            return Flow::Done(Box::new(sol));
        }
        self.dipped = true;
        let (added, raised) = self.add_flagged(&v, "verification");
        if added + raised == 0 {
            let reason = "dense verification failed on a constraint the optimiser cannot refine (goal or equality)";
            return self.answer(
                StopReason::VerificationFailed,
                Some(v),
                Some(reason.into()),
                &[],
            );
        }
        self.reevaluate();
        self.phase = unverified;
        Flow::Continue
    }

    /// Step 1 once the run has dipped between its phases: a converged
    /// feasible iterate is verified densely *before* Clarabel certifies it.
    /// Flagged phases join, and the run goes on from the point as after a
    /// failed verification (a Clarabel QP on the grown phase set, which
    /// measured better than descending on the active-set method): the
    /// certifying QPs that would have preceded that verification, two to
    /// four at 5-10 ms on a MotionBenchMaker plan, are saved. A clean
    /// point goes to certification, and keeps this verification if
    /// certification leaves it where it is.
    fn screen(&mut self) -> Flow {
        self.stats.screens.0 += 1;
        let p = self.problem;
        let v = self.verify_here();
        if let Some(why) = v.interrupted {
            return self.stopped_early(why, Some(v));
        }
        let clean = v.flagged.is_empty() && p.is_feasible(&v.report);
        if !clean {
            let (added, raised) = self.add_flagged(&v, "screening");
            if added + raised > 0 {
                self.reevaluate();
                self.start_certifying();
                return Flow::Continue;
            }
        }
        // Clean, or nothing left to refine: certification decides.
        self.screened = Some((self.eval.w.clone(), v));
        self.start_certifying();
        Flow::Continue
    }

    /// Dense verification of the current iterate, timed.
    fn verify_here(&mut self) -> Verification {
        let (p, ctl, w) = (self.problem, self.ctl, &self.eval.w);
        timed(&mut self.stats.verification_ms, || {
            p.verifier().verify(w, ctl)
        })
    }

    /// The next QP is Clarabel's certifying one, its ball at least the
    /// initial radius.
    fn start_certifying(&mut self) {
        self.phase = Phase::Certify;
        self.radius = self.radius.max(self.problem.options.trust_region);
    }

    /// Whether the current iterate is the last one screened.
    fn screened_here(&self) -> bool {
        self.screened
            .as_ref()
            .is_some_and(|(w, _)| *w == self.eval.w)
    }

    /// The iterate evaluated again on the (grown) optimisation phases.
    fn reevaluate(&mut self) {
        let (p, ctl) = (self.problem, self.ctl);
        let z = self.eval.z.clone();
        self.eval = timed(&mut self.stats.evaluation_ms, || {
            p.evaluate_grid(&self.rows, z, self.centre, ctl)
        });
    }

    /// Add (a spread-out subset of) the phases dense verification flagged
    /// to the optimisation phases, and raise their extra clearance by the
    /// verification's clearance deficit ([`clearance_deficit`], at most
    /// [`MAX_MARGIN_STEP_M`] per round), so
    /// that a trajectory that dipped between the phases is held farther
    /// out there, not only at the phases; returns how many phases were new
    /// and how many margins changed (`stage`, which step verified, is for
    /// the log).
    fn add_flagged(&mut self, v: &Verification, stage: &str) -> (usize, usize) {
        let p = self.problem;
        let deficit = clearance_deficit(p.clearance_m, &v.report).min(MAX_MARGIN_STEP_M);
        let rows = self.rows.to_mut();
        let before = rows.len();
        let stride = v.flagged.len().div_ceil(MAX_ADDED_PER_ROUND).max(1);
        let mut raised = 0;
        for &phase in v.flagged.iter().step_by(stride) {
            let i = rows.push(&p.basis, &p.whitening, phase);
            raised += usize::from(rows.raise_margin(i, deficit, MAX_CLEARANCE_MARGIN_M));
        }
        let added = rows.len() - before;
        self.stats.added_phases += added;
        tracing::debug!(
            stage,
            iteration = self.stats.iterations,
            flagged = v.flagged.len(),
            added,
            raised,
            deficit = clearance_deficit(p.clearance_m, &v.report),
            grid = self.rows.len(),
            dense_clearance = v.report.min_clearance_m,
            continuous_clearance = v.report.continuous_clearance_m,
            "dense verification flagged phases"
        );
        (added, raised)
    }
}

/// Most phases added per dense verification round.
const MAX_ADDED_PER_ROUND: usize = 64;

/// How far (m) the verified trajectory comes inside `clearance_m`: at the
/// closest dense sample when that one is inside (a measured distance), else
/// by the continuous certificate between the samples (zero when both keep
/// the clearance or the scene is empty). The certificate's bound is only
/// read when every sample clears: next to a sample inside the clearance it
/// is not bisected and says little about how far out the trajectory must go.
fn clearance_deficit(clearance_m: f64, report: &TrajectoryReport) -> f64 {
    let closest = match report.min_clearance_m {
        Some(dense) if dense < clearance_m => dense,
        _ => report
            .continuous_clearance_m
            .into_iter()
            .chain(report.min_clearance_m)
            .fold(f64::INFINITY, f64::min),
    };
    (clearance_m - closest).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_deficit_is_the_closest_figure_inside_the_clearance() {
        let report = |dense: Option<f64>, continuous: Option<f64>| TrajectoryReport {
            min_clearance_m: dense,
            continuous_clearance_m: continuous,
            ..Default::default()
        };
        let deficit = |r: &TrajectoryReport| clearance_deficit(0.005, r);
        assert_eq!(deficit(&report(None, None)), 0.0, "no obstacles");
        assert_eq!(deficit(&report(Some(0.006), Some(0.0052))), 0.0);
        assert!((deficit(&report(Some(0.0052), Some(0.0043))) - 0.0007).abs() < 1e-15);
        assert!((deficit(&report(Some(0.004), Some(0.0045))) - 0.001).abs() < 1e-15);
        // Next to a sample inside, the certificate's unbisected bound is
        // not read.
        assert!((deficit(&report(Some(0.004), Some(-0.003))) - 0.001).abs() < 1e-15);
        assert!((deficit(&report(Some(-0.01), None)) - 0.015).abs() < 1e-15);
    }
}
