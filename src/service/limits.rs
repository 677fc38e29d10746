//! Concurrency limit, blocking pool and deadline for the CPU-heavy work
//! (network inference, the optimiser).
//!
//! [`Limiter::run`] admits a job when fewer than `max_queue` jobs are
//! waiting (else 429 `overloaded`), waits for one of `max_concurrency`
//! solver slots until the deadline (else 503 `deadline_exceeded`), then runs
//! the job on tokio's blocking pool so the async runtime never stalls. The
//! job receives a [`Job`] with the deadline and a cancel flag; the flag is
//! raised when the client goes away (the handler future is dropped) and
//! when the answer is still missing a grace period after the deadline, at
//! which point the client gets 503 instead of a hung connection.

use super::error::ApiError;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;

/// Time after the deadline that a job gets to return its (partial) answer
/// before the request is answered 503.
pub const GRACE: Duration = Duration::from_millis(500);

/// What a job may read to stop cleanly.
#[derive(Clone, Debug)]
pub struct Job {
    /// When the job should stop and return its best answer.
    pub deadline: Instant,
    /// Raised when nobody waits for the answer any more.
    pub cancel: Arc<AtomicBool>,
}

impl Job {
    /// Whether the job should stop now.
    pub fn should_stop(&self) -> bool {
        self.cancel.load(Ordering::Relaxed) || Instant::now() >= self.deadline
    }
}

/// Admission control for CPU-heavy jobs. Cheap to clone.
#[derive(Clone, Debug)]
pub struct Limiter {
    slots: Arc<Semaphore>,
    waiting: Arc<AtomicUsize>,
    running: Arc<AtomicUsize>,
    max_queue: usize,
}

/// Counts of the limiter at one instant (for `/metrics`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LimiterLoad {
    /// Jobs waiting for a slot.
    pub waiting: usize,
    /// Jobs running.
    pub running: usize,
}

/// Decrements a counter when dropped.
struct CountGuard(Arc<AtomicUsize>);

impl CountGuard {
    fn enter(counter: &Arc<AtomicUsize>) -> (CountGuard, usize) {
        let before = counter.fetch_add(1, Ordering::SeqCst);
        (CountGuard(counter.clone()), before + 1)
    }
}

impl Drop for CountGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Raises the cancel flag when dropped (client gone, or answered).
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

impl Limiter {
    /// `max_concurrency` jobs at once, at most `max_queue` waiting.
    pub fn new(max_concurrency: usize, max_queue: usize) -> Limiter {
        Limiter {
            slots: Arc::new(Semaphore::new(max_concurrency)),
            waiting: Arc::new(AtomicUsize::new(0)),
            running: Arc::new(AtomicUsize::new(0)),
            max_queue,
        }
    }

    /// Current load.
    pub fn load(&self) -> LimiterLoad {
        LimiterLoad {
            waiting: self.waiting.load(Ordering::SeqCst),
            running: self.running.load(Ordering::SeqCst),
        }
    }

    /// Run `work` on the blocking pool under the limits described in the
    /// module docs.
    pub async fn run<T, F>(&self, deadline: Instant, work: F) -> Result<T, ApiError>
    where
        T: Send + 'static,
        F: FnOnce(&Job) -> T + Send + 'static,
    {
        let permit = {
            let (_queued, now_waiting) = CountGuard::enter(&self.waiting);
            if now_waiting > self.max_queue + self.slots.available_permits() {
                return Err(ApiError::overloaded());
            }
            let acquire = self.slots.clone().acquire_owned();
            match tokio::time::timeout_at(deadline.into(), acquire).await {
                Ok(Ok(permit)) => permit,
                Ok(Err(_closed)) => return Err(ApiError::internal("the solver pool is closed")),
                Err(_elapsed) => {
                    return Err(ApiError::deadline_exceeded(
                        "the deadline passed while waiting for a free solver",
                    ))
                }
            }
        };
        let job = Job {
            deadline,
            cancel: Arc::new(AtomicBool::new(false)),
        };
        let _cancel_on_drop = CancelOnDrop(job.cancel.clone());
        let running = self.running.clone();
        let task = tokio::task::spawn_blocking(move || {
            let _slot = permit;
            let (_running, _) = CountGuard::enter(&running);
            work(&job)
        });
        match tokio::time::timeout_at((deadline + GRACE).into(), task).await {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(join)) => Err(ApiError::internal(format!(
                "the solver task failed: {join}"
            ))),
            Err(_elapsed) => Err(ApiError::deadline_exceeded(
                "the solver did not stop by the deadline",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn runs_jobs_and_reports_their_values() {
        let limiter = Limiter::new(2, 4);
        let deadline = Instant::now() + Duration::from_secs(5);
        let v = limiter.run(deadline, |_| 40 + 2).await.unwrap();
        assert_eq!(v, 42);
        assert_eq!(
            limiter.load(),
            LimiterLoad {
                waiting: 0,
                running: 0
            }
        );
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn full_queue_answers_429_and_late_queue_503() {
        let limiter = Limiter::new(1, 0);
        let long = Instant::now() + Duration::from_secs(5);
        let busy = {
            let l = limiter.clone();
            tokio::spawn(async move {
                l.run(long, |job| {
                    while !job.should_stop() {
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    job.cancel.load(Ordering::Relaxed)
                })
                .await
            })
        };
        while limiter.load().running == 0 {
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        let e = limiter.run(long, |_| ()).await.unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (429, "overloaded"));

        let roomy = Limiter {
            max_queue: 8,
            ..limiter.clone()
        };
        let soon = Instant::now() + Duration::from_millis(30);
        let e = roomy.run(soon, |_| ()).await.unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (503, "deadline_exceeded"));
        busy.abort();
        // Aborting the handler drops its future, which raises the cancel flag
        // and lets the blocking job finish early.
        let t0 = Instant::now();
        while limiter.load().running != 0 {
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        assert!(t0.elapsed() < Duration::from_secs(2));
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_job_ignoring_the_deadline_gets_503_not_a_hang() {
        let limiter = Limiter::new(1, 1);
        let deadline = Instant::now() + Duration::from_millis(20);
        let t0 = Instant::now();
        let e = limiter
            .run(deadline, |job| {
                // Ignores the deadline but honours cancellation.
                while !job.cancel.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(2));
                }
            })
            .await
            .unwrap_err();
        assert_eq!(e.status.as_u16(), 503);
        assert!(t0.elapsed() < GRACE + Duration::from_secs(1));
    }
}
