//! More basis functions when the motion needs them: a request on the
//! smoothness prior's default basis whose solve finds no certified answer
//! is solved again on finer bases.
//!
//! The smoothness prior ([`crate::promp::smooth`]) is not learned: it is
//! the integrated squared acceleration on whatever basis the request uses,
//! so the same prior exists on any number of basis functions, and on more
//! of them it can bend more. Its default, [`SMOOTH_N_BASIS`] functions,
//! keeps the QP small for the motions most requests ask; a path out of a
//! shelf, under a table and up to a grasp, or round a box's rim, may need
//! more bends than it has, and the solve then ends `max_iterations`
//! (a local minimum of the violation, or an iteration limit while the
//! certificate keeps finding the trajectory dipping between its phases).
//! So when a solve on the default basis ends `max_iterations` for such a
//! reason (not the caller's deadline or cancel flag), the same request is
//! solved on [`FINER_BASES`] functions in turn (each Gaussian's width the
//! spacing of their centres, as the default's:
//! [`smooth_basis_config_with`]); the first `optimal` answer is the
//! response, with its basis in [`OptimizeResponse::promp`] and a warning
//! saying why. When none is `optimal`, the default basis's answer stands.
//!
//! The finer prior is the same smoothness functional on a larger space, so
//! its Mahalanobis distance is measured against that prior (the answer's
//! `mahalanobis` and `prior_mean_report` are the finer problem's), and the
//! certificate is unchanged: the answer is the finer problem's `optimal`,
//! verified densely and continuously like any other. A request that sets
//! `promp` to something else than the default, or whose prior is learned
//! (a mean and covariance, an annotation: its basis is part of it), or
//! with `options.refine_basis: false`, keeps its basis.
//!
//! The answer on a finer basis is the answer of the same request with
//! `promp` set to that basis, byte for byte (the solve is deterministic):
//! a caller can reproduce it, and `duration: auto` retimes it on that
//! basis ([`super::auto_duration`]).

use super::report::{OptimizeResponse, Status};
use super::request::{OptimizeRequest, PriorSpec};
use super::solution::SolveControl;
use crate::promp::smooth::{smooth_basis_config, smooth_basis_config_with, SMOOTH_N_BASIS};
use crate::Result;
use std::time::Instant;

/// The finer bases tried in turn (functions per joint). Measured on the
/// MotionBenchMaker problems the default basis left uncertified
/// (docs/experiments.md): 16, 20 and 24 functions each certified about half
/// of them, different halves, and of those 20 and 24 left, 16, 28 and 32
/// two or three each; each step costs one more solve on a request that had
/// failed.
pub const FINER_BASES: [usize; 3] = [20, 24, 28];

/// Whether a failed solve of `request` is tried again on finer bases: the
/// smoothness prior on its default basis, with `options.refine_basis`.
pub fn refinable(request: &OptimizeRequest) -> bool {
    matches!(request.prior, PriorSpec::Smooth)
        && request.task.promp == smooth_basis_config()
        && request.task.options.refine_basis
}

/// `answer` (of `request`, on its basis) when it is `optimal`, a proof, a
/// stop by the caller, or `request` is not [`refinable`]; otherwise the
/// first `optimal` answer of `request` on [`FINER_BASES`] (`solve` answers
/// a request on its own basis), else `answer`. `report.solve_ms` counts
/// every solve.
pub fn refine(
    request: &OptimizeRequest,
    answer: OptimizeResponse,
    ctl: &SolveControl,
    solve: &dyn Fn(&OptimizeRequest) -> Result<OptimizeResponse>,
) -> Result<OptimizeResponse> {
    if answer.status != Status::MaxIterations || !refinable(request) {
        return Ok(answer);
    }
    let started = Instant::now();
    for n_basis in FINER_BASES {
        if ctl.should_stop() {
            break;
        }
        let mut finer = request.clone();
        finer.task.promp = smooth_basis_config_with(n_basis);
        let mut found = solve(&finer)?;
        if found.status == Status::Optimal {
            found.report.warnings.push(format!(
                "the smoothness prior's default basis ({SMOOTH_N_BASIS} functions per joint) found no certified answer ({}); {n_basis} functions did: `weights` are on the basis in `promp`",
                answer.reason.as_deref().unwrap_or("no reason given")
            ));
            found.report.solve_ms = answer.report.solve_ms + started.elapsed().as_secs_f64() * 1e3;
            found.promp = Some(finer.task.promp);
            return Ok(found);
        }
    }
    Ok(answer)
}

/// `request` on the basis `answer`'s weights are on: its own, or the finer
/// one [`refine`] chose (to validate the problem the weights belong to).
pub fn on_answer_basis(request: &OptimizeRequest, answer: &OptimizeResponse) -> OptimizeRequest {
    let mut at = request.clone();
    if let Some(promp) = &answer.promp {
        at.task.promp = promp.clone();
    }
    at
}
