//! How short a motion can be: a closed-form lower bound on the duration
//! from the rate limits, and the proof of infeasibility it gives.
//!
//! ## The bound
//!
//! Take any trajectory of joint `j` over `[0, T]` within the velocity
//! limit `v`, the acceleration limit `a` and the jerk limit `J`, at rest
//! (zero velocity and acceleration) at both ends when `boundary` is
//! `rest`. From rest, the fastest the joint can be moving at time `t` is
//!
//! ```text
//! f(t) = J t² / 2                 for t ≤ a / J,
//!        a t − a² / (2 J)         after            (a·t alone without jerk limit)
//! ```
//!
//! (the jerk held at `J` until the acceleration reaches `a`, then the
//! acceleration held), and by symmetry no faster than `f(T − t)` if it must
//! be at rest again at `T`. So `|q̇_j(t)| ≤ u_j(t) = min(v, f(t), f(T − t))`
//! and the joint's path length is at most `S_j(T) = ∫₀ᵀ u_j(t) dt`, which
//! grows with `T`. Every point of the robot, the TCP among them, moves at
//! most `Σ_j L_j |q̇_j|` ([`crate::robot::Robot::lever_arms`]), so the TCP's
//! path is at most `Σ_j L_j S_j(T)` long.
//!
//! A trajectory ending within `goal.tolerance_m` of the goal must move the
//! TCP at least `D = |goal − tcp(start)| − tolerance_m`; one ending at
//! `options.final_configuration` must move joint `j` at least
//! `|q_final,j − q_start,j|`. When `T` cannot give that, **no** trajectory
//! within the limits exists, whatever the obstacles, the prior or the
//! solver: the request is answered `infeasible` at once, before any QP,
//! with the shortest duration the bound allows (`duration_lower_bound_s`,
//! rounded down to the millisecond). The integral is an upper Riemann sum
//! on [`BOUND_CELLS`] cells of the monotone pieces of `u_j`, so the bound
//! errs towards "possible", never towards a false proof.
//!
//! ## What it is not
//!
//! The bound ignores the path's shape (joint limits, obstacles, the
//! kinematics between the joints' speeds and the TCP's), so a duration
//! above it can still be infeasible. The duration a *verified* solve
//! reached is a separate figure, `min_duration_s`, searched by
//! [`crate::optim::optimize_with`] from the bound upwards
//! ([`DURATION_SEARCH_GROWTH`]) within [`DURATION_SEARCH_BUDGET`] and the
//! caller's deadline.

use crate::optim::problem::phases::Derivative;
use crate::optim::problem::Problem;
use crate::optim::task::MAX_DURATION_S;
use std::time::Duration;

/// Cells of the upper Riemann sum of a joint's speed bound.
pub const BOUND_CELLS: usize = 512;

/// Each duration the verified search tries is this factor times the last.
pub const DURATION_SEARCH_GROWTH: f64 = 2.0;

/// Wall-time budget of the verified-duration search (it also stops at the
/// caller's deadline).
pub const DURATION_SEARCH_BUDGET: Duration = Duration::from_millis(1000);

/// Relative width of the bisection that inverts the bound.
const BISECTION_TOLERANCE: f64 = 1e-4;

/// The rate limits of one joint: velocity (always), acceleration and jerk
/// (when limited), and whether it rests at both ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointRates {
    /// Velocity limit (rad/s or m/s).
    pub velocity: f64,
    /// Acceleration limit, if any.
    pub acceleration: Option<f64>,
    /// Jerk limit, if any.
    pub jerk: Option<f64>,
    /// Zero velocity and acceleration at both ends.
    pub rest: bool,
}

impl JointRates {
    /// The fastest the joint can move `t` seconds after leaving rest.
    fn speed_from_rest(&self, t: f64) -> f64 {
        if !self.rest {
            return f64::INFINITY;
        }
        match (self.acceleration, self.jerk) {
            (None, None) => f64::INFINITY,
            (Some(a), None) => a * t,
            (None, Some(j)) => 0.5 * j * t * t,
            (Some(a), Some(j)) => {
                if t <= a / j {
                    0.5 * j * t * t
                } else {
                    a * t - 0.5 * a * a / j
                }
            }
        }
    }

    /// Upper bound on the joint's path length `∫|q̇|` over a motion of
    /// `duration` seconds (see the module docs).
    pub fn path_length_bound(&self, duration: f64) -> f64 {
        if duration.is_nan() || duration <= 0.0 {
            return 0.0;
        }
        let h = duration / BOUND_CELLS as f64;
        (0..BOUND_CELLS)
            .map(|k| {
                let (t0, t1) = (k as f64 * h, (k + 1) as f64 * h);
                // u is increasing in t through f(t) and decreasing through
                // f(T − t): its cell maximum is at most this.
                let up = self.speed_from_rest(t1);
                let down = self.speed_from_rest(duration - t0);
                self.velocity.min(up).min(down) * h
            })
            .sum()
    }
}

/// The motion the request demands, which the limits must allow.
#[derive(Clone, Debug, PartialEq)]
enum Demand {
    /// The TCP must travel at least this far (m).
    TcpTravel(f64),
    /// Each joint must travel at least this far (rad).
    JointTravel(Vec<f64>),
}

/// A proof that the requested duration is too short.
#[derive(Clone, Debug, PartialEq)]
pub struct DurationProof {
    /// Why, in words naming the request fields.
    pub reason: String,
    /// The shortest duration the bound allows (s, rounded down to the
    /// millisecond); `None` when even [`MAX_DURATION_S`] is too short.
    pub lower_bound_s: Option<f64>,
}

impl Problem {
    /// Per joint, the rate limits of this request.
    pub fn joint_rates(&self) -> Vec<JointRates> {
        (0..self.robot.dof())
            .map(|j| JointRates {
                velocity: self.linear.velocity[j],
                acceleration: self.linear.rate_bound(Derivative::Acceleration, j),
                jerk: self.linear.rate_bound(Derivative::Jerk, j),
                rest: self.linear.rest,
            })
            .collect()
    }

    /// `Some` when the rate limits prove that no trajectory of
    /// `duration_s` seconds can make the motion the request demands (see
    /// the module docs); microseconds, no QP.
    pub fn duration_proof(&self) -> Option<DurationProof> {
        let demand = self.demand()?;
        let rates = self.joint_rates();
        if self.duration_allows(&rates, &demand, self.duration) {
            return None;
        }
        let lower_bound_s = self.shortest_allowed(&rates, &demand, self.duration);
        let what = match &demand {
            Demand::TcpTravel(d) => format!(
                "the TCP must travel at least {d:.3} m from the start to within goal.tolerance_m of goal.position"
            ),
            Demand::JointTravel(_) => {
                "the joints must travel from start to options.final_configuration".to_string()
            }
        };
        let limits = "the velocity, acceleration and jerk limits (velocity_scaling, acceleration_limits, acceleration_scaling, jerk_limits)";
        let reason = match lower_bound_s {
            Some(lb) => format!(
                "duration_s: {what}, which {limits} do not allow in {:.3} s; no duration below {lb:.3} s can work (duration_lower_bound_s)",
                self.duration
            ),
            None => format!(
                "duration_s: {what}, which {limits} do not allow even in {MAX_DURATION_S} s"
            ),
        };
        Some(DurationProof {
            reason,
            lower_bound_s,
        })
    }

    /// What the request makes the robot travel; `None` without a start (or
    /// with nothing that must move).
    fn demand(&self) -> Option<Demand> {
        let start = self.linear.start.as_ref()?;
        if let Some(end) = &self.linear.final_configuration {
            let travel = start.iter().zip(end).map(|(a, b)| (b - a).abs()).collect();
            return Some(Demand::JointTravel(travel));
        }
        let goal = self.goal.as_ref()?;
        let tcp = self.robot.tcp_pose(start).translation.vector;
        let d = (tcp - nalgebra::Vector3::from(goal.position)).norm() - goal.tolerance_m;
        (d > 0.0).then_some(Demand::TcpTravel(d))
    }

    /// Whether `duration` lets the robot make `demand` within `rates`.
    fn duration_allows(&self, rates: &[JointRates], demand: &Demand, duration: f64) -> bool {
        match demand {
            Demand::TcpTravel(d) => {
                let reach: f64 = rates
                    .iter()
                    .zip(self.robot.lever_arms())
                    .map(|(r, lever)| lever * r.path_length_bound(duration))
                    .sum();
                reach >= *d
            }
            Demand::JointTravel(travel) => rates
                .iter()
                .zip(travel)
                .all(|(r, need)| r.path_length_bound(duration) >= *need),
        }
    }

    /// The shortest duration (s, rounded down to the millisecond) the
    /// closed-form bound allows for the motion the request demands,
    /// whatever its `duration_s`; `None` without a start, when nothing
    /// must move, or when not even [`MAX_DURATION_S`] is enough.
    pub fn duration_lower_bound(&self) -> Option<f64> {
        let demand = self.demand()?;
        self.shortest_allowed(&self.joint_rates(), &demand, 0.0)
    }

    /// The smallest duration above `from` that the bound allows for
    /// `demand` (bisection; the bound is monotone in the duration),
    /// rounded down to the millisecond.
    fn shortest_allowed(&self, rates: &[JointRates], demand: &Demand, from: f64) -> Option<f64> {
        if !self.duration_allows(rates, demand, MAX_DURATION_S) {
            return None;
        }
        let (mut lo, mut hi) = (from, MAX_DURATION_S);
        while hi - lo > BISECTION_TOLERANCE * hi {
            let mid = 0.5 * (lo + hi);
            if self.duration_allows(rates, demand, mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some((lo * 1000.0).floor() / 1000.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rates(acceleration: Option<f64>, jerk: Option<f64>) -> JointRates {
        JointRates {
            velocity: 2.0,
            acceleration,
            jerk,
            rest: true,
        }
    }

    #[test]
    fn path_length_matches_the_bang_bang_closed_forms() {
        // Acceleration only, velocity never reached: a T² / 4.
        let r = rates(Some(10.0), None);
        let t = 0.3;
        let exact = 10.0 * t * t / 4.0;
        let bound = r.path_length_bound(t);
        assert!(bound >= exact && bound <= exact * (1.0 + 5.0 / BOUND_CELLS as f64));
        // Velocity reached: trapezoid v (T − v / a).
        let t = 2.0;
        let exact = 2.0 * (t - 2.0 / 10.0);
        let bound = r.path_length_bound(t);
        assert!(bound >= exact && bound <= exact * (1.0 + 5.0 / BOUND_CELLS as f64));
        // Free ends: the velocity limit alone.
        let free = JointRates { rest: false, ..r };
        assert!((free.path_length_bound(t) - 2.0 * t).abs() < 1e-12);
        // Jerk only, short motion: ∫ min(J t²/2, J (T−t)²/2) = J T³ / 24.
        let r = rates(None, Some(1000.0));
        let t = 0.1;
        let exact = 1000.0 * t * t * t / 24.0;
        let bound = r.path_length_bound(t);
        assert!(bound >= exact && bound <= exact * (1.0 + 10.0 / BOUND_CELLS as f64));
    }

    #[test]
    fn the_bound_dominates_a_fine_sum_of_its_speed_profile_and_grows_with_time() {
        let r = rates(Some(7.5), Some(3750.0));
        let mut last = 0.0;
        for k in 1..60 {
            let t = 0.02 * k as f64;
            let fine: f64 = (0..100_000)
                .map(|i| {
                    let s = (i as f64 + 0.5) * t / 100_000.0;
                    r.velocity
                        .min(r.speed_from_rest(s))
                        .min(r.speed_from_rest(t - s))
                        * t
                        / 100_000.0
                })
                .sum();
            let b = r.path_length_bound(t);
            assert!(b >= fine - 1e-12, "{t}: {b} < {fine}");
            assert!(b >= last);
            last = b;
        }
    }
}
