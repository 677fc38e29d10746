//! Restarts of the SCP from seeded prior draws when the run from the prior
//! mean ends without a feasible solution.
//!
//! Clearance makes the problem non-convex. The run from the prior mean
//! decides early on which side of each obstacle the trajectory passes, and
//! when it picks a side that leads nowhere it ends in a local minimum of the
//! violation (`max_iterations`: the penalty reached its cap, or the
//! iteration limit). On the typical problems (`fixtures::typical`) most such
//! problems are feasible: a run started elsewhere finds a feasible answer.
//! So [`Problem::solve`] restarts `options.restarts` times, still
//! minimising the distance to the prior mean: first, when the planner
//! applies (the start fixed, the end a configuration or a goal position)
//! and the mean collides, from a feasible trajectory that ends at a clear
//! configuration of the goal region (for a goal position, [`super::pinned`])
//! and from a second collision-free path (the planner of [`super::path`] on
//! another random stream than the global stage's), made feasible near
//! itself first when it can be ([`super::near_path`]), then from detours around the
//! obstacles that block the mean (the prior conditioned to pass each on its
//! near or far side, [`super::detour`]), then from draws `z ~ N(0, I)` of
//! the whitened prior (seeded by `options.seed`) to make up the number: the
//! best of [`SCREENED_DRAWS`] draws scored on the optimisation phases
//! ([`super::screen`]).
//!
//! The restarts race ([`Problem::race`]): they advance together in rounds
//! of [`RACE_ROUND`] iterations, in parallel within a round, and the race
//! ends with the first round in which one of them ends `optimal`. The
//! answer is the closest (lowest cost, ties to the lower index) of the
//! runs that ended `optimal` by then. A run's iterations do not depend on
//! when it was paused, and which runs have ended after a round depends only
//! on their iteration counts, so the answer is the same whatever the thread
//! count and whichever run finishes first. The restarts that succeed mostly
//! end within 6-25 iterations while the others run to their cap, so
//! stopping those early is most of what the race saves (docs/experiments.md).
//! From the second round on, a lane still far from feasible while another
//! is nearly feasible is stopped too ([`stop_hopeless`]).
//! The answer is a local optimum found from a detour or a draw: a warning
//! says so.
//!
//! A restart may take at most [`RESTART_MAX_ITERATIONS`] iterations (the
//! successful restarts on the typical problems mostly need 7-35), so that a
//! problem with no feasible answer costs a bounded multiple of one run.
//! Nothing restarts after a proof of infeasibility, after an `optimal`
//! answer, or once the deadline or the cancel flag has stopped the solve.
//! A stop during the restarts still answers with the closest restart that
//! had already verified `optimal`, if any (the best verified trajectory
//! found within the budget), else with the first run's iterate.

use crate::optim::problem::Problem;
use crate::optim::report::Status;
use crate::optim::scp::{Progress, Scp};
use crate::optim::seeds::screen::SCREENED_DRAWS;
use crate::optim::solution::{Solution, SolveControl, SolveStats};
use crate::Result;
use nalgebra::DVector;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

pub use crate::optim::task::MAX_RESTARTS;
/// Iteration limit of one restart (less when `options.max_iterations` is).
pub const RESTART_MAX_ITERATIONS: usize = 40;
/// What the restarts start from, in order, as the warnings name them.
const RESTART_KINDS: &str = "when the mean collides, a feasible trajectory ending at a clear goal configuration and a second planned path, made feasible near itself; detours around the blocking obstacles; then screened prior draws";
/// Mixed into `options.seed` so that the restart draws are not the
/// `samples` draws.
const RESTART_STREAM: u64 = 0x7e57_a275;

impl Problem {
    /// `first` (the run from the prior mean) when it is `optimal`,
    /// `infeasible`, stopped by the caller or restarts are off; otherwise
    /// the best `optimal` restart, or `first` with every run's counters
    /// when none is.
    ///
    /// The restarts run in parallel (rayon), and the answer does not depend
    /// on which finishes first: every draw is fixed up front by the seed,
    /// every restart runs to its own end, and the pick is the lowest cost
    /// among the `optimal` runs, ties to the lower restart index.
    pub(in crate::optim) fn restart_if_stuck(
        &self,
        first: Solution,
        ctl: &SolveControl,
    ) -> Result<Solution> {
        let restarts = self.options.restarts;
        if first.status != Status::MaxIterations || restarts == 0 || ctl.stop_reason().is_some() {
            return Ok(first);
        }
        let began = std::time::Instant::now();
        let starts = self.restart_starts(restarts, ctl);
        let mean = DVector::zeros(self.whitening.dim());
        let race = self.race(&starts, &mean, ctl);
        let mut spent = Spent::from(&first);
        spent.solve_ms += began.elapsed().as_secs_f64() * 1e3;
        for stats in &race.unfinished {
            spent.add(stats);
        }
        for run in race.finished.iter().flatten() {
            spent.add(&run.stats);
        }
        let stopped = ctl.stop_reason();
        let best = closest_optimal(&race.finished)
            .and_then(|k| race.finished.into_iter().nth(k).flatten().map(|r| (k, r)));
        match (best, stopped) {
            (Some((k, sol)), _) => {
                let mut note = format!(
                    "the run from the prior mean found no feasible solution ({}); of {restarts} restarts ({RESTART_KINDS}), restart {} found the closest feasible one: a local optimum, a feasible solution closer to the prior may exist",
                    first.reason.as_deref().unwrap_or("no reason given"),
                    k + 1
                );
                if let Some(why) = stopped {
                    note.push_str(&format!(" (the other restarts were stopped: {why})"));
                }
                Ok(spent.onto(sol, note))
            }
            (None, Some(why)) => {
                let mut first = first;
                first.stop_reason = why.stop_reason();
                first.status = first.stop_reason.status();
                Ok(spent.onto(first, format!("restarts stopped: {why}")))
            }
            (None, None) => {
                let note = format!(
                    "{restarts} restarts ({RESTART_KINDS}) found no feasible solution either"
                );
                Ok(spent.onto(first, note))
            }
        }
    }

    /// The runs from `starts` towards `centre` (each of at most its
    /// start's cap of iterations), advanced together in rounds of [`RACE_ROUND`]
    /// iterations each (in parallel within a round) until the end of the
    /// first round in which one of them is `optimal`, or until every run
    /// has ended or been stopped as hopeless ([`stop_hopeless`]). Which
    /// runs have finished after a round depends only on their iteration
    /// counts and states, so the outcome is the same whatever the thread
    /// count.
    pub(super) fn race(
        &self,
        starts: &[RestartStart],
        centre: &DVector<f64>,
        ctl: &SolveControl,
    ) -> Race {
        let lane = |start: &RestartStart| {
            let scp = Scp::new(self, &start.z, centre, start.cap, ctl);
            let scp = if start.keep_feasible {
                scp.keeping_feasibility()
            } else {
                scp
            };
            Lane::Running(Box::new(scp))
        };
        let lanes: Vec<Lane> = if ctl.parallel() {
            starts.par_iter().map(lane).collect()
        } else {
            starts.iter().map(lane).collect()
        };
        race_lanes(lanes, ctl)
    }
}

/// [`Problem::race`] of lanes already started (some may have run ahead or
/// finished): advanced together in rounds until the end of the first round
/// in which one is `optimal`, or until every lane has ended or been
/// stopped as hopeless.
pub(super) fn race_lanes(mut lanes: Vec<Lane>, ctl: &SolveControl) -> Race {
    let mut round = 0;
    while lanes.iter().any(|l| matches!(l, Lane::Running(_)))
        && !lanes
            .iter()
            .any(|l| matches!(l, Lane::Finished(s) if s.status == Status::Optimal))
    {
        round += RACE_ROUND;
        let advance = |lane: &mut Lane| {
            if let Lane::Running(scp) = lane {
                if let Progress::Done(done) = scp.advance(round) {
                    *lane = Lane::Finished(done);
                }
            }
        };
        if ctl.parallel() {
            lanes.par_iter_mut().for_each(advance);
        } else {
            lanes.iter_mut().for_each(advance);
        }
        if round >= HOPELESS_FROM {
            stop_hopeless(&mut lanes);
        }
    }
    let mut race = Race {
        finished: Vec::with_capacity(lanes.len()),
        unfinished: Vec::new(),
    };
    for lane in lanes {
        match lane {
            Lane::Running(scp) => {
                race.unfinished.push(scp.stats().clone());
                race.finished.push(None);
            }
            Lane::Finished(sol) => race.finished.push(Some(*sol)),
            Lane::Stopped(stats) => {
                race.unfinished.push(stats);
                race.finished.push(None);
            }
        }
    }
    race
}

impl Problem {
    /// The `n` restart starts: when the mean collides, the pinned goal
    /// start ([`Problem::pinned_goal_start`]) and the second planned path
    /// ([`Problem::near_path_start`], made feasible near itself when it can
    /// be) where they are found; the detours around the obstacles that
    /// block the prior mean ([`Problem::detour_starts`]); then screened
    /// draws ([`Problem::screened_draws`]) to make up the number. The
    /// feasible starts are kept feasible ([`RestartStart::kept_feasible`]);
    /// every other start may take [`RESTART_MAX_ITERATIONS`].
    fn restart_starts(&self, n: usize, ctl: &SolveControl) -> Vec<RestartStart> {
        let zero = DVector::zeros(self.whitening.dim());
        let capped = |z| RestartStart::capped(z, self);
        let mut starts: Vec<RestartStart> = Vec::new();
        if self.mean_collides(&zero, ctl) {
            starts.extend(
                self.pinned_goal_start(ctl)
                    .map(|z| RestartStart::kept_feasible(z, self)),
            );
            starts.extend(self.near_path_start(ctl));
        }
        starts.truncate(n);
        let detours = self.detour_starts(n - starts.len(), ctl);
        starts.extend(detours.into_iter().map(capped));
        let draws = self.restart_draws(n.max(SCREENED_DRAWS));
        let kept = self.screened_draws(draws, n - starts.len(), ctl);
        starts.extend(kept.into_iter().map(capped));
        starts
    }

    /// `n` draws `z ~ N(0, I)` of the whitened prior from `options.seed`.
    pub(super) fn restart_draws(&self, n: usize) -> Vec<DVector<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.options.seed ^ RESTART_STREAM);
        let dim = self.whitening.dim();
        (0..n)
            .map(|_| DVector::from_fn(dim, |_, _| StandardNormal.sample(&mut rng)))
            .collect()
    }
}

/// Where a restart starts (whitened weights), how many iterations it may
/// take, and whether it keeps a feasible iterate feasible
/// ([`Scp::keeping_feasibility`]).
pub(super) struct RestartStart {
    pub(super) z: DVector<f64>,
    pub(super) cap: usize,
    pub(super) keep_feasible: bool,
}

impl Problem {
    /// Iteration limit of a restart that is not kept feasible, and of the
    /// runs that make a feasible start: [`RESTART_MAX_ITERATIONS`], less
    /// when `options.max_iterations` is.
    pub(super) fn restart_cap(&self) -> usize {
        self.options.max_iterations.min(RESTART_MAX_ITERATIONS)
    }

    /// The whitened weights of `run`'s answer when it ended `optimal`: a
    /// start feasible for this problem (the run was of this problem, or of
    /// one whose constraints include its own).
    pub(super) fn optimal_start(&self, run: Result<Solution>) -> Option<DVector<f64>> {
        let run = run.ok()?;
        (run.status == Status::Optimal).then(|| {
            self.whitening
                .whiten(&DVector::from_column_slice(&run.weights))
        })
    }
}

impl RestartStart {
    /// A start of at most [`RESTART_MAX_ITERATIONS`] iterations.
    pub(super) fn capped(z: DVector<f64>, problem: &Problem) -> Self {
        RestartStart {
            z,
            cap: problem.restart_cap(),
            keep_feasible: false,
        }
    }

    /// A start feasible for `problem`, kept feasible, which may take the
    /// problem's whole iteration limit: a run that never accepts an
    /// infeasible step may crawl along the clearance for longer than one
    /// from a draw.
    pub(super) fn kept_feasible(z: DVector<f64>, problem: &Problem) -> Self {
        RestartStart {
            z,
            cap: problem.options.max_iterations,
            keep_feasible: true,
        }
    }
}

/// The index of the closest `optimal` run among `runs` (lowest Mahalanobis
/// distance, ties to the lower index): the race's pick.
pub(super) fn closest_optimal(runs: &[Option<Solution>]) -> Option<usize> {
    runs.iter()
        .enumerate()
        .filter_map(|(k, run)| run.as_ref().map(|r| (k, r)))
        .filter(|(_, r)| r.status == Status::Optimal)
        .min_by(|(i, a), (j, b)| a.mahalanobis.total_cmp(&b.mahalanobis).then(i.cmp(j)))
        .map(|(k, _)| k)
}

/// Iterations each restart takes per round of [`Problem::race`]: small
/// enough that the runs still going when one ends `optimal` have not spent
/// much more, large enough that a round's parallel work is not dominated
/// by its slowest run's single iteration.
const RACE_ROUND: usize = 5;

/// One restart in [`Problem::race`].
pub(super) enum Lane<'a> {
    Running(Box<Scp<'a>>),
    Finished(Box<Solution>),
    /// Stopped as hopeless ([`stop_hopeless`]), with its counters.
    Stopped(SolveStats),
}

/// The round (in iterations) from which hopeless lanes are stopped: every
/// lane has had two rounds to leave its start.
const HOPELESS_FROM: usize = 2 * RACE_ROUND;

/// A lane within this true violation of feasibility (metres of clearance
/// deficit and goal excess, summed) is as good as feasible.
const NEAR_FEASIBLE: f64 = 1e-3;

/// A lane this far from feasibility while another is near it is stopped.
const HOPELESS: f64 = 0.1;

/// Stop the running lanes whose true violation is above [`HOPELESS`] when
/// another running lane is within [`NEAR_FEASIBLE`] of feasibility: on the
/// hard set the lanes that won were within 0.05 by iteration 10, and the
/// lanes still at 0.2-2.5 then never won (docs/experiments.md). The test
/// reads only the lanes' states after a round, so it is the same whatever
/// the thread count.
fn stop_hopeless(lanes: &mut [Lane]) {
    let near = lanes
        .iter()
        .any(|l| matches!(l, Lane::Running(s) if s.iterate().true_violation <= NEAR_FEASIBLE));
    if !near {
        return;
    }
    for lane in lanes.iter_mut() {
        if let Lane::Running(scp) = lane {
            if scp.iterate().true_violation > HOPELESS {
                *lane = Lane::Stopped(scp.stats().clone());
            }
        }
    }
}

/// What [`Problem::race`] ended with.
pub(super) struct Race {
    /// Each run's answer by start index; `None` for a run stopped when
    /// another ended `optimal`.
    pub(super) finished: Vec<Option<Solution>>,
    /// The counters of the stopped runs.
    pub(super) unfinished: Vec<SolveStats>,
}

/// Counters of every run of one solve, and its wall time (the restarts
/// overlap, so their times do not add up).
pub(super) struct Spent {
    stats: SolveStats,
    pub(super) solve_ms: f64,
}

impl Spent {
    pub(super) fn from(first: &Solution) -> Spent {
        Spent {
            stats: first.stats.clone(),
            solve_ms: first.report.solve_ms,
        }
    }

    pub(super) fn add(&mut self, restart: &SolveStats) {
        self.stats.absorb(restart);
        self.stats.restarts += 1;
    }

    /// `sol` reporting the work of every run, with `note` as a warning.
    pub(super) fn onto(self, mut sol: Solution, note: String) -> Solution {
        sol.report.iterations = self.stats.iterations;
        sol.report.solve_ms = self.solve_ms;
        sol.report.warnings.push(note);
        sol.stats = self.stats;
        sol
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{typical_request, ExampleSettings};
    use crate::optim::qp::nullspace::NullSpace;
    use crate::robot::Robot;

    /// A run that starts at a feasible point other than the prior mean
    /// (a restart whose draw happens to be feasible) must still move to the
    /// Mahalanobis-closest point, not return its start.
    #[test]
    fn a_run_from_a_feasible_start_still_converges_to_the_closest_point() {
        let robot = Robot::panda().unwrap();
        let settings = ExampleSettings {
            n_obstacles: 0,
            ..Default::default()
        };
        let mut req = typical_request(&robot, 5, &settings).unwrap();
        req.task.goal = None;
        req.task.obstacles.clear();
        let p = req.validate(&robot).unwrap();
        let ctl = SolveControl::default();
        let best = p.solve(&ctl).unwrap();
        assert_eq!(best.status, Status::Optimal);
        // With only the start equality, the optimum is its projection.
        let dim = p.whitening.dim();
        let equalities = p.linear.equalities(&p.ends, &p.prior.mean);
        let space = NullSpace::new(&equalities, dim).unwrap();
        let z_best = p
            .whitening
            .whiten(&DVector::from_column_slice(&best.weights));
        // A feasible start: the optimum moved 0.3 along the affine set.
        let start = &z_best + space.basis.column(0) * 0.3;
        let probe = p.evaluate(p.whitening.weights(&start).as_slice());
        assert!(p.is_feasible(&probe), "the start must be feasible");
        let zero = DVector::zeros(dim);
        let run = p.run(&start, &zero, 100, &ctl).unwrap();
        assert_eq!(run.status, Status::Optimal);
        assert!(run.stats.iterations >= 1);
        let z_run = p
            .whitening
            .whiten(&DVector::from_column_slice(&run.weights));
        assert!(
            (&z_run - &z_best).amax() < 1e-6,
            "{}",
            (&z_run - &z_best).amax()
        );
        assert!((run.mahalanobis - best.mahalanobis).abs() < 1e-6);
    }

    /// Pausing a run between iterations (as the race does) never changes
    /// it: the same weights, bit for bit, and the same iteration count as
    /// one uninterrupted run.
    #[test]
    fn a_run_paused_after_every_iteration_is_the_uninterrupted_run() {
        let robot = Robot::panda().unwrap();
        let req = typical_request(&robot, 7, &ExampleSettings::default()).unwrap();
        let p = req.validate(&robot).unwrap();
        let ctl = SolveControl::default();
        let zero = DVector::zeros(p.whitening.dim());
        let whole = p.run(&zero, &zero, 100, &ctl).unwrap();
        assert!(whole.stats.iterations >= 3, "{}", whole.stats.iterations);
        let mut scp = Scp::new(&p, &zero, &zero, 100, &ctl);
        let mut pauses = 0;
        let paused = loop {
            if let Progress::Done(done) = scp.advance(scp.stats().iterations + 1) {
                break *done;
            }
            pauses += 1;
        };
        assert!(pauses >= whole.stats.iterations - 1, "{pauses}");
        assert_eq!(paused.status, whole.status);
        assert_eq!(paused.weights, whole.weights);
        assert_eq!(paused.stats.iterations, whole.stats.iterations);
    }

    /// The race's answer, checked against every restart run to its own
    /// end: of the runs that end `optimal` in the earliest round (of
    /// [`RACE_ROUND`] iterations) in which any does, the lowest cost, ties
    /// to the lower index.
    #[test]
    fn the_race_answers_with_the_closest_of_the_first_runs_to_end_optimal() {
        let robot = Robot::panda().unwrap();
        let settings = ExampleSettings {
            boundary: crate::optim::Boundary::Free,
            ..Default::default()
        };
        // Typical problem 400 on free ends needs its restarts.
        let req = typical_request(&robot, 400, &settings).unwrap();
        let p = req.validate(&robot).unwrap();
        let ctl = SolveControl::default();
        let starts = p.restart_starts(p.options.restarts, &ctl);
        assert!(starts.len() >= 2);
        let mean = DVector::zeros(p.whitening.dim());
        let full: Vec<Solution> = starts
            .iter()
            .map(|s| p.run(&s.z, &mean, s.cap, &ctl).unwrap())
            .collect();
        let round_of = |s: &Solution| s.stats.iterations.max(1).div_ceil(RACE_ROUND);
        let first_round = full
            .iter()
            .filter(|s| s.status == Status::Optimal)
            .map(round_of)
            .min()
            .expect("a restart of problem 400 ends optimal");
        let expected = full
            .iter()
            .enumerate()
            .filter(|(_, s)| s.status == Status::Optimal && round_of(s) == first_round)
            .min_by(|(i, a), (j, b)| a.mahalanobis.total_cmp(&b.mahalanobis).then(i.cmp(j)))
            .map(|(k, _)| k)
            .unwrap();
        // The plain run from the mean (the global stage aside) is stuck,
        // and the restarts answer with the race's pick.
        let first = p.run(&mean, &mean, p.options.max_iterations, &ctl).unwrap();
        assert_eq!(first.status, Status::MaxIterations);
        let answer = p.restart_if_stuck(first, &ctl).unwrap();
        assert_eq!(answer.status, Status::Optimal);
        assert_eq!(answer.weights, full[expected].weights);
        let race = p.race(&starts, &mean, &ctl);
        let picked = race.finished[expected].as_ref().expect("the pick finished");
        assert_eq!(picked.weights, full[expected].weights);
        for (k, run) in race.finished.iter().enumerate() {
            match run {
                Some(run) => assert_eq!(run.weights, full[k].weights, "restart {k}"),
                None => assert!(round_of(&full[k]) > first_round, "restart {k}"),
            }
        }
        let stopped = race.finished.iter().filter(|r| r.is_none()).count();
        assert!(stopped >= 1, "the race must stop a restart early");
        assert_eq!(race.unfinished.len(), stopped);
    }
}
