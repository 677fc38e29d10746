//! Shared state of the service ([`AppState`]): settings, the loaded robot
//! and (optional) network model, metrics, the solver limiter and the
//! shutdown flag. Cheap to clone (one `Arc`).

use super::config::ServiceConfig;
use super::limits::Limiter;
use super::metrics::Metrics;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Everything a handler needs; nothing in it is read from a request.
#[derive(Clone, Debug)]
pub struct AppState {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    config: ServiceConfig,
    metrics: Metrics,
    limiter: Limiter,
    shutting_down: AtomicBool,
}

impl AppState {
    /// State for `config` (validated here).
    pub fn new(config: ServiceConfig) -> crate::Result<AppState> {
        config.validate()?;
        let limiter = Limiter::new(config.max_concurrency, config.max_queue);
        Ok(AppState {
            inner: Arc::new(Inner {
                config,
                metrics: Metrics::default(),
                limiter,
                shutting_down: AtomicBool::new(false),
            }),
        })
    }

    /// The settings.
    pub fn config(&self) -> &ServiceConfig {
        &self.inner.config
    }

    /// The metrics registry.
    pub fn metrics(&self) -> &Metrics {
        &self.inner.metrics
    }

    /// The solver limiter.
    pub fn limiter(&self) -> &Limiter {
        &self.inner.limiter
    }

    /// Whether a graceful shutdown has begun (`/readyz` then answers 503).
    pub fn is_shutting_down(&self) -> bool {
        self.inner.shutting_down.load(Ordering::SeqCst)
    }

    /// Mark the start of a graceful shutdown.
    pub fn begin_shutdown(&self) {
        self.inner.shutting_down.store(true, Ordering::SeqCst);
    }
}
