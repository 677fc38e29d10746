//! The HTTP service (axum), hardened for a robot cell.
//!
//! | route | what |
//! |---|---|
//! | `POST /v1/optimize` | the optimise request/response of DESIGN.md |
//! | `POST /v1/plan` | image + target box → network prior → optimiser (JSON with base64, or multipart) |
//! | `GET /v1/robot` | joint names, limits, home, collision shapes |
//! | `GET /v1/models` | loaded network models and their configs |
//! | `GET /healthz`, `GET /readyz` | liveness, readiness |
//! | `GET /metrics` | Prometheus text |
//!
//! The contract is `api/openapi.yaml` (a test keeps it and [`routes::table`]
//! equal). Errors are `{"error": {"code", "message", "field"}}`
//! ([`error::ApiError`]); no input gives a 5xx. All of a request's CPU work
//! (body parsing, image decoding, inference, the optimiser) runs on the
//! blocking pool under a concurrency limit and a deadline counted from the
//! request's arrival ([`limits`]); connections are capped and time out, and
//! a shutdown drains within a time limit ([`server`]); an optional bearer
//! token ([`token`]) guards `/v1/*` and `/metrics` ([`auth`]); CORS is off unless
//! origins are configured. No endpoint reads a file path from a request.
//!
//! ```no_run
//! # fn main() -> dpmp::Result<()> {
//! use dpmp::service::{AppState, RunningServer, ServiceConfig};
//! let config = ServiceConfig::default().with_addr("127.0.0.1:0".parse().unwrap());
//! let robot = dpmp::robot::Robot::panda()?;
//! let server = RunningServer::start(AppState::new(config, robot, None)?)?;
//! println!("listening on {}", server.addr());
//! server.shutdown()?;
//! # Ok(()) }
//! ```

pub mod auth;
pub mod config;
pub mod describe;
pub mod error;
pub mod extract;
pub mod image;
pub mod limits;
pub mod metrics;
pub mod routes;
pub mod server;
pub mod state;
pub mod token;

pub use config::ServiceConfig;
pub use error::ApiError;
pub use state::AppState;

use axum::extract::DefaultBodyLimit;
use axum::middleware::from_fn_with_state;
use axum::Router;
use std::future::Future;
use std::net::SocketAddr;
use tokio::sync::oneshot;

/// The complete router for `state`: routes, auth, body limit, metrics,
/// the arrival stamp and shutdown gate ([`server::layers`]), JSON 404/405
/// answers and (only when configured) CORS.
pub fn router(state: AppState) -> Router {
    let mut open = Router::new();
    let mut protected = Router::new();
    for (spec, handler) in routes::table() {
        if spec.protected {
            protected = protected.route(spec.path, handler);
        } else {
            open = open.route(spec.path, handler);
        }
    }
    let protected = protected.route_layer(from_fn_with_state(state.clone(), auth::require_token));
    let mut app = open
        .merge(protected)
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(state.config().body_limit_bytes))
        .layer(from_fn_with_state(
            state.clone(),
            server::layers::declared_length_gate,
        ))
        .layer(from_fn_with_state(
            state.clone(),
            server::layers::shutdown_gate,
        ))
        .layer(from_fn_with_state(state.clone(), server::layers::track))
        .layer(axum::middleware::from_fn(server::layers::stamp_arrival));
    if let Some(cors) = cors_layer(&state.config().cors_origins) {
        app = app.layer(cors);
    }
    app.with_state(state)
}

async fn not_found() -> ApiError {
    ApiError::not_found()
}

async fn method_not_allowed() -> ApiError {
    ApiError::method_not_allowed()
}

fn cors_layer(origins: &[String]) -> Option<tower_http::cors::CorsLayer> {
    use tower_http::cors::{AllowOrigin, CorsLayer};
    if origins.is_empty() {
        return None;
    }
    let values = origins.iter().filter_map(|o| o.parse().ok());
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(values))
            .allow_methods([axum::http::Method::GET, axum::http::Method::POST])
            .allow_headers([
                axum::http::header::CONTENT_TYPE,
                axum::http::header::AUTHORIZATION,
            ]),
    )
}

/// Serve on `listener` until `shutdown` resolves, then drain and close
/// ([`server`]).
pub async fn serve_on(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> crate::Result<()> {
    let app = router(state.clone());
    server::serve_on(listener, state, app, shutdown).await
}

/// Resolves on the first SIGINT (Ctrl-C) or SIGTERM; a second one ends the
/// process at once (exit code 130), whatever is still draining.
pub async fn shutdown_signal() {
    let (first, received) = oneshot::channel::<()>();
    tokio::spawn(async move {
        let mut signals = Signals::new();
        signals.next().await;
        let _ = first.send(());
        signals.next().await;
        tracing::warn!("second signal: exiting now");
        std::process::exit(130);
    });
    let _ = received.await;
}

/// SIGINT and SIGTERM as one stream (the service's shutdown, and the ROS 2
/// node's).
pub struct Signals {
    #[cfg(unix)]
    interrupt: Option<tokio::signal::unix::Signal>,
    #[cfg(unix)]
    terminate: Option<tokio::signal::unix::Signal>,
}

impl Default for Signals {
    fn default() -> Self {
        Signals::new()
    }
}

impl Signals {
    /// Start listening (a signal that cannot be listened for never comes).
    pub fn new() -> Signals {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{signal, SignalKind};
            Signals {
                interrupt: signal(SignalKind::interrupt()).ok(),
                terminate: signal(SignalKind::terminate()).ok(),
            }
        }
        #[cfg(not(unix))]
        Signals {}
    }

    /// The next SIGINT or SIGTERM (never, where neither can be received).
    pub async fn next(&mut self) {
        #[cfg(unix)]
        {
            let interrupt = async {
                match self.interrupt.as_mut() {
                    Some(s) => s.recv().await,
                    None => std::future::pending().await,
                }
            };
            let terminate = async {
                match self.terminate.as_mut() {
                    Some(s) => s.recv().await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                _ = interrupt => {},
                _ = terminate => {},
            }
        }
        #[cfg(not(unix))]
        {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

/// A tokio runtime sized for the service: async workers for I/O plus a
/// blocking pool for the solver slots.
fn runtime(config: &ServiceConfig) -> crate::Result<tokio::runtime::Runtime> {
    let workers = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(2)
        .clamp(2, 8);
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(workers)
        .max_blocking_threads(config.max_concurrency + 4)
        .thread_name("dpmp-serve")
        .enable_all()
        .build()
        .map_err(|e| crate::Error::Numerical(format!("cannot start the async runtime: {e}")))
}

async fn bind(addr: SocketAddr) -> crate::Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(addr)
        .await
        .map_err(|e| crate::Error::invalid("addr", format!("cannot listen on {addr}: {e}")))
}

/// Serve `state` on its configured address until SIGINT/SIGTERM (what
/// `dpmp serve` runs).
pub fn serve(state: AppState) -> crate::Result<()> {
    let rt = runtime(state.config())?;
    let result = rt.block_on(async move {
        let listener = bind(state.config().addr).await?;
        let addr = listener.local_addr().map_err(|e| {
            crate::Error::invalid("addr", format!("cannot read the bound address: {e}"))
        })?;
        tracing::info!(%addr, "dpmp service listening");
        serve_on(listener, state, shutdown_signal()).await
    });
    rt.shutdown_timeout(RUNTIME_SHUTDOWN);
    result
}

/// How long the runtime waits for blocking tasks (cancelled solves) when
/// the server has closed; they stop within milliseconds of the cancel.
const RUNTIME_SHUTDOWN: std::time::Duration = std::time::Duration::from_millis(500);

/// A server running on its own thread and runtime (tests, embedding).
/// Dropping it shuts it down gracefully.
pub struct RunningServer {
    addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<crate::Result<()>>>,
}

impl RunningServer {
    /// Bind `state.config().addr` (port 0 picks a free port) and serve.
    pub fn start(state: AppState) -> crate::Result<RunningServer> {
        let rt = runtime(state.config())?;
        let listener = rt.block_on(bind(state.config().addr))?;
        let addr = listener
            .local_addr()
            .map_err(|e| crate::Error::invalid("addr", format!("no bound address: {e}")))?;
        let (stop, stopped) = oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("dpmp-server".into())
            .spawn(move || {
                let result = rt.block_on(serve_on(listener, state, async move {
                    let _ = stopped.await;
                }));
                rt.shutdown_timeout(RUNTIME_SHUTDOWN);
                result
            })
            .map_err(|e| crate::Error::Numerical(format!("cannot spawn the server: {e}")))?;
        Ok(RunningServer {
            addr,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The bound address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// `http://ADDR{path}`.
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }

    /// Shut down as a signal would ([`server`]: drain, then close) and wait.
    pub fn shutdown(mut self) -> crate::Result<()> {
        self.stop_and_join()
    }

    fn stop_and_join(&mut self) -> crate::Result<()> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        match self.thread.take() {
            Some(thread) => thread
                .join()
                .map_err(|_| crate::Error::Numerical("the server thread panicked".into()))?,
            None => Ok(()),
        }
    }
}

impl Drop for RunningServer {
    fn drop(&mut self) {
        let _ = self.stop_and_join();
    }
}
