//! One convex subproblem in the whitened coordinates, solved by Clarabel.
//!
//! Variables `x = [z, s]`: the whitened weights and one non-negative slack
//! per soft row. Objective `|z - c|² + Σ ρ_i s_i` (c = 0 when solving
//! towards the prior mean, the whitened draw when projecting a sample).
//! Rows: equalities `a·z = b`, hard and soft (slacked) inequalities
//! `a·z ≤ b (+ s)`, second-order cones `|g0 + G z| ≤ r (+ s)` (the goal),
//! and an optional trust-region ball `|z - z_k|₂ ≤ Δ` (a second-order cone:
//! in whitened coordinates that is a Mahalanobis ball, and it costs one cone
//! instead of 2 x dim rows). The equalities never reach Clarabel: they are
//! eliminated by a [`NullSpace`] basis, which keeps the cost and the trust
//! ball isotropic and makes every dense row shorter. The constraint matrix
//! is built column by column straight into Clarabel's CSC format.

pub mod active_set;
pub mod dual_active_set;
pub mod nullspace;

use crate::optim::qp::nullspace::NullSpace;
use crate::Error;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::{DMatrix, DVector};

/// A row `a·z ≤ b`, with an L1-penalised slack when `penalty` is set.
#[derive(Clone, Debug)]
pub struct Inequality {
    /// Coefficients on `z`.
    pub a: DVector<f64>,
    /// Right-hand side.
    pub b: f64,
    /// Weight of the slack in the objective, `None` for a hard row.
    pub penalty: Option<f64>,
}

/// `|offset + matrix z| ≤ radius (+ s)`, slack weight `penalty`.
#[derive(Clone, Debug)]
pub struct Cone {
    /// Constant part of the vector.
    pub offset: DVector<f64>,
    /// Linear part (`k x dim z`).
    pub matrix: DMatrix<f64>,
    /// Allowed norm.
    pub radius: f64,
    /// Weight of the slack in the objective.
    pub penalty: f64,
}

/// Settings of each Clarabel solve.
#[derive(Clone, Debug)]
pub struct QpSettings {
    /// Clarabel's gap and feasibility tolerances.
    pub tolerance: f64,
    /// Clarabel's iteration limit.
    pub max_iterations: u32,
    /// Seconds left before the caller's deadline (`None`: no limit).
    pub time_limit: Option<f64>,
}

impl Default for QpSettings {
    fn default() -> Self {
        QpSettings {
            tolerance: 1e-9,
            max_iterations: 200,
            time_limit: None,
        }
    }
}

/// A convex subproblem (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct Qp {
    /// Centre `c` of the cost `|z - c|²`.
    pub center: DVector<f64>,
    /// Equalities `a·z = b`.
    pub equalities: Vec<(DVector<f64>, f64)>,
    /// Inequalities.
    pub inequalities: Vec<Inequality>,
    /// Second-order cones.
    pub cones: Vec<Cone>,
    /// Trust region: centre and radius of a ball on `z`.
    pub trust: Option<(DVector<f64>, f64)>,
}

/// What Clarabel returned.
#[derive(Clone, Debug)]
pub struct QpSolution {
    /// Optimal `z`.
    pub z: DVector<f64>,
    /// Slack of each soft inequality (in `inequalities` order, 0 for hard rows).
    pub inequality_slacks: Vec<f64>,
    /// Slack of each cone.
    pub cone_slacks: Vec<f64>,
    /// Objective value `|z - c|² + Σ ρ s`.
    pub objective: f64,
    /// Multipliers of the inequalities (>= 0).
    pub inequality_duals: Vec<f64>,
    /// Number of rows of the constraint matrix Clarabel solved (equalities
    /// eliminated).
    pub rows: usize,
    /// Number of variables Clarabel solved (equalities eliminated).
    pub variables: usize,
    /// Interior-point iterations Clarabel took (0 for the active-set path).
    pub ipm_iterations: u32,
    /// Multiplier steps of the dual active-set solver (0 for Clarabel).
    pub active_set_steps: usize,
    /// Clarabel's status and residuals (`None` for the active-set path).
    pub clarabel: Option<ClarabelInfo>,
    /// The active-set path's row states by inequality index: the warm
    /// start of the next solve over the same rows (plus new ones).
    pub row_states: Option<crate::optim::qp::dual_active_set::WarmStart>,
    /// The trust ball's multiplier `μ` in the active-set path (0 when the
    /// ball does not bind, and for Clarabel).
    pub proximal_weight: f64,
}

/// Clarabel's own account of one solve: what the report's `final_qp`
/// diagnostics show.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ClarabelInfo {
    /// `Solved` or `AlmostSolved`.
    pub status: String,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Primal residual of the KKT system (Clarabel's scaled measure).
    pub primal_residual: f64,
    /// Dual residual of the KKT system.
    pub dual_residual: f64,
    /// Relative duality gap.
    pub gap: f64,
}

/// Outcome of a solve that did not produce a solution.
#[derive(Clone, Debug, PartialEq)]
pub enum QpFailure {
    /// The hard rows cannot all hold.
    Infeasible,
    /// Clarabel stopped on its time limit.
    OutOfTime,
    /// Any other failure, with Clarabel's status.
    Numerical(String),
}

impl QpFailure {
    /// As a crate error.
    pub fn into_error(self) -> Error {
        match self {
            QpFailure::Infeasible => {
                Error::Infeasible("the hard constraints are incompatible".into())
            }
            QpFailure::OutOfTime => Error::Cancelled("QP ran past the deadline".into()),
            QpFailure::Numerical(s) => Error::Numerical(format!("Clarabel: {s}")),
        }
    }
}

/// Column-wise builder of the constraint matrix.
struct Columns {
    cols: Vec<Vec<(usize, f64)>>,
    b: Vec<f64>,
}

impl Columns {
    fn row(&mut self, z_coeffs: &DVector<f64>, extra: &[(usize, f64)], b: f64) {
        let r = self.b.len();
        for (c, &v) in z_coeffs.iter().enumerate() {
            if v != 0.0 {
                self.cols[c].push((r, v));
            }
        }
        for &(c, v) in extra {
            self.cols[c].push((r, v));
        }
        self.b.push(b);
    }

    fn into_csc(self, m: usize) -> CscMatrix<f64> {
        let n = self.cols.len();
        let mut colptr = Vec::with_capacity(n + 1);
        let nnz: usize = self.cols.iter().map(|c| c.len()).sum();
        let mut rowval = Vec::with_capacity(nnz);
        let mut nzval = Vec::with_capacity(nnz);
        colptr.push(0);
        for col in self.cols {
            for (r, v) in col {
                rowval.push(r);
                nzval.push(v);
            }
            colptr.push(rowval.len());
        }
        CscMatrix::new(m, n, colptr, rowval, nzval)
    }
}

impl Qp {
    /// An empty problem over `dim` whitened coordinates, cost `|z|²`.
    pub fn new(dim: usize) -> Qp {
        Qp {
            center: DVector::zeros(dim),
            ..Default::default()
        }
    }

    pub(in crate::optim) fn dim(&self) -> usize {
        self.center.len()
    }

    /// Solve with Clarabel. Equalities are eliminated first (see
    /// [`NullSpace`]): Clarabel sees the problem in the null-space
    /// coordinates, and the solution is mapped back.
    pub fn solve(&self, settings: &QpSettings) -> std::result::Result<QpSolution, QpFailure> {
        if self.equalities.is_empty() {
            return self.solve_without_equalities(settings);
        }
        let space = NullSpace::new(&self.equalities, self.dim()).ok_or(QpFailure::Infeasible)?;
        let mut sol = self
            .restricted_to(&space)
            .solve_without_equalities(settings)?;
        sol.z = space.lift(&sol.z);
        sol.objective += space.distance_squared(&self.center);
        Ok(sol)
    }

    /// This problem over `z = z_p + N y` (variables `y`), without its
    /// equalities.
    pub(in crate::optim) fn restricted_to(&self, space: &NullSpace) -> Qp {
        let inequalities = self
            .inequalities
            .iter()
            .map(|ineq| {
                let (a, offset) = space.row(&ineq.a);
                Inequality {
                    a,
                    b: ineq.b - offset,
                    penalty: ineq.penalty,
                }
            })
            .collect();
        let cones = self
            .cones
            .iter()
            .map(|cone| Cone {
                offset: &cone.offset + &cone.matrix * &space.particular,
                matrix: &cone.matrix * &space.basis,
                radius: cone.radius,
                penalty: cone.penalty,
            })
            .collect();
        // The ball's centre moves onto the affine set and its radius becomes
        // the ball's section there, but never less than half the radius: the
        // trust region limits the step, it must never make a QP infeasible
        // (an iterate within the equality tolerance can still lie a little
        // off the set in whitened coordinates when the start is tight).
        let trust = self.trust.as_ref().map(|(centre, radius)| {
            let section = radius * radius - space.distance_squared(centre);
            (
                space.coordinates(centre),
                section.max(0.25 * radius * radius).sqrt(),
            )
        });
        Qp {
            center: space.coordinates(&self.center),
            equalities: Vec::new(),
            inequalities,
            cones,
            trust,
        }
    }

    /// Solve a problem without equalities with Clarabel.
    fn solve_without_equalities(
        &self,
        settings: &QpSettings,
    ) -> std::result::Result<QpSolution, QpFailure> {
        debug_assert!(self.equalities.is_empty());
        // Clarabel checks its time limit between interior-point iterations,
        // not while it sets up: a deadline already past stops here.
        if settings.time_limit.is_some_and(|t| t <= 0.0) {
            return Err(QpFailure::OutOfTime);
        }
        let layout = SlackLayout::of(self);
        let q = self.linear_cost(&layout);
        let (a, b, cones) = self.constraints(&layout);
        let p = cost_matrix(layout.n_z, layout.n);
        let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, clarabel_settings(settings))
            .map_err(|e| QpFailure::Numerical(format!("{e:?}")))?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {}
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                return Err(QpFailure::Infeasible)
            }
            SolverStatus::MaxTime => return Err(QpFailure::OutOfTime),
            other => return Err(QpFailure::Numerical(format!("{other:?}"))),
        }
        Ok(self.read_solution(&layout, &q, b.len(), &solver))
    }

    /// `q` of Clarabel's `½xᵀPx + qᵀx`: `-2c` on `z`, the penalties on the
    /// slacks.
    fn linear_cost(&self, layout: &SlackLayout) -> Vec<f64> {
        let mut q = vec![0.0; layout.n];
        for (qc, cc) in q.iter_mut().zip(self.center.iter()) {
            *qc = -2.0 * cc;
        }
        for (i, ineq) in self.inequalities.iter().enumerate() {
            if let (Some(s), Some(rho)) = (layout.slack_of[i], ineq.penalty) {
                q[s] = rho;
            }
        }
        for (k, cone) in self.cones.iter().enumerate() {
            q[layout.cone_slack(k)] = cone.penalty;
        }
        q
    }

    /// `A`, `b` and the cones of `b - A x ∈ K`: the inequalities and slack
    /// signs (non-negative cone), each goal cone, the trust ball.
    fn constraints(
        &self,
        layout: &SlackLayout,
    ) -> (CscMatrix<f64>, Vec<f64>, Vec<SupportedConeT<f64>>) {
        let (n_z, n) = (layout.n_z, layout.n);
        let mut cols = Columns {
            cols: vec![Vec::new(); n],
            b: Vec::new(),
        };
        let mut cones = Vec::new();
        for (i, ineq) in self.inequalities.iter().enumerate() {
            match layout.slack_of[i] {
                Some(s) => cols.row(&ineq.a, &[(s, -1.0)], ineq.b),
                None => cols.row(&ineq.a, &[], ineq.b),
            }
        }
        let empty = DVector::zeros(n_z);
        for s in n_z..n {
            cols.row(&empty, &[(s, -1.0)], 0.0);
        }
        let n_nonneg = self.inequalities.len() + (n - n_z);
        if n_nonneg > 0 {
            cones.push(SupportedConeT::NonnegativeConeT(n_nonneg));
        }
        for (k, cone) in self.cones.iter().enumerate() {
            // b - A x = (radius + s, offset + M z).
            cols.row(&empty, &[(layout.cone_slack(k), -1.0)], cone.radius);
            for r in 0..cone.offset.len() {
                let row = -cone.matrix.row(r).transpose();
                cols.row(&row, &[], cone.offset[r]);
            }
            cones.push(SupportedConeT::SecondOrderConeT(1 + cone.offset.len()));
        }
        if let Some((centre, radius)) = &self.trust {
            // b - A x = (radius, z - centre).
            cols.row(&empty, &[], *radius);
            let mut e = DVector::zeros(n_z);
            for c in 0..n_z {
                e[c] = -1.0;
                cols.row(&e, &[], -centre[c]);
                e[c] = 0.0;
            }
            cones.push(SupportedConeT::SecondOrderConeT(1 + n_z));
        }
        let b = cols.b.clone();
        let m = b.len();
        (cols.into_csc(m), b, cones)
    }

    /// The [`QpSolution`] of a solved Clarabel problem with `m` rows.
    fn read_solution(
        &self,
        layout: &SlackLayout,
        q: &[f64],
        m: usize,
        solver: &DefaultSolver<f64>,
    ) -> QpSolution {
        let sol = &solver.solution;
        let (n_z, n) = (layout.n_z, layout.n);
        let x = &sol.x;
        let z = DVector::from_column_slice(&x[..n_z]);
        let inequality_slacks = layout
            .slack_of
            .iter()
            .map(|s| s.map_or(0.0, |s| x[s].max(0.0)))
            .collect();
        let cone_slacks = (0..self.cones.len())
            .map(|k| x[layout.cone_slack(k)].max(0.0))
            .collect();
        let objective =
            (&z - &self.center).norm_squared() + (n_z..n).map(|i| q[i] * x[i]).sum::<f64>();
        QpSolution {
            z,
            inequality_slacks,
            cone_slacks,
            objective,
            inequality_duals: sol.z[..self.inequalities.len()].to_vec(),
            rows: m,
            variables: n,
            ipm_iterations: solver.info.iterations,
            active_set_steps: 0,
            row_states: None,
            proximal_weight: 0.0,
            clarabel: Some(ClarabelInfo {
                status: format!("{:?}", sol.status),
                iterations: solver.info.iterations,
                primal_residual: solver.info.res_primal,
                dual_residual: solver.info.res_dual,
                gap: solver.info.gap_rel,
            }),
        }
    }
}

/// Where the slack variables sit in Clarabel's `x = [z, s]`: one per soft
/// inequality, then one per cone.
struct SlackLayout {
    n_z: usize,
    n: usize,
    /// Slack index of each inequality (`None` for a hard row).
    slack_of: Vec<Option<usize>>,
    n_soft: usize,
}

impl SlackLayout {
    fn of(qp: &Qp) -> SlackLayout {
        let n_z = qp.dim();
        let mut slack_of = vec![None; qp.inequalities.len()];
        let mut n_soft = 0;
        for (i, ineq) in qp.inequalities.iter().enumerate() {
            if ineq.penalty.is_some() {
                slack_of[i] = Some(n_z + n_soft);
                n_soft += 1;
            }
        }
        SlackLayout {
            n_z,
            n: n_z + n_soft + qp.cones.len(),
            slack_of,
            n_soft,
        }
    }

    /// Slack index of cone `k`.
    fn cone_slack(&self, k: usize) -> usize {
        self.n_z + self.n_soft + k
    }
}

/// Clarabel's settings for `settings`.
fn clarabel_settings(settings: &QpSettings) -> DefaultSettings<f64> {
    DefaultSettings {
        verbose: false,
        tol_gap_abs: settings.tolerance,
        tol_gap_rel: settings.tolerance,
        tol_feas: settings.tolerance,
        max_iter: settings.max_iterations,
        time_limit: settings.time_limit.unwrap_or(f64::INFINITY),
        ..DefaultSettings::default()
    }
}

/// Upper triangle of `P = diag(2 I_z, 0_s)` (Clarabel minimises `½xᵀPx + qᵀx`).
fn cost_matrix(n_z: usize, n: usize) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(n + 1);
    colptr.push(0);
    for c in 0..n {
        colptr.push((c + 1).min(n_z));
    }
    CscMatrix::new(n, n, colptr, (0..n_z).collect(), vec![2.0; n_z])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(n: usize, i: usize, v: f64) -> DVector<f64> {
        let mut e = DVector::zeros(n);
        e[i] = v;
        e
    }

    #[test]
    fn projection_onto_a_halfspace_matches_the_closed_form() {
        // min |z|² s.t. a·z >= 1  ->  z = a / |a|².
        let a = DVector::from_vec(vec![1.0, 2.0, -2.0]);
        let mut qp = Qp::new(3);
        qp.inequalities.push(Inequality {
            a: -&a,
            b: -1.0,
            penalty: None,
        });
        let sol = qp.solve(&QpSettings::default()).unwrap();
        let expect = &a / a.norm_squared();
        assert!((&sol.z - &expect).amax() < 1e-8);
        assert!((sol.objective - expect.norm_squared()).abs() < 1e-8);
        // KKT: 2z = μ a with μ >= 0.
        let mu = sol.inequality_duals[0];
        assert!((2.0 * &sol.z - &a * mu).amax() < 1e-6, "mu {mu}");
    }

    #[test]
    fn a_trust_ball_off_the_equality_set_is_recentred_not_infeasible() {
        // min |z - c|² s.t. z0 + z1 = 1, trust ball of radius 0.1 around a
        // point 1.0 away from the line: the ball moves onto the line (its
        // centre's projection, radius 0.05 there).
        let n = 3;
        let mut qp = Qp::new(n);
        qp.center = DVector::from_vec(vec![5.0, -4.0, 0.0]);
        qp.equalities
            .push((DVector::from_vec(vec![1.0, 1.0, 0.0]), 1.0));
        let off = std::f64::consts::FRAC_1_SQRT_2;
        let ball_centre = DVector::from_vec(vec![0.5 + off, 0.5 + off, 0.0]);
        qp.trust = Some((ball_centre, 0.1));
        let sol = qp.solve(&QpSettings::default()).unwrap();
        assert!((sol.z[0] + sol.z[1] - 1.0).abs() < 1e-9);
        let on_line = DVector::from_vec(vec![0.5, 0.5, 0.0]);
        let moved = (&sol.z - &on_line).norm();
        assert!((moved - 0.05).abs() < 1e-6, "{moved}");
        // The step goes towards the cost centre's projection (4.5, -3.5, 0).
        assert!(sol.z[0] > 0.5 && sol.z[1] < 0.5);
    }

    #[test]
    fn equalities_cones_slacks_and_trust_region_behave() {
        let n = 2;
        // z0 = 1 exactly, z1 free, cost centre (0, 3), trust ball of radius
        // 2 around 0: z1 = sqrt(4 - 1).
        let mut qp = Qp::new(n);
        qp.center = DVector::from_vec(vec![0.0, 3.0]);
        qp.equalities.push((unit(n, 0, 1.0), 1.0));
        qp.trust = Some((DVector::zeros(n), 2.0));
        let sol = qp.solve(&QpSettings::default()).unwrap();
        assert!((sol.z[0] - 1.0).abs() < 1e-8, "{}", sol.z);
        assert!((sol.z[1] - 3f64.sqrt()).abs() < 1e-7, "{}", sol.z);
        // Soft row z1 <= -10 with a small penalty: slack takes the rest.
        let mut qp = Qp::new(n);
        qp.inequalities.push(Inequality {
            a: unit(n, 1, 1.0),
            b: -10.0,
            penalty: Some(1.0),
        });
        let sol = qp.solve(&QpSettings::default()).unwrap();
        // min z1² + s, s >= z1 + 10 -> z1 = -0.5, s = 9.5.
        assert!((sol.z[1] + 0.5).abs() < 1e-6);
        assert!((sol.inequality_slacks[0] - 9.5).abs() < 1e-6);
        // Cone: |z - (3, 4)| <= 1 -> closest point to origin is 0.8 * (3, 4).
        let mut qp = Qp::new(n);
        qp.cones.push(Cone {
            offset: DVector::from_vec(vec![-3.0, -4.0]),
            matrix: DMatrix::identity(2, 2),
            radius: 4.0,
            penalty: 1e3,
        });
        let sol = qp.solve(&QpSettings::default()).unwrap();
        assert!((sol.z[0] - 0.6).abs() < 1e-6 && (sol.z[1] - 0.8).abs() < 1e-6);
        assert!(sol.cone_slacks[0] < 1e-7);
    }

    #[test]
    fn incompatible_hard_rows_are_reported_infeasible() {
        let n = 1;
        let mut qp = Qp::new(n);
        qp.inequalities.push(Inequality {
            a: unit(n, 0, 1.0),
            b: -1.0,
            penalty: None,
        });
        qp.inequalities.push(Inequality {
            a: unit(n, 0, -1.0),
            b: -1.0,
            penalty: None,
        });
        assert_eq!(
            qp.solve(&QpSettings::default()).unwrap_err(),
            QpFailure::Infeasible
        );
    }
}
