//! Validation of an [`OptimizeRequest`] into a whitened [`Problem`]:
//! every field checked against the robot (errors name the JSON field), the
//! prior repaired when it is not positive semi-definite (with a warning),
//! the whitening, the phase rows and the limit set built.

use super::{
    OptimizeRequest, PriorSpec, Task, MAX_EXTRA_SAMPLES, MAX_OBSTACLES, MAX_PHASE_SAMPLES,
    MAX_REQUEST_POINTS,
};
use crate::error::{ensure_finite, ensure_in_range as check_range, ensure_positive};
use crate::optim::constraints::end_constraints;
use crate::optim::problem::linear::LinearSet;
use crate::optim::problem::phases::{PhaseRows, TimeWarp};
use crate::optim::problem::whiten::Whitening;
use crate::optim::problem::Problem;
use crate::optim::task::{
    Boundary, Goal, SolverOptions, Waypoint, DEFAULT_ACTIVATION_MARGIN_M,
    DEFAULT_WAYPOINT_TOLERANCE_M, MAX_DURATION_S, MAX_ITERATIONS, MAX_RESTARTS, MAX_VIA_POINTS,
};
use crate::promp::annotation::{prior_from_joints, REPAIR_FLOOR_RELATIVE};
use crate::promp::basis::phase_grid;
use crate::promp::smooth::{EndConditions, SmoothnessPrior};
use crate::promp::{repair_covariance, Basis, PrompConfig, WeightDistribution};
use crate::robot::Robot;
use crate::scene::Scene;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Vector3};

impl OptimizeRequest {
    /// Check every field against `robot` and build the whitened problem.
    /// Errors name the JSON field (`prior.cov[3][4]`, `start[2]`,
    /// `obstacles[1].radius`, `duration_s`, ...). An indefinite prior
    /// covariance is repaired and reported as a warning.
    pub fn validate(&self, robot: &Robot) -> Result<Problem> {
        validate_spec(&self.prior, &self.task, robot)
    }
}

/// [`OptimizeRequest::validate`] of the request `prior` + `task`.
pub(crate) fn validate_spec(prior: &PriorSpec, task: &Task, robot: &Robot) -> Result<Problem> {
    let n_basis = task.promp.n_basis;
    task.problem(robot, None, |warnings| {
        prior_distribution(prior, task, robot.dof(), n_basis, warnings)
    })
}

impl Task {
    /// [`OptimizeRequest::validate`] for a prior that is already a
    /// distribution (the network's): the same checks on the same numbers,
    /// errors naming `prior.mean` / `prior.cov[r][c]`, an indefinite
    /// covariance repaired with a warning; no round trip through the wire
    /// format. `basis` is reused when it is the task's ([`Task::basis`]);
    /// another is ignored and the task's built.
    pub fn validate(
        &self,
        robot: &Robot,
        prior: &WeightDistribution,
        basis: &Basis,
    ) -> Result<Problem> {
        self.problem(robot, Some(basis), |warnings| {
            typed_prior(prior, robot.dof(), self.promp.n_basis, warnings)
        })
    }

    /// How the phase advances with time: ramps to rest at both ends for
    /// `boundary: rest`, uniformly for `free`.
    pub fn time_warp(&self) -> TimeWarp {
        match self.boundary {
            Boundary::Rest => TimeWarp::Ramped,
            Boundary::Free => TimeWarp::Identity,
        }
    }

    /// The basis of the task's `promp` (errors name `promp`).
    pub fn basis(&self) -> Result<Basis> {
        Basis::new(&self.promp).map_err(|e| e.within("promp"))
    }

    /// Check every field, then the prior `prior` builds (it runs where the
    /// request's prior has always been checked, so the first error of a
    /// request with several is the same whichever way the prior came).
    fn problem(
        &self,
        robot: &Robot,
        basis: Option<&Basis>,
        prior: impl FnOnce(&mut Vec<String>) -> Result<WeightDistribution>,
    ) -> Result<Problem> {
        let mut warnings = Vec::new();
        self.check_fields(robot)?;
        let scene = Scene::new(self.obstacles.clone())?;
        let activation_m = validate_options(&self.options, self.clearance_m, robot)?;
        let linear = joint_bounds(robot, self.joint_limit_margin_rad, self)?;
        let prior = prior(&mut warnings)?;
        let lambda = match self.options.lambda {
            Some(l) => l,
            None => Whitening::default_lambda(&prior),
        };
        let whitening = Whitening::new(&prior, lambda)?;
        let basis = match basis {
            Some(b) if b.config() == &self.promp => b.clone(),
            _ => Basis::new(&self.promp)?,
        };
        let warp = self.time_warp();
        let timing = (self.duration_s, warp);
        let grid = PhaseRows::new(&basis, &whitening, robot.dof(), timing, basis.phases());
        let end_phases: Vec<f64> = [0.0, 1.0]
            .into_iter()
            .chain(self.via_points.iter().map(|v| v.phase_for(self.duration_s)))
            .collect();
        let ends = PhaseRows::new(&basis, &whitening, robot.dof(), timing, &end_phases);
        let dense_config = PrompConfig {
            n_samples: self.promp.n_samples * self.options.verify_factor,
            ..self.promp.clone()
        };
        dense_config.validate().map_err(|_| {
            Error::invalid(
                "options.verify_factor",
                format!(
                    "promp.n_samples × options.verify_factor = {} × {} = {} dense samples, more than the {} allowed",
                    self.promp.n_samples,
                    self.options.verify_factor,
                    dense_config.n_samples,
                    crate::promp::config::MAX_SAMPLES
                ),
            )
        })?;
        let dense_phases = phase_grid(dense_config.n_samples);
        Ok(Problem {
            robot: robot.clone(),
            scene,
            dense: derivative_matrices(&basis, &dense_phases, timing),
            dense_phases,
            basis,
            prior,
            whitening,
            grid,
            ends,
            linear,
            clearance_m: self.clearance_m,
            activation_m,
            goal: self.goal.clone(),
            end_constraints: end_constraints(self.goal.as_ref(), &self.via_points),
            options: self.options.clone(),
            duration: self.duration_s,
            warp,
            trajectory_format: self.trajectory_format,
            n_extra_samples: self.samples,
            warnings,
        })
    }

    /// The scalar fields, the start, the goal and the scene size: each
    /// within its range, errors naming the field.
    fn check_fields(&self, robot: &Robot) -> Result<()> {
        self.promp.validate().map_err(|e| e.within("promp"))?;
        if self.promp.n_samples > MAX_PHASE_SAMPLES {
            return Err(Error::invalid(
                "promp.n_samples",
                format!(
                    "must be at most {MAX_PHASE_SAMPLES}, got {}",
                    self.promp.n_samples
                ),
            ));
        }
        check_range("duration_s", self.duration_s, 1e-3, MAX_DURATION_S)?;
        check_range("clearance_m", self.clearance_m, 0.0, 1.0)?;
        check_range(
            "joint_limit_margin_rad",
            self.joint_limit_margin_rad,
            0.0,
            1.0,
        )?;
        if self.samples > MAX_EXTRA_SAMPLES {
            return Err(Error::invalid(
                "samples",
                format!("must be at most {MAX_EXTRA_SAMPLES}, got {}", self.samples),
            ));
        }
        if let Some(start) = &self.start {
            robot.validate_configuration("start", start)?;
        }
        if let Some(goal) = &self.goal {
            check_goal(goal)?;
        }
        check_via_points(&self.via_points, self.duration_s, robot)?;
        check_scaling("velocity_scaling", self.velocity_scaling)?;
        check_scaling("acceleration_scaling", self.acceleration_scaling)?;
        for (field, limits) in [
            ("acceleration_limits", &self.acceleration_limits),
            ("jerk_limits", &self.jerk_limits),
        ] {
            if let Some(limits) = limits {
                check_positive_per_joint(field, limits, robot.dof())?;
            }
        }
        let points: usize = self.obstacles.iter().map(|o| o.shape.point_count()).sum();
        if points > MAX_REQUEST_POINTS {
            return Err(Error::invalid(
                "obstacles",
                format!("at most {MAX_REQUEST_POINTS} cloud points in all, got {points}"),
            ));
        }
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(Error::invalid(
                "obstacles",
                format!(
                    "at most {MAX_OBSTACLES} obstacles, got {}",
                    self.obstacles.len()
                ),
            ));
        }
        Ok(())
    }
}

/// The basis rows of the trajectory's time derivatives at the time
/// fractions `phases` ([`TimeWarp::time_rows`]): row `p` of matrix `k` maps
/// one joint's weights to `dᵏq/dtᵏ` at `phases[p]`.
pub(crate) fn derivative_matrices(
    basis: &Basis,
    phases: &[f64],
    (duration, warp): (f64, TimeWarp),
) -> [DMatrix<f64>; 4] {
    let nb = basis.n_basis();
    let mut out: [DMatrix<f64>; 4] = std::array::from_fn(|_| DMatrix::zeros(phases.len(), nb));
    for (p, &z) in phases.iter().enumerate() {
        for (k, row) in warp.time_rows(basis, z, duration).into_iter().enumerate() {
            out[k].row_mut(p).copy_from(&row.transpose());
        }
    }
    out
}

/// A scaling factor must be in (0, 1].
fn check_scaling(field: &str, value: f64) -> Result<()> {
    if value.is_finite() && (MIN_SCALING..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(Error::invalid(
            field,
            format!("must be a number in [{MIN_SCALING}, 1], got {value:e}"),
        ))
    }
}

/// Smallest accepted `velocity_scaling` / `acceleration_scaling`: a
/// thousandth of the robot's limits (smaller ones make every limit ratio
/// overflow, and no motion of a sensible duration meets them).
pub const MIN_SCALING: f64 = 1e-3;

/// One positive finite number per joint.
fn check_positive_per_joint(field: &str, values: &[f64], dof: usize) -> Result<()> {
    if values.len() != dof {
        return Err(Error::invalid(
            field,
            format!(
                "expected {dof} numbers (one per joint), got {}",
                values.len()
            ),
        ));
    }
    values
        .iter()
        .enumerate()
        .try_for_each(|(j, &v)| ensure_positive(&format!("{field}[{j}]"), v))
}

/// Largest accepted deviation of `goal.approach_axis` from unit length
/// (the axis is normalised after the check).
pub const APPROACH_AXIS_NORM_TOLERANCE: f64 = 1e-3;

/// The goal's position, tolerance and approach direction.
fn check_goal(goal: &Goal) -> Result<()> {
    ensure_finite("goal.position", &goal.position)?;
    check_range("goal.tolerance_m", goal.tolerance_m, 1e-6, 1.0)?;
    if let Some(axis) = &goal.approach_axis {
        ensure_finite("goal.approach_axis", axis)?;
        let norm = Vector3::from(*axis).norm();
        if (norm - 1.0).abs() > APPROACH_AXIS_NORM_TOLERANCE {
            return Err(Error::invalid(
                "goal.approach_axis",
                format!("must be a unit vector (length within {APPROACH_AXIS_NORM_TOLERANCE} of 1), got length {norm}"),
            ));
        }
    }
    // Checked with or without an axis: a value out of range is a mistake
    // either way.
    let tol = goal.approach_tolerance_rad;
    if !(tol.is_finite() && tol > 0.0 && tol <= std::f64::consts::PI) {
        return Err(Error::invalid(
            "goal.approach_tolerance_rad",
            format!("must be a number in (0, π], got {tol}"),
        ));
    }
    Ok(())
}

/// Check the solver knobs; returns the activation distance.
fn validate_options(o: &SolverOptions, clearance: f64, robot: &Robot) -> Result<f64> {
    if let Some(l) = o.lambda {
        check_range("options.lambda", l, 1e-15, 1e6)?;
    }
    if !(1..=MAX_ITERATIONS).contains(&o.max_iterations) {
        return Err(Error::invalid(
            "options.max_iterations",
            format!("must be in 1..={MAX_ITERATIONS}, got {}", o.max_iterations),
        ));
    }
    if o.restarts > MAX_RESTARTS {
        return Err(Error::invalid(
            "options.restarts",
            format!("must be in 0..={MAX_RESTARTS}, got {}", o.restarts),
        ));
    }
    if !(4..=32).contains(&o.verify_factor) {
        return Err(Error::invalid(
            "options.verify_factor",
            format!("must be in 4..=32, got {}", o.verify_factor),
        ));
    }
    check_range("options.trust_region", o.trust_region, 1e-6, 1e3)?;
    check_range("options.penalty", o.penalty, 1e-3, 1e9)?;
    check_range("options.qp_tolerance", o.qp_tolerance, 1e-12, 1e-3)?;
    if let Some(q) = &o.final_configuration {
        robot.validate_configuration("options.final_configuration", q)?;
    }
    let activation = o
        .activation_distance_m
        .unwrap_or(clearance + DEFAULT_ACTIVATION_MARGIN_M);
    check_range("options.activation_distance_m", activation, clearance, 10.0)?;
    Ok(activation)
}

/// Joint limits shrunk by the margin, plus the equalities.
fn joint_bounds(robot: &Robot, margin: f64, req: &Task) -> Result<LinearSet> {
    let limits = robot.limits();
    for (j, l) in limits.iter().enumerate() {
        if l.lower + margin >= l.upper - margin {
            return Err(Error::invalid(
                "joint_limit_margin_rad",
                format!(
                    "a margin of {margin} rad leaves no range for joint {} ({}..{})",
                    j + 1,
                    l.lower,
                    l.upper
                ),
            ));
        }
    }
    let acceleration = rate_limits(
        req.acceleration_limits.as_deref(),
        limits.iter().map(|l| l.acceleration),
    )
    .map(|a| a.iter().map(|v| v * req.acceleration_scaling).collect());
    Ok(LinearSet {
        lower: limits.iter().map(|l| l.lower + margin).collect(),
        upper: limits.iter().map(|l| l.upper - margin).collect(),
        velocity: limits
            .iter()
            .map(|l| l.velocity * req.velocity_scaling)
            .collect(),
        acceleration,
        jerk: rate_limits(req.jerk_limits.as_deref(), limits.iter().map(|l| l.jerk)),
        start: req.start.clone(),
        final_configuration: req.options.final_configuration.clone(),
        via: req
            .via_points
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_exact_configuration())
            .filter_map(|(i, v)| Some((2 + i, v.configuration.clone()?)))
            .collect(),
        rest: req.boundary == Boundary::Rest,
        bound_weights: req.options.bound_weights,
    })
}

/// Via points: at most [`MAX_VIA_POINTS`], each with exactly one of
/// `phase` (in (0, 1)) and `time_s` (in (0, `duration_s`)), exactly one of
/// a finite configuration of the robot's size and a finite TCP position
/// within [`MAX_WAYPOINT_DISTANCE_M`] of the base (with its `tolerance_m`
/// in [1e-6, 1] m; none with a configuration), and no two at the same time
/// (to 1e-9 of the motion).
fn check_via_points(via: &[Waypoint], duration_s: f64, robot: &Robot) -> Result<()> {
    if via.len() > MAX_VIA_POINTS {
        return Err(Error::invalid(
            "via_points",
            format!("at most {MAX_VIA_POINTS} via points, got {}", via.len()),
        ));
    }
    let mut phases: Vec<(f64, usize)> = Vec::with_capacity(via.len());
    for (i, v) in via.iter().enumerate() {
        let field = |name: &str| format!("via_points[{i}].{name}");
        match (v.phase, v.time_s) {
            (Some(_), Some(_)) | (None, None) => {
                return Err(Error::invalid(
                    format!("via_points[{i}]"),
                    "give exactly one of `phase` and `time_s`",
                ))
            }
            (Some(p), None) => check_open("phase", &field("phase"), p, 1.0)?,
            (None, Some(t)) => check_open("time", &field("time_s"), t, duration_s)?,
        }
        match (&v.configuration, &v.position) {
            (Some(q), None) => {
                robot.validate_configuration(&field("configuration"), q)?;
                if v.tolerance_m.is_some() {
                    return Err(Error::invalid(
                        field("tolerance_m"),
                        "`tolerance_m` goes with `position`; a configuration takes `tolerance_rad`",
                    ));
                }
                if let Some(t) = v.tolerance_rad {
                    check_range(&field("tolerance_rad"), t, 0.0, std::f64::consts::PI)?;
                }
            }
            (None, Some(p)) => {
                ensure_finite(&field("position"), p)?;
                let norm = Vector3::from(*p).norm();
                if norm > MAX_WAYPOINT_DISTANCE_M {
                    return Err(Error::invalid(
                        field("position"),
                        format!(
                            "must lie within {MAX_WAYPOINT_DISTANCE_M} m of the base, got {norm} m"
                        ),
                    ));
                }
                let tolerance = v.tolerance_m.unwrap_or(DEFAULT_WAYPOINT_TOLERANCE_M);
                check_range(&field("tolerance_m"), tolerance, 1e-6, 1.0)?;
                if v.tolerance_rad.is_some() {
                    return Err(Error::invalid(
                        field("tolerance_rad"),
                        "`tolerance_rad` goes with `configuration`; a position takes `tolerance_m`",
                    ));
                }
            }
            _ => {
                return Err(Error::invalid(
                    format!("via_points[{i}]"),
                    "give exactly one of `configuration` and `position`",
                ))
            }
        }
        phases.push((v.phase_for(duration_s), i));
    }
    phases.sort_by(|a, b| a.0.total_cmp(&b.0));
    for pair in phases.windows(2) {
        if pair[1].0 - pair[0].0 < 1e-9 {
            return Err(Error::invalid(
                format!("via_points[{}]", pair[1].1.max(pair[0].1)),
                format!(
                    "at the same time as via_points[{}]",
                    pair[1].1.min(pair[0].1)
                ),
            ));
        }
    }
    Ok(())
}

/// Farthest a waypoint's TCP position may lie from the base (m).
const MAX_WAYPOINT_DISTANCE_M: f64 = 10.0;

/// `value` strictly between 0 and `end` (the motion's interior).
fn check_open(what: &str, field: &str, value: f64, end: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 && value < end {
        return Ok(());
    }
    Err(Error::invalid(
        field,
        format!("the {what} must lie strictly inside (0, {end}), got {value}"),
    ))
}

/// The request's limits, else the robot's (a joint without one is
/// unbounded); `None` when neither gives any.
fn rate_limits(
    request: Option<&[f64]>,
    robot: impl Iterator<Item = Option<f64>>,
) -> Option<Vec<f64>> {
    if let Some(r) = request {
        return Some(r.to_vec());
    }
    let per_joint: Vec<Option<f64>> = robot.collect();
    per_joint.iter().any(Option::is_some).then(|| {
        per_joint
            .iter()
            .map(|v| v.unwrap_or(f64::INFINITY))
            .collect()
    })
}

/// Whether `prior` is a valid prior for `dof` joints of `n_basis` weights
/// (the check [`Task::validate`] gives it; errors name `prior.…`).
pub fn check_prior(prior: &WeightDistribution, dof: usize, n_basis: usize) -> Result<()> {
    typed_prior(prior, dof, n_basis, &mut Vec::new()).map(|_| ())
}

/// The prior as a (repaired) weight distribution over `dof x n_basis` weights.
fn prior_distribution(
    spec: &PriorSpec,
    task: &Task,
    dof: usize,
    n_basis: usize,
    warnings: &mut Vec<String>,
) -> Result<WeightDistribution> {
    match spec {
        PriorSpec::Smooth => smooth_prior(task, dof),
        PriorSpec::Full { mean, cov } => {
            full_prior(mean, cov, dof, n_basis, warnings).map_err(|e| e.within("prior"))
        }
        PriorSpec::Annotation { annotation } => {
            if annotation.len() != dof {
                return Err(Error::invalid(
                    "prior.annotation",
                    format!("expected {dof} joints, got {}", annotation.len()),
                ));
            }
            let prior =
                prior_from_joints(annotation, n_basis).map_err(|e| e.within("prior.annotation"))?;
            warnings.extend(prior.warnings);
            Ok(prior.distribution)
        }
    }
}

/// The smoothness prior on the task's basis, conditioned on its start, its
/// final configuration (when given) and its boundary.
fn smooth_prior(task: &Task, dof: usize) -> Result<WeightDistribution> {
    let Some(start) = task.start.as_deref() else {
        return Err(Error::invalid(
            "start",
            "required with the smooth prior (a request without `prior`): the prior is the smoothest motion from the start",
        ));
    };
    if start.len() != dof {
        return Err(Error::invalid(
            "start",
            format!("expected {dof} joint values, got {}", start.len()),
        ));
    }
    let warp = task.time_warp();
    let prior = SmoothnessPrior::new(&task.promp, &|tau| warp.at(tau)).map_err(|e| match e {
        Error::Invalid { .. } => e,
        other => other.within("promp"),
    })?;
    prior.conditioned(&EndConditions {
        start,
        end: task.options.final_configuration.as_deref(),
    })
}

fn full_prior(
    mean: &[f64],
    cov: &[Vec<f64>],
    dof: usize,
    n_basis: usize,
    warnings: &mut Vec<String>,
) -> Result<WeightDistribution> {
    let n = dof * n_basis;
    if mean.len() != n {
        return Err(Error::invalid(
            "mean",
            format!(
                "expected {n} numbers ({dof} joints x {n_basis} basis functions), got {}",
                mean.len()
            ),
        ));
    }
    ensure_finite("mean", mean)?;
    if cov.len() != n {
        return Err(Error::invalid(
            "cov",
            format!("expected {n} rows, got {}", cov.len()),
        ));
    }
    for (r, row) in cov.iter().enumerate() {
        if row.len() != n {
            return Err(Error::invalid(
                format!("cov[{r}]"),
                format!(
                    "expected {n} numbers (the covariance must be square), got {}",
                    row.len()
                ),
            ));
        }
        ensure_finite(&format!("cov[{r}]"), row)?;
    }
    let matrix = DMatrix::from_fn(n, n, |r, c| cov[r][c]);
    let dist = WeightDistribution::new(DVector::from_column_slice(mean), matrix, dof, n_basis)?;
    Ok(repaired(dist, warnings))
}

/// A typed prior checked as [`full_prior`] checks the wire's (its size for
/// `dof` joints of `n_basis` weights, finite, symmetric; then the repair),
/// on the same numbers, so both ways give the same problem.
fn typed_prior(
    prior: &WeightDistribution,
    dof: usize,
    n_basis: usize,
    warnings: &mut Vec<String>,
) -> Result<WeightDistribution> {
    let dist = WeightDistribution::new(prior.mean.clone(), prior.cov.clone(), dof, n_basis)
        .map_err(|e| e.within("prior"))?;
    Ok(repaired(dist, warnings))
}

/// `dist` with its covariance's eigenvalues clipped when it is not
/// positive semi-definite (a warning says so).
fn repaired(dist: WeightDistribution, warnings: &mut Vec<String>) -> WeightDistribution {
    let scale = dist.cov.symmetric_eigenvalues().amax();
    let (repaired, min_eig, changed) = repair_covariance(&dist.cov, REPAIR_FLOOR_RELATIVE * scale);
    if changed {
        warnings.push(format!(
            "prior covariance is not positive semi-definite (min eigenvalue {min_eig:.3e}); eigenvalues clipped to {:.3e}",
            REPAIR_FLOOR_RELATIVE * scale
        ));
    }
    WeightDistribution {
        cov: repaired,
        ..dist
    }
}
