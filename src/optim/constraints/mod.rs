//! The constraints a request sets at single phases of the motion: the
//! goal's TCP position and approach direction, and the waypoints. One kind
//! per file, each behind [`EndConstraint`]:
//!
//! - [`tcp_position`] — the TCP within a distance of a point (the goal's
//!   `position`, a waypoint's `position`): a second-order cone;
//! - [`approach`] — the gripper's z axis within an angle of the goal's
//!   `approach_axis`: one linearised row;
//! - [`via_configuration`] — every joint within `tolerance_rad` of a
//!   waypoint's `configuration`: two rows per joint (exact, a
//!   configuration is linear in the weights).
//!
//! Each kind is a function of the configuration at one of the problem's
//! `ends` phases (0 the start, 1 the end, `2 + i` the request's
//! `via_points[i]`), so the solver treats them alike: the SCP evaluates
//! each at the iterate ([`EndConstraint::evaluate`]: what must reach zero
//! and what the merit counts), the subproblem adds its linearisation with
//! an L1-penalised slack ([`EndConstraint::linearise`]), the dense
//! verification writes its figure into the report
//! ([`EndConstraint::report`]) and the feasibility test reads it back
//! ([`EndConstraint::holds`]). A new kind is one file here, its place in
//! [`end_constraints`], its request field and its OpenAPI entry.
//!
//! The constraints that are linear in the weights (limits, rates, the start
//! and exact configurations) live in [`crate::optim::problem::linear`] and
//! the clearance in [`crate::scene`] with the subproblem's working set: both
//! are checked at every phase and take their rows by constraint generation,
//! which these single-phase constraints do not need.
//!
//! The order of [`end_constraints`] is the order their rows enter the QP
//! and their excesses are summed; keep it when adding a kind so that the
//! answers of existing requests stay bit-identical.

pub mod approach;
pub mod tcp_position;
pub mod via_configuration;

use crate::optim::qp::{Cone, Inequality};
use crate::optim::report::TrajectoryReport;
use crate::optim::task::{Goal, Waypoint, DEFAULT_WAYPOINT_TOLERANCE_M};
use crate::robot::Robot;
use approach::Approach;
use nalgebra::{DMatrix, DVector, Vector3};
use std::fmt::Debug;
use std::sync::Arc;
use tcp_position::{TcpPosition, TcpTarget};
use via_configuration::ViaConfiguration;

/// A constraint on the configuration at one of the problem's `ends`
/// phases.
pub(in crate::optim) trait EndConstraint: Debug + Send + Sync {
    /// Index of its phase in the problem's `ends` rows.
    fn phase(&self) -> usize;

    /// Its state at configuration `q` (the configuration at [`Self::phase`]).
    fn evaluate(&self, robot: &Robot, q: Vec<f64>) -> EndEval;

    /// Its QP rows linearised at `eval`, the iterate `z`, each with an
    /// L1-penalised slack of weight `rho`; `jacobian` is `∂q/∂z` at its
    /// phase (joints × whitened weights; the configuration is affine in
    /// `z`).
    fn linearise(
        &self,
        robot: &Robot,
        jacobian: &DMatrix<f64>,
        eval: &EndEval,
        z: &DVector<f64>,
        rho: f64,
    ) -> EndRows;

    /// Writes its figure at configuration `q` into `report` (a figure
    /// several constraints share keeps the worst).
    fn report(&self, robot: &Robot, q: &[f64], report: &mut TrajectoryReport);

    /// Whether `report`'s figure meets it within `tolerance`.
    fn holds(&self, report: &TrajectoryReport, tolerance: f64) -> bool;

    /// Its violation at `eval`, in words, naming the request's field.
    fn describe(&self, eval: &EndEval) -> String;
}

/// An [`EndConstraint`] at one iterate.
#[derive(Clone, Debug)]
pub(in crate::optim) struct EndEval {
    /// The configuration at the constraint's phase.
    pub(in crate::optim) q: Vec<f64>,
    /// What the kind measures there (a TCP residual, a cosine; empty
    /// when the configuration says it all).
    pub(in crate::optim) value: Vec<f64>,
    /// `∂value/∂q`, row-major, when the kind computes it while evaluating
    /// (else empty).
    pub(in crate::optim) gradient: Vec<f64>,
    /// How far the constraint is broken (what must reach zero).
    pub(in crate::optim) excess: f64,
    /// The same against the buffered tolerance the QP aims for (the
    /// merit's).
    pub(in crate::optim) buffered_excess: f64,
}

/// An [`EndConstraint`]'s QP rows.
#[derive(Clone, Debug, Default)]
pub(in crate::optim) struct EndRows {
    /// Second-order cones.
    pub(in crate::optim) cones: Vec<Cone>,
    /// Linear rows.
    pub(in crate::optim) inequalities: Vec<Inequality>,
}

/// The request's single-phase constraints, in the order their rows enter
/// the QP: the goal's position, the tolerant configuration waypoints, the
/// position waypoints, the goal's approach. `via_points[i]` is at `ends`
/// phase `2 + i`.
pub(in crate::optim) fn end_constraints(
    goal: Option<&Goal>,
    via_points: &[Waypoint],
) -> Vec<Arc<dyn EndConstraint>> {
    let mut out: Vec<Arc<dyn EndConstraint>> = Vec::new();
    if let Some(g) = goal {
        out.push(Arc::new(TcpPosition {
            target: TcpTarget::Goal,
            phase: 1,
            position: Vector3::from(g.position),
            tolerance_m: g.tolerance_m,
        }));
    }
    for (i, v) in via_points.iter().enumerate() {
        if let (Some(configuration), Some(tolerance_rad)) = (&v.configuration, v.tolerance_rad) {
            if !v.is_exact_configuration() {
                out.push(Arc::new(ViaConfiguration {
                    index: i,
                    phase: 2 + i,
                    configuration: configuration.clone(),
                    tolerance_rad,
                }));
            }
        }
    }
    for (i, v) in via_points.iter().enumerate() {
        if let Some(position) = v.position {
            out.push(Arc::new(TcpPosition {
                target: TcpTarget::Waypoint(i),
                phase: 2 + i,
                position: Vector3::from(position),
                tolerance_m: v.tolerance_m.unwrap_or(DEFAULT_WAYPOINT_TOLERANCE_M),
            }));
        }
    }
    if let Some(a) = goal.and_then(Goal::approach) {
        out.push(Arc::new(Approach {
            axis: Vector3::from(a.approach_axis).normalize(),
            tolerance_rad: a.approach_tolerance_rad,
        }));
    }
    out
}

/// `Some(max(figure, value))`: a report figure that keeps the worst of
/// several constraints.
fn worst(figure: Option<f64>, value: f64) -> Option<f64> {
    Some(figure.map_or(value, |f| f.max(value)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Whitened weights' dimension of the test's affine map.
    const DIM: usize = 12;

    /// A configuration affine in `z`, `q = q0 + J z`, as the problem's
    /// phase rows make it: `q0` a bent Panda configuration, `J` seeded.
    struct Affine {
        q0: DVector<f64>,
        jacobian: DMatrix<f64>,
    }

    impl Affine {
        fn new(seed: u64) -> Affine {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            Affine {
                q0: DVector::from_row_slice(&[0.1, -0.4, 0.2, -2.1, 0.1, 1.7, 0.6]),
                jacobian: DMatrix::from_fn(7, DIM, |_, _| rng.gen_range(-0.2..0.2)),
            }
        }

        fn q(&self, z: &DVector<f64>) -> Vec<f64> {
            (&self.q0 + &self.jacobian * z).iter().copied().collect()
        }
    }

    /// One constraint of each kind, each met at `z = 0` within a few
    /// millimetres or hundredths of a radian of its tolerance.
    fn one_of_each(robot: &Robot, map: &Affine) -> Vec<Arc<dyn EndConstraint>> {
        let q0 = map.q(&DVector::zeros(DIM));
        let tcp = robot.tcp_pose(&q0);
        vec![
            Arc::new(TcpPosition {
                target: TcpTarget::Goal,
                phase: 1,
                position: tcp.translation.vector + Vector3::new(0.003, -0.002, 0.0),
                tolerance_m: 0.005,
            }),
            Arc::new(TcpPosition {
                target: TcpTarget::Waypoint(0),
                phase: 2,
                position: tcp.translation.vector + Vector3::new(0.0, 0.003, 0.003),
                tolerance_m: 0.005,
            }),
            Arc::new(Approach {
                axis: (tcp.rotation * Vector3::new(0.1, 0.0, 1.0)).normalize(),
                tolerance_rad: 0.2,
            }),
            Arc::new(ViaConfiguration {
                index: 0,
                phase: 2,
                configuration: q0.iter().map(|q| q + 0.01).collect(),
                tolerance_rad: 0.02,
            }),
        ]
    }

    /// What rows linearised at some `z` predict for the constraint's own
    /// measure at `z1`: each cone's vector `offset + M z1` (a TCP
    /// residual), each row's `a·z1 − b` (≤ 0 where it holds).
    fn predicted(rows: &EndRows, z1: &DVector<f64>) -> Vec<f64> {
        let cones = rows.cones.iter().flat_map(|c| {
            (&c.offset + &c.matrix * z1)
                .iter()
                .copied()
                .collect::<Vec<_>>()
        });
        let lines = rows.inequalities.iter().map(|r| r.a.dot(z1) - r.b);
        cones.chain(lines).collect()
    }

    /// The same measure exactly at `z1`: the rows linearised at `z1`
    /// itself and read there (a linearisation is exact at its point).
    fn exact(c: &dyn EndConstraint, robot: &Robot, map: &Affine, z1: &DVector<f64>) -> Vec<f64> {
        let there = c.evaluate(robot, map.q(z1));
        predicted(&c.linearise(robot, &map.jacobian, &there, z1, 1.0), z1)
    }

    #[test]
    fn each_kinds_rows_match_its_exact_value_to_second_order() {
        let robot = Robot::panda().unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for seed in 0..3 {
            let map = Affine::new(seed);
            for c in one_of_each(&robot, &map) {
                let z = DVector::from_fn(DIM, |_, _| rng.gen_range(-0.5..0.5));
                let dir = DVector::from_fn(DIM, |_, _| rng.gen_range(-1.0..1.0));
                let eval = c.evaluate(&robot, map.q(&z));
                let rows = c.linearise(&robot, &map.jacobian, &eval, &z, 1.0);
                // The model's error shrinks with the square of the step.
                let error = |h: f64| {
                    let z1 = &z + h * &dir;
                    let model = predicted(&rows, &z1);
                    let truth = exact(c.as_ref(), &robot, &map, &z1);
                    assert_eq!(model.len(), truth.len());
                    model
                        .iter()
                        .zip(&truth)
                        .map(|(m, t)| (m - t).abs())
                        .fold(0.0, f64::max)
                };
                let (coarse, fine) = (error(1e-2), error(1e-3));
                assert!(
                    fine <= 0.02 * coarse + 1e-12,
                    "{c:?} seed {seed}: model error {coarse:e} at h = 1e-2, {fine:e} at 1e-3"
                );
            }
        }
    }

    #[test]
    fn each_kind_holds_exactly_where_its_excess_is_zero() {
        let robot = Robot::panda().unwrap();
        let map = Affine::new(1);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut seen = [0usize; 2];
        for c in one_of_each(&robot, &map) {
            for k in 0..40 {
                let scale = [0.0, 0.01, 0.03, 0.1, 1.0][k % 5];
                let z = DVector::from_fn(DIM, |_, _| scale * rng.gen_range(-1.0..1.0));
                let q = map.q(&z);
                let eval = c.evaluate(&robot, q.clone());
                let mut report = TrajectoryReport::default();
                c.report(&robot, &q, &mut report);
                let holds = c.holds(&report, 1e-12);
                assert_eq!(holds, eval.excess <= 1e-12, "{c:?}: excess {}", eval.excess);
                assert!(eval.buffered_excess >= eval.excess, "{c:?}");
                let text = c.describe(&eval);
                assert!(
                    text.starts_with("goal") || text.starts_with("via_points[0]"),
                    "{text}"
                );
                seen[usize::from(holds)] += 1;
            }
        }
        assert!(seen[0] > 20 && seen[1] > 20, "broken / held: {seen:?}");
    }

    #[test]
    fn the_request_gives_each_kind_in_the_qp_order() {
        let goal = Goal::at([0.5, 0.0, 0.4], 0.01).with_approach(Some(
            &crate::optim::task::GoalApproach {
                approach_axis: [0.0, 0.0, -2.0],
                approach_tolerance_rad: 0.1,
            },
        ));
        let position = Waypoint {
            phase: Some(0.3),
            time_s: None,
            configuration: None,
            position: Some([0.4, 0.1, 0.5]),
            tolerance_m: None,
            tolerance_rad: None,
        };
        let exact = Waypoint {
            configuration: Some(vec![0.0; 7]),
            position: None,
            ..position.clone()
        };
        let tolerant = Waypoint {
            tolerance_rad: Some(0.05),
            ..exact.clone()
        };
        let kinds = end_constraints(Some(&goal), &[position, exact, tolerant]);
        let names: Vec<String> = kinds
            .iter()
            .map(|c| {
                format!(
                    "{} {}",
                    c.phase(),
                    format!("{c:?}").split([' ', '{']).next().unwrap()
                )
            })
            .collect();
        // The exact configuration is an equality, not one of these.
        assert_eq!(
            names,
            [
                "1 TcpPosition",
                "4 ViaConfiguration",
                "2 TcpPosition",
                "1 Approach"
            ]
        );
        let approach = format!("{:?}", kinds[3]);
        assert!(
            approach.contains("[[0.0, 0.0, -1.0]]"),
            "the axis is normalised: {approach}"
        );
    }
}
