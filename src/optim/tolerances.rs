//! Every tolerance and convergence threshold of the optimiser, in one
//! place: what counts as satisfied, converged, active or tiny, and the
//! margins the QPs aim for. Units are the constraint's own (m, rad, rad/s)
//! unless stated.

// Feasibility (what the report and `optimal` accept).

/// Tolerance (m, rad, ratio) within which a constraint counts as satisfied.
pub const FEASIBILITY_TOLERANCE: f64 = 1e-6;

/// Linear rows count as satisfied within this (rad, rad/s).
pub const LINEAR_TOLERANCE: f64 = 1e-7;

/// Clearance the QP aims for beyond `clearance_m` (m), so that small
/// linearisation and sampling errors do not leave the true trajectory just
/// short of the requirement.
pub const CLEARANCE_BUFFER_M: f64 = 2e-4;

/// Largest extra clearance (m) the optimiser keeps at a phase where the
/// verification found the trajectory too close between the optimisation
/// phases: each such round raises the flagged phases' target by the
/// deficit it measured, up to this. A corner of an obstacle passed at
/// 0.5 m/s between phases 20 ms apart comes up to 5 mm closer than at the
/// phases themselves.
pub const MAX_CLEARANCE_MARGIN_M: f64 = 5e-3;

/// Largest raise (m) of a phase's extra clearance in one verification
/// round: the certificate's bound between samples can overstate how far in
/// the trajectory comes, so a large deficit is closed over several rounds.
pub const MAX_MARGIN_STEP_M: f64 = 1e-3;

/// Goal tolerance the QP aims for: `tolerance_m` less a buffer of
/// [`CLEARANCE_BUFFER_M`] (at most half the tolerance), for the same reason.
pub fn buffered_tolerance(tolerance_m: f64) -> f64 {
    tolerance_m - CLEARANCE_BUFFER_M.min(0.5 * tolerance_m)
}

/// Angle (rad) the QP keeps inside `goal.approach_tolerance_rad` (at most
/// half the tolerance), for the same reason as [`CLEARANCE_BUFFER_M`].
pub const APPROACH_BUFFER_RAD: f64 = 2e-4;

/// Approach tolerance the QP aims for.
pub fn buffered_angle(tolerance_rad: f64) -> f64 {
    tolerance_rad - APPROACH_BUFFER_RAD.min(0.5 * tolerance_rad)
}

// SCP convergence and trust region.

/// An iterate whose next step is predicted to improve the merit by less
/// than this fraction of it has converged when feasible (the tail of SCP
/// on curved constraints is linear) and has stalled when not (exact
/// generation or a larger penalty follows). A converged iterate is then
/// certified by Clarabel's final QP, whose step is taken exactly, so this
/// does not limit the accuracy on convex problems.
pub const OPTIMALITY_TOLERANCE: f64 = 1e-3;

/// Smallest trust-region half-width before the iteration counts as stalled.
pub const MIN_TRUST_REGION: f64 = 1e-4;

/// Largest trust-region half-width.
pub const MAX_TRUST_REGION: f64 = 1e3;

/// Largest L1 penalty before slack is declared irreducible.
pub const MAX_PENALTY: f64 = 1e6;

/// A certifying step longer than this fraction of the trust radius counts
/// as held by the ball (not a KKT point of the linearised problem).
pub const BALL_ACTIVE_FRACTION: f64 = 0.99;

// Working set and constraint generation.

/// A candidate row the QP solution breaks by more than this (rad, rad/s or
/// m) joins the working set.
pub const GENERATION_TOLERANCE: f64 = 1e-8;

/// Clearance rows within this much of the target (m) start in the working
/// set of each QP; the rest join by constraint generation.
pub const CLEARANCE_BAND_M: f64 = 3e-3;

/// Multipliers below this fraction of the largest one count as inactive.
pub const ACTIVE_DUAL_FRACTION: f64 = 1e-6;

// QP solves.

/// The final QP is solved [`CERTIFY_TIGHTENING`] times tighter than
/// `options.qp_tolerance` (at least 1e-12), so that on a convex problem
/// the answer meets the closed form to about 1e-8; if Clarabel cannot reach
/// that, at the requested tolerance.
pub const CERTIFY_TIGHTENING: f64 = 1e-2;

/// A cone broken by more than this (its units) at a solution gets a cut.
pub const CONE_TOLERANCE: f64 = 1e-9;

/// The proximal search stops once the step fills this fraction of the
/// ball (the SCP counts such a step as held by the ball).
pub const TRUST_FILL: f64 = 0.6;

/// A step this fraction longer than the radius is accepted (the ball only
/// limits the step; it need not hold exactly).
pub const TRUST_OVERSHOOT: f64 = 0.25;
