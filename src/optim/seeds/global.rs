//! The global stage: when the prior mean is blocked, a run from a
//! collision-free path races the run from the mean from the first
//! iteration.
//!
//! The SCP is a local method: from the prior mean it decides early on
//! which side of each obstacle the trajectory passes, and when an obstacle
//! lies across the mean (a shelf board between the start and the goal, a
//! berry across the demonstrated path) the side it picks may lead nowhere.
//! The restarts ([`super::restart`]) only begin after that run has spent
//! its iterations. So when the problem fixes the start and the end (a
//! configuration or a goal position, [`super::goal_pose`]) and the mean's
//! trajectory collides with an obstacle at an optimisation
//! phase (signed distance below zero: an obstacle across it, not merely
//! near it), [`Problem::first_run`] asks the planner ([`super::path`]) for
//! a collision-free path while the run from the mean takes its first
//! [`HEAD_START`] iterations (both at once where the solve may use two
//! threads). When the mean's run has ended `optimal` by then, that is the
//! answer and the planner is abandoned; otherwise the run from the path's
//! seed races the mean's ([`race_lanes`]): the answer is the closest of the
//! runs that end `optimal` in the first round in which one does, as for
//! the restarts. What the planner contributes depends only on the mean's
//! run's first iterations, never on timing, so the answer is the same
//! whatever the thread count. When neither run ends `optimal`, the mean's
//! run is the first run as before (the path's when the mean's was stopped
//! as hopeless), and the restarts follow.

use crate::optim::problem::Problem;
use crate::optim::report::Status;
use crate::optim::scp::{Progress, Scp};
use crate::optim::seeds::restart::{closest_optimal, race_lanes, Lane, Race, Spent};
use crate::optim::solution::{Solution, SolveControl};
use crate::Result;
use nalgebra::DVector;
use std::sync::atomic::{AtomicBool, Ordering};

/// Iterations the run from the mean takes before the path's run joins it:
/// the problems it solves alone mostly end within them, and the planner
/// works meanwhile.
pub const HEAD_START: usize = 10;

impl Problem {
    /// The first run of a solve: from the prior mean, raced by a run from
    /// a collision-free path's seed when the mean collides and a path is
    /// found (see the module docs).
    pub(in crate::optim) fn first_run(&self, ctl: &SolveControl) -> Result<Solution> {
        let zero = DVector::zeros(self.whitening.dim());
        let max_iterations = self.options.max_iterations;
        let began = std::time::Instant::now();
        let mut mean = Scp::new(self, &zero, &zero, max_iterations, ctl);
        if !(self.plannable() && mean.iterate().collides()) {
            return mean.run();
        }
        // The planner stops once the mean's run needs no race: it ended
        // `optimal`, or it has left the obstacles.
        let settled = AtomicBool::new(false);
        let mut head_start = || {
            let progress = mean.advance(HEAD_START);
            let settles = match &progress {
                Progress::Done(s) => s.status == Status::Optimal,
                Progress::Paused => !mean.iterate().collides(),
            };
            settled.store(settles, Ordering::Relaxed);
            progress
        };
        let (progress, mut path) = if ctl.parallel() {
            rayon::join(head_start, || self.path_start(ctl, &settled, 0))
        } else {
            let progress = head_start();
            (progress, self.path_start(ctl, &settled, 0))
        };
        let mean_lane = match progress {
            // Optimal, a proof of infeasibility or a stop: nothing to race.
            Progress::Done(done) if done.status != Status::MaxIterations => return Ok(*done),
            Progress::Done(done) => Lane::Finished(done),
            Progress::Paused if settled.load(Ordering::Relaxed) => {
                // Out of the obstacles after the head start: the mean's run
                // goes on alone, and the path's run follows only when that
                // ends without a feasible answer (planned now if the
                // planner was stopped: the same path, which depends only on
                // the seed).
                let alone = mean.run()?;
                if alone.status != Status::MaxIterations {
                    return Ok(alone);
                }
                path = path.or_else(|| self.path_start(ctl, &AtomicBool::new(false), 0));
                Lane::Finished(Box::new(alone))
            }
            Progress::Paused => Lane::Running(Box::new(mean)),
        };
        let Some(path) = path else {
            return match mean_lane {
                Lane::Running(scp) => scp.run(),
                Lane::Finished(done) => Ok(*done),
                Lane::Stopped(_) => self.run(&zero, &zero, max_iterations, ctl),
            };
        };
        let path_lane = Lane::Running(Box::new(Scp::new(self, &path, &zero, max_iterations, ctl)));
        let race = race_lanes(vec![mean_lane, path_lane], ctl);
        match first_of(race, began) {
            Some(first) => Ok(first),
            // Unreachable (a race ends with a finished run), kept total.
            None => self.run(&zero, &zero, max_iterations, ctl),
        }
    }

    /// Whether the problem fixes the start configuration and the end (as
    /// a configuration, `options.final_configuration`, or a goal
    /// position): what the planner joins.
    fn plannable(&self) -> bool {
        self.linear.start.is_some()
            && (self.linear.final_configuration.is_some() || self.goal.is_some())
    }

    /// Whether the planner applies ([`Problem::plannable`]) and the prior
    /// mean's trajectory collides with an obstacle at an optimisation
    /// phase.
    pub(super) fn mean_collides(&self, zero: &DVector<f64>, ctl: &SolveControl) -> bool {
        self.plannable()
            && self
                .evaluate_grid(&self.grid, zero.clone(), zero, ctl)
                .collides()
    }
}

/// The first run's answer from the race of the mean (lane 0) and the path
/// (lane 1): the closest `optimal` run, else the mean's run, else the
/// path's; with every run's counters and a warning saying the path raced.
/// `None` when no run finished.
fn first_of(race: Race, began: std::time::Instant) -> Option<Solution> {
    let Race {
        finished,
        unfinished,
    } = race;
    let best = closest_optimal(&finished);
    let mut runs: Vec<(usize, Solution)> = finished
        .into_iter()
        .enumerate()
        .filter_map(|(k, run)| run.map(|r| (k, r)))
        .collect();
    let pick = best.or_else(|| runs.first().map(|(k, _)| *k))?;
    let at = runs.iter().position(|(k, _)| *k == pick)?;
    let (k, answer) = runs.swap_remove(at);
    let mut spent = Spent::from(&answer);
    spent.solve_ms = began.elapsed().as_secs_f64() * 1e3;
    for (_, run) in &runs {
        spent.add(&run.stats);
    }
    for stats in &unfinished {
        spent.add(stats);
    }
    let note = if k == 1 {
        "the prior mean collides with an obstacle: the answer was found from a collision-free path in configuration space (RRT-Connect), a local optimum; a feasible solution closer to the prior may exist".to_string()
    } else {
        "the prior mean collides with an obstacle: a run from a collision-free path in configuration space (RRT-Connect) raced the run from the mean".to_string()
    };
    Some(spent.onto(answer, note))
}
