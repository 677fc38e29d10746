//! Shared state of the service ([`AppState`]): settings, the loaded robot
//! and (optional) network model, metrics, the solver limiter and the
//! shutdown flag. Cheap to clone (one `Arc`).

use super::config::ServiceConfig;
use super::describe;
use super::image::DecodeBudget;
use super::limits::Limiter;
use super::metrics::Metrics;
use crate::net::Model;
use crate::robot::Robot;
use serde_json::Value;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// When a request arrived (its headers were read): stamped by the
/// outermost layer, read by [`AppState::deadline_of`].
#[derive(Clone, Copy, Debug)]
pub struct Arrival(pub Instant);

/// Everything a handler needs; nothing in it is read from a request.
#[derive(Clone, Debug)]
pub struct AppState {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    config: ServiceConfig,
    robot: Arc<Robot>,
    model: Option<Arc<Model>>,
    robot_info: Value,
    models_info: Value,
    metrics: Metrics,
    limiter: Limiter,
    decode_budget: Arc<DecodeBudget>,
    shutting_down: AtomicBool,
}

impl AppState {
    /// State for `config` (validated here), `robot` and an optional model.
    pub fn new(
        config: ServiceConfig,
        robot: Robot,
        model: Option<Model>,
    ) -> crate::Result<AppState> {
        config.validate()?;
        if let Some(model) = &model {
            model.config().check_robot(&robot)?;
        }
        let limiter = Limiter::new(config.max_concurrency, config.max_queue);
        let decode_budget = Arc::new(DecodeBudget::new(config.max_decoded_bytes));
        let robot_info = to_json("robot", &describe::robot(&robot))?;
        let models_info = to_json("models", &describe::models(model.as_ref()))?;
        Ok(AppState {
            inner: Arc::new(Inner {
                config,
                robot: Arc::new(robot),
                model: model.map(Arc::new),
                robot_info,
                models_info,
                metrics: Metrics::default(),
                limiter,
                decode_budget,
                shutting_down: AtomicBool::new(false),
            }),
        })
    }

    /// The settings.
    pub fn config(&self) -> &ServiceConfig {
        &self.inner.config
    }

    /// The robot.
    pub fn robot(&self) -> Arc<Robot> {
        self.inner.robot.clone()
    }

    /// The network model, when one is loaded.
    pub fn model(&self) -> Option<Arc<Model>> {
        self.inner.model.clone()
    }

    /// The `/v1/robot` body (computed once).
    pub fn robot_info(&self) -> &Value {
        &self.inner.robot_info
    }

    /// The `/v1/models` body (computed once).
    pub fn models_info(&self) -> &Value {
        &self.inner.models_info
    }

    /// The metrics registry.
    pub fn metrics(&self) -> &Metrics {
        &self.inner.metrics
    }

    /// The solver limiter.
    pub fn limiter(&self) -> &Limiter {
        &self.inner.limiter
    }

    /// The budget of decoded image bytes held at once.
    pub fn decode_budget(&self) -> Arc<DecodeBudget> {
        self.inner.decode_budget.clone()
    }

    /// The deadline of a request: its [`Arrival`] (stamped by the outermost
    /// layer; now, for a request without one) plus the configured deadline.
    pub fn deadline_of(&self, request: &axum::extract::Request) -> Instant {
        let arrived = request
            .extensions()
            .get::<Arrival>()
            .map_or_else(Instant::now, |a| a.0);
        arrived + self.inner.config.deadline
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

fn to_json<T: serde::Serialize>(what: &str, value: &T) -> crate::Result<Value> {
    serde_json::to_value(value)
        .map_err(|e| crate::Error::Numerical(format!("cannot describe the {what}: {e}")))
}
