//! Joint position limits between the dense verification samples.
//!
//! A joint that rides its limit bulges past it between two samples by up to
//! `max|q̈| h² / 8` (tens of microradians at the default sampling), which a
//! check at the samples alone cannot see. Each joint's position is a smooth
//! function of the time fraction, so its largest value between two samples
//! is at a sample or at an interior root of its velocity: wherever the
//! velocity changes sign from positive to negative (a peak) or from
//! negative to positive (a trough) between two samples, the root is found
//! by a bracketing search on the velocity (to [`ROOT_TOLERANCE`] in time
//! fraction, where the position is flat to second order) and the position
//! there is checked against the limits. Between two samples 1/600 of the motion
//! apart the velocity changes sign at most once (a reversal and back within
//! a few milliseconds needs jerks far beyond any arm's).
//!
//! The peaks that break a limit are flagged at their own phase, so the
//! optimiser constrains the peak itself; the next peak lies next to it and
//! differs from it in the second order.

use crate::optim::tolerances::FEASIBILITY_TOLERANCE;
use crate::optim::verify::Verifier;
use nalgebra::DMatrix;

/// Width (time fraction) to which a velocity root is found: the position
/// there is within `max|q̈| (ROOT_TOLERANCE · duration)² / 2` of the peak,
/// far below any tolerance.
pub const ROOT_TOLERANCE: f64 = 1e-12;

/// Steps of one root search at most.
const MAX_ROOT_STEPS: usize = 60;

/// The joint extrema between dense samples.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LimitPeaks {
    /// Largest excess (rad) of an interior extremum beyond its joint's
    /// limit (0 when none is beyond).
    pub excess: f64,
    /// Time fractions of the extrema beyond a limit by more than
    /// [`FEASIBILITY_TOLERANCE`].
    pub flagged: Vec<f64>,
}

impl Verifier<'_> {
    /// Every interior extremum of every joint between the dense samples
    /// against the joint's limits; `wm` is the weight matrix (`n_basis ×
    /// n_joints`), `qd` the dense velocities.
    pub(crate) fn limit_peaks(&self, wm: &DMatrix<f64>, qd: &DMatrix<f64>) -> LimitPeaks {
        let mut out = LimitPeaks::default();
        let phases = &self.problem.dense_phases;
        for j in 0..wm.ncols() {
            for p in 0..phases.len().saturating_sub(1) {
                let (va, vb) = (qd[(p, j)], qd[(p + 1, j)]);
                if va * vb >= 0.0 {
                    continue;
                }
                let tau = self.velocity_root(wm, j, phases[p], phases[p + 1], va > 0.0);
                let q = self.joint_position(wm, j, tau);
                let excess =
                    (q - self.problem.linear.upper[j]).max(self.problem.linear.lower[j] - q);
                out.excess = out.excess.max(excess);
                if excess > FEASIBILITY_TOLERANCE {
                    out.flagged.push(tau);
                }
            }
        }
        out.flagged.sort_by(f64::total_cmp);
        out.flagged.dedup();
        out
    }

    /// The root of joint `j`'s velocity between time fractions `lo` and
    /// `hi`, where it is positive at `lo` when `rising` (negative
    /// otherwise) and of the other sign at `hi`: regula falsi with the
    /// Illinois modification (the bracket always holds the root, and the
    /// velocity, nearly linear over one sample interval, converges in a few
    /// steps), until the bracket or the step is below [`ROOT_TOLERANCE`].
    fn velocity_root(&self, wm: &DMatrix<f64>, j: usize, lo: f64, hi: f64, rising: bool) -> f64 {
        let sign = if rising { 1.0 } else { -1.0 };
        // f > 0 at `a`, f < 0 at `b`.
        let f = |tau: f64| sign * self.joint_velocity(wm, j, tau);
        let (mut a, mut b) = (lo, hi);
        let (mut fa, mut fb) = (f(a), f(b));
        let mut x = 0.5 * (a + b);
        let mut side = 0i8;
        for _ in 0..MAX_ROOT_STEPS {
            if b - a <= ROOT_TOLERANCE || fa <= 0.0 || fb >= 0.0 {
                break;
            }
            let next = (a * fb - b * fa) / (fb - fa);
            let next = if next > a && next < b {
                next
            } else {
                0.5 * (a + b)
            };
            let step = (next - x).abs();
            x = next;
            let fx = f(x);
            if fx == 0.0 || step <= ROOT_TOLERANCE {
                break;
            }
            if fx > 0.0 {
                (a, fa) = (x, fx);
                if side == 1 {
                    fb *= 0.5;
                }
                side = 1;
            } else {
                (b, fb) = (x, fx);
                if side == -1 {
                    fa *= 0.5;
                }
                side = -1;
            }
        }
        x
    }

    fn joint_position(&self, wm: &DMatrix<f64>, j: usize, tau: f64) -> f64 {
        let [psi, ..] =
            self.problem
                .warp
                .time_rows(&self.problem.basis, tau, self.problem.duration);
        psi.dot(&wm.column(j))
    }

    fn joint_velocity(&self, wm: &DMatrix<f64>, j: usize, tau: f64) -> f64 {
        let [_, dpsi, ..] =
            self.problem
                .warp
                .time_rows(&self.problem.basis, tau, self.problem.duration);
        dpsi.dot(&wm.column(j))
    }
}

#[cfg(test)]
mod tests {
    use crate::fixtures::{typical_request, ExampleSettings};
    use crate::robot::Robot;

    /// Every velocity reversal between the dense samples of a typical
    /// prior mean: the root found is the one a 60-step bisection finds.
    #[test]
    fn velocity_roots_match_bisection() {
        let robot = Robot::panda().unwrap();
        let p = typical_request(&robot, 3, &ExampleSettings::default())
            .unwrap()
            .validate(&robot)
            .unwrap();
        let wm = p.weight_matrix(&p.prior.mean);
        let qd = &p.dense[1] * &wm;
        let mut reversals = 0;
        for j in 0..wm.ncols() {
            for k in 0..p.dense_phases.len() - 1 {
                let (va, vb) = (qd[(k, j)], qd[(k + 1, j)]);
                if va * vb >= 0.0 {
                    continue;
                }
                reversals += 1;
                let (lo, hi) = (p.dense_phases[k], p.dense_phases[k + 1]);
                let root = p.verifier().velocity_root(&wm, j, lo, hi, va > 0.0);
                let (mut a, mut b) = (lo, hi);
                for _ in 0..60 {
                    let mid = 0.5 * (a + b);
                    if (p.verifier().joint_velocity(&wm, j, mid) > 0.0) == (va > 0.0) {
                        a = mid;
                    } else {
                        b = mid;
                    }
                }
                assert!(
                    (root - 0.5 * (a + b)).abs() < 1e-10,
                    "joint {j}: {root} vs {}",
                    0.5 * (a + b)
                );
            }
        }
        assert!(reversals >= 3, "only {reversals} velocity reversals");
    }
}
