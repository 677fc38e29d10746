//! Concurrency limit, blocking pool and deadline for the CPU-heavy work
//! (body parsing, image decoding, network inference, the optimiser).
//!
//! [`Limiter::run`] admits a job when fewer than `max_queue` jobs are
//! waiting (else 429 `overloaded`), waits for one of `max_concurrency`
//! solver slots until the deadline (else 503 `deadline_exceeded`), then runs
//! the job on tokio's blocking pool so the async runtime never stalls. The
//! job receives a [`Job`] with the deadline and a cancel flag; the flag is
//! raised when the client goes away (the handler future is dropped), when
//! the answer is still missing a grace period after the deadline (the
//! client then gets 503 instead of a hung connection), and for every job at
//! the end of a shutdown ([`Limiter::cancel_all`]). The optimiser checks
//! both once per phase of its long loops, so a job stops within
//! milliseconds of either.
//!
//! A panic inside a job is caught: the client gets 500 `internal` with the
//! server's own words, and the panic's text goes to the log only.

use super::error::ApiError;
use std::collections::HashMap;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;

/// Time after the deadline that a job gets to return its (partial) answer
/// before the request is answered 503.
pub const GRACE: Duration = Duration::from_millis(500);

/// What a job may read to stop cleanly, and how many jobs share the
/// machine with it.
#[derive(Clone, Debug)]
pub struct Job {
    /// When the job should stop and return its best answer.
    pub deadline: Instant,
    /// Raised when nobody waits for the answer any more.
    pub cancel: Arc<AtomicBool>,
    /// Jobs running now, this one included.
    pub running: Arc<AtomicUsize>,
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
    /// Cancel flags of the jobs admitted and not yet finished.
    jobs: Arc<Mutex<HashMap<u64, Arc<AtomicBool>>>>,
    next_job: Arc<AtomicU64>,
    closed: Arc<AtomicBool>,
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

/// Keeps a job's cancel flag in the registry while the job runs.
struct Registered {
    jobs: Arc<Mutex<HashMap<u64, Arc<AtomicBool>>>>,
    id: u64,
}

impl Drop for Registered {
    fn drop(&mut self) {
        lock(&self.jobs).remove(&self.id);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Limiter {
    /// `max_concurrency` jobs at once, at most `max_queue` waiting.
    pub fn new(max_concurrency: usize, max_queue: usize) -> Limiter {
        Limiter {
            slots: Arc::new(Semaphore::new(max_concurrency)),
            waiting: Arc::new(AtomicUsize::new(0)),
            running: Arc::new(AtomicUsize::new(0)),
            max_queue,
            jobs: Arc::new(Mutex::new(HashMap::new())),
            next_job: Arc::new(AtomicU64::new(0)),
            closed: Arc::new(AtomicBool::new(false)),
        }
    }

    /// Current load.
    pub fn load(&self) -> LimiterLoad {
        LimiterLoad {
            waiting: self.waiting.load(Ordering::SeqCst),
            running: self.running.load(Ordering::SeqCst),
        }
    }

    /// Refuse new jobs (503 `shutting_down`) and raise the cancel flag of
    /// every job admitted: the end of a shutdown.
    pub fn cancel_all(&self) {
        self.closed.store(true, Ordering::SeqCst);
        self.slots.close();
        for flag in lock(&self.jobs).values() {
            flag.store(true, Ordering::SeqCst);
        }
    }

    /// Run `work` on the blocking pool under the limits described in the
    /// module docs.
    pub async fn run<T, F>(&self, deadline: Instant, work: F) -> Result<T, ApiError>
    where
        T: Send + 'static,
        F: FnOnce(&Job) -> T + Send + 'static,
    {
        if self.closed.load(Ordering::SeqCst) {
            return Err(ApiError::shutting_down());
        }
        let permit = {
            let (_queued, now_waiting) = CountGuard::enter(&self.waiting);
            if now_waiting > self.max_queue + self.slots.available_permits() {
                return Err(ApiError::overloaded());
            }
            let acquire = self.slots.clone().acquire_owned();
            match tokio::time::timeout_at(deadline.into(), acquire).await {
                Ok(Ok(permit)) => permit,
                Ok(Err(_closed)) => return Err(ApiError::shutting_down()),
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
            running: self.running.clone(),
        };
        let registered = self.register(&job);
        let _cancel_on_drop = CancelOnDrop(job.cancel.clone());
        let running = self.running.clone();
        let task = tokio::task::spawn_blocking(move || {
            let _slot = permit;
            let _registered = registered;
            let (_running, _) = CountGuard::enter(&running);
            std::panic::catch_unwind(AssertUnwindSafe(|| work(&job)))
        });
        match tokio::time::timeout_at((deadline + GRACE).into(), task).await {
            Ok(Ok(Ok(value))) => Ok(value),
            Ok(Ok(Err(panic))) => Err(internal_failure(&panic_text(panic.as_ref()))),
            Ok(Err(join)) => Err(internal_failure(&join.to_string())),
            Err(_elapsed) => Err(ApiError::deadline_exceeded(
                "the solver did not stop by the deadline",
            )),
        }
    }

    fn register(&self, job: &Job) -> Registered {
        let id = self.next_job.fetch_add(1, Ordering::SeqCst);
        lock(&self.jobs).insert(id, job.cancel.clone());
        if self.closed.load(Ordering::SeqCst) {
            job.cancel.store(true, Ordering::SeqCst);
        }
        Registered {
            jobs: self.jobs.clone(),
            id,
        }
    }
}

/// Log a job's failure in full; answer 500 without its text.
fn internal_failure(detail: &str) -> ApiError {
    tracing::error!(detail, "a request's job panicked (a bug)");
    ApiError::internal(
        "the server failed on this request (a bug; the details are in the server log)",
    )
}

/// The message of a panic payload.
fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_string()
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
        // A job counts itself among the running (its solves read this to
        // decide whether a core is idle).
        let seen = limiter
            .run(deadline, |job| job.running.load(Ordering::SeqCst))
            .await
            .unwrap();
        assert_eq!(seen, 1);
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
    async fn a_panicking_job_answers_500_without_its_text() {
        let limiter = Limiter::new(1, 1);
        let deadline = Instant::now() + Duration::from_secs(5);
        let e = limiter
            .run(deadline, |_| -> u8 { panic!("secret index out of bounds") })
            .await
            .unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (500, "internal"));
        assert!(!e.message.contains("secret"), "{}", e.message);
        // The slot came back.
        assert_eq!(limiter.run(deadline, |_| 7).await.unwrap(), 7);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn cancel_all_stops_running_jobs_and_refuses_new_ones() {
        let limiter = Limiter::new(1, 4);
        let long = Instant::now() + Duration::from_secs(30);
        let busy = {
            let l = limiter.clone();
            tokio::spawn(async move {
                l.run(long, |job| {
                    while !job.should_stop() {
                        std::thread::sleep(Duration::from_millis(1));
                    }
                })
                .await
            })
        };
        while limiter.load().running == 0 {
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        let t0 = Instant::now();
        limiter.cancel_all();
        busy.await.unwrap().unwrap();
        assert!(t0.elapsed() < Duration::from_millis(200));
        let e = limiter.run(long, |_| ()).await.unwrap_err();
        assert_eq!((e.status.as_u16(), e.code), (503, "shutting_down"));
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
