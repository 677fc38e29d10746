//! The accept loop: connections under caps and timeouts, and a shutdown
//! that drains within a time limit.
//!
//! axum's own `serve` has no header or body timeouts, no connection cap and
//! a shutdown that waits forever for a half-sent request, so the service
//! drives hyper's HTTP/1.1 connections itself:
//!
//! - **Caps** ([`connections`]): `max_connections` in all and
//!   `max_connections_per_ip`; at a cap the oldest idle connection gives
//!   way, and when every one is busy the new one is answered 503
//!   `too_many_connections` and closed. `/healthz` answers throughout a
//!   flood of idle connections.
//! - **Timeouts**: hyper's header read timeout (`header_read_timeout`,
//!   also between requests on a kept-alive connection); the body read
//!   timeout and the request deadline are the handlers' ([`super::extract`]).
//!   A request head over [`MAX_HEADER_BYTES`] is answered 431.
//! - **Errors**: hyper's own 400/414/431 answers get the JSON error body,
//!   and the ends hyper answers with silence (an HTTP/2 preface, a request
//!   head cut by the header timeout) get an answer before the close
//!   ([`json_errors`]).
//! - **Shutdown**, in three phases: *serve* until the shutdown future
//!   resolves; *drain*: `/readyz` answers 503 `shutting_down: true`, every
//!   other route 503 `shutting_down` ([`layers`]), every answer carries
//!   `connection: close`, idle connections are closed, and new connections
//!   are still accepted so that late clients get that answer instead of a
//!   reset; after the requests in flight finish, or `drain_timeout` at the
//!   latest, *close*: every connection is dropped and every running solve
//!   cancelled ([`super::limits::Limiter::cancel_all`]).

pub mod connections;
pub mod json_errors;
pub mod layers;

use super::state::AppState;
use axum::Router;
use connections::{Connection, ConnectionTable, Refusal};
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use json_errors::JsonErrors;
use std::future::Future;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinSet;

/// How often the drain looks whether the requests in flight are done.
const DRAIN_POLL: Duration = Duration::from_millis(10);

/// Pause after a failed `accept` (e.g. out of file descriptors), so the
/// loop does not spin.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(20);

/// Serve `app` on `listener` until `shutdown` resolves, then drain and
/// close as the module docs say.
pub async fn serve_on(
    listener: TcpListener,
    state: AppState,
    app: Router,
    shutdown: impl Future<Output = ()> + Send,
) -> crate::Result<()> {
    let config = state.config().clone();
    let table = ConnectionTable::new(config.max_connections, config.max_connections_per_ip);
    let mut accept = Acceptor {
        app,
        table: table.clone(),
        header_read_timeout: config.header_read_timeout,
        tasks: JoinSet::new(),
    };
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            accepted = listener.accept() => accept.handle(accepted).await,
        }
    }
    state.begin_shutdown();
    tracing::info!(
        in_flight = table.busy(),
        drain_timeout_ms = config.drain_timeout.as_millis() as u64,
        "shutting down: draining requests in flight"
    );
    table.close_idle();
    let drained = tokio::time::sleep(config.drain_timeout);
    tokio::pin!(drained);
    loop {
        tokio::select! {
            _ = &mut drained => {
                tracing::warn!(in_flight = table.busy(), "drain timeout: closing every connection");
                break;
            }
            _ = tokio::time::sleep(DRAIN_POLL) => {
                if table.busy() == 0 {
                    break;
                }
            }
            accepted = listener.accept() => accept.handle(accepted).await,
        }
    }
    drop(listener);
    table.close_all();
    state.limiter().cancel_all();
    accept.tasks.abort_all();
    while accept.tasks.join_next().await.is_some() {}
    tracing::info!("shut down");
    Ok(())
}

/// What the accept loop needs for each new connection.
struct Acceptor {
    app: Router,
    table: ConnectionTable,
    header_read_timeout: Duration,
    tasks: JoinSet<()>,
}

impl Acceptor {
    /// Admit or refuse one accepted connection.
    async fn handle(&mut self, accepted: std::io::Result<(TcpStream, SocketAddr)>) {
        while self.tasks.try_join_next().is_some() {}
        let (stream, peer) = match accepted {
            Ok(pair) => pair,
            Err(e) => {
                tracing::warn!(error = %e, "accept failed");
                tokio::time::sleep(ACCEPT_BACKOFF).await;
                return;
            }
        };
        let _ = stream.set_nodelay(true);
        match self.table.admit(peer.ip()) {
            Ok(connection) => {
                let app = self.app.clone();
                let timeout = self.header_read_timeout;
                self.tasks
                    .spawn(serve_connection(stream, connection, app, timeout));
            }
            Err(refusal) => {
                tracing::warn!(%peer, ?refusal, "connection refused at the cap");
                self.tasks.spawn(refuse(stream, refusal));
            }
        }
    }
}

/// Serve one connection until it ends or the table evicts it; when hyper
/// gives up without answering (an HTTP/2 preface, a head cut by the header
/// timeout), send the connection's last word ([`json_errors`]) before
/// closing.
async fn serve_connection(
    stream: TcpStream,
    connection: Connection,
    app: Router,
    header_read_timeout: Duration,
) {
    let busy = connection.busy_counter();
    let router = TowerToHyperService::new(app);
    let service = hyper::service::service_fn(move |request: hyper::Request<Incoming>| {
        let guard = BusyGuard::enter(&busy);
        let answer = hyper::service::Service::call(&router, request);
        Box::pin(async move {
            let response = answer.await;
            drop(guard);
            response
        })
    });
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(header_read_timeout)
        .max_header_size(MAX_HEADER_BYTES)
        .writev(false);
    let mut conn = builder.serve_connection(TokioIo::new(JsonErrors::new(stream)), service);
    let evicted = connection.evicted();
    tokio::pin!(evicted);
    let mut closing = false;
    let result = std::future::poll_fn(|cx| {
        if !closing && evicted.as_mut().poll(cx).is_ready() {
            closing = true;
            std::pin::Pin::new(&mut conn).graceful_shutdown();
        }
        conn.poll_without_shutdown(cx)
    })
    .await;
    let end = match &result {
        Err(e) if e.is_timeout() => json_errors::End::HeaderTimeout,
        _ => json_errors::End::Other,
    };
    log_end(result);
    let io = conn.into_parts().io.into_inner();
    let last_word = io.last_word(end, header_read_timeout);
    let mut stream = io.into_inner();
    match last_word {
        Some(bytes) => send_and_close(stream, &bytes).await,
        None => {
            let _ = tokio::time::timeout(REFUSAL_LINGER, stream.shutdown()).await;
        }
    }
}

fn log_end(result: Result<(), hyper::Error>) {
    if let Err(e) = result {
        tracing::debug!(error = %e, "connection ended with an error");
    }
}

/// Answer a connection refused at a cap with a JSON 503 and close it.
async fn refuse(stream: TcpStream, refusal: Refusal) {
    let body = json_errors::error_body("too_many_connections", refusal.message());
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n{body}",
        body.len()
    );
    send_and_close(stream, answer.as_bytes()).await;
}

/// Write `bytes`, close the writing half and read what the client still
/// sends, for at most [`REFUSAL_LINGER`]: closing with unread bytes makes
/// the kernel reset the connection, and a reset can discard the answer
/// before the client reads it.
async fn send_and_close(mut stream: TcpStream, bytes: &[u8]) {
    let answer_and_drain = async {
        stream.write_all(bytes).await?;
        stream.shutdown().await?;
        let mut sink = [0u8; 4096];
        while stream.read(&mut sink).await? > 0 {}
        Ok::<(), std::io::Error>(())
    };
    let _ = tokio::time::timeout(REFUSAL_LINGER, answer_and_drain).await;
}

/// How long a refused (or last-worded) connection is kept to deliver its
/// answer.
const REFUSAL_LINGER: Duration = Duration::from_millis(500);

/// Largest request head (request line and headers) read; larger → 431.
pub const MAX_HEADER_BYTES: usize = 64 * 1024;

/// Counts a request in flight on its connection while alive.
struct BusyGuard(Arc<AtomicUsize>);

impl BusyGuard {
    fn enter(counter: &Arc<AtomicUsize>) -> BusyGuard {
        counter.fetch_add(1, Ordering::SeqCst);
        BusyGuard(counter.clone())
    }
}

impl Drop for BusyGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}
