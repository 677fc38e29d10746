//! Service settings ([`ServiceConfig`]): address, request limits, deadline,
//! concurrency, connection caps and timeouts, and the optional bearer
//! token.

use super::token::Token;
use crate::{Error, Result};
use std::net::SocketAddr;
use std::time::Duration;

/// Default address: loopback only; a robot cell exposes it deliberately.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8080";

/// Everything the HTTP service can be tuned with. Build it with
/// [`ServiceConfig::default`] and the `with_*` setters, then
/// [`ServiceConfig::validate`] (done by [`super::AppState::new`]).
#[derive(Clone, Debug)]
pub struct ServiceConfig {
    /// Address to listen on.
    pub addr: SocketAddr,
    /// Largest accepted request body in bytes (default 16 MiB); larger → 413.
    pub body_limit_bytes: usize,
    /// Largest accepted image in pixels (width x height), checked from the
    /// image header before decoding (default 4096 x 4096); larger → 413.
    pub max_image_pixels: u64,
    /// Largest number of obstacles in one request (default 256); more → 422.
    pub max_obstacles: usize,
    /// Largest number of extra `samples` in one request (default 32); more → 422.
    pub max_samples: usize,
    /// Largest `promp.n_samples` in one request (default 2000); more → 422.
    pub max_trajectory_samples: usize,
    /// Time budget of one solve, from the moment the request is accepted
    /// (default 2 s). The solver stops cleanly at the deadline and answers
    /// `max_iterations`; a request still queued at the deadline gets 503.
    pub deadline: Duration,
    /// Number of solves running at once on the blocking pool (default: the
    /// number of CPU cores).
    pub max_concurrency: usize,
    /// Number of requests allowed to wait for a solver slot (default 256);
    /// beyond that the service answers 429 at once.
    pub max_queue: usize,
    /// Time a client has to send a request's headers (and, on a kept-alive
    /// connection, the next request's) before the connection is closed
    /// (default 10 s).
    pub header_read_timeout: Duration,
    /// Time a client has to send a request's body once the headers are in
    /// (default 30 s); slower → 408 `body_timeout`. The deadline counts
    /// too: a body still arriving at the deadline gets 503.
    pub body_read_timeout: Duration,
    /// Open connections at most (default 512). At the cap a new connection
    /// takes the place of the oldest idle one (no request in flight); when
    /// every connection is busy it is answered 503 `too_many_connections`.
    pub max_connections: usize,
    /// Open connections from one IP address at most (default 128), with the
    /// same rule.
    pub max_connections_per_ip: usize,
    /// How long a graceful shutdown waits for requests in flight before it
    /// closes every connection and cancels the solves (default 5 s).
    pub drain_timeout: Duration,
    /// Decoded image bytes held at once across all requests (default 512
    /// MiB); an image is counted at twice its decoded size (the decode and
    /// its RGB copy). A request waits for room until its deadline; one image
    /// larger than the whole budget → 413 `image_too_large`.
    pub max_decoded_bytes: u64,
    /// Bearer token required on `/v1/*` and `/metrics` when set.
    pub token: Option<Token>,
    /// Origins allowed by CORS; empty (the default) = CORS off.
    pub cors_origins: Vec<String>,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        let cores = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(2);
        ServiceConfig {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            body_limit_bytes: 16 * 1024 * 1024,
            max_image_pixels: 4096 * 4096,
            max_obstacles: 256,
            max_samples: 32,
            max_trajectory_samples: 2000,
            deadline: Duration::from_secs(2),
            max_concurrency: cores,
            max_queue: 256,
            header_read_timeout: Duration::from_secs(10),
            body_read_timeout: Duration::from_secs(30),
            max_connections: 512,
            max_connections_per_ip: 128,
            drain_timeout: Duration::from_secs(5),
            max_decoded_bytes: 512 << 20,
            token: None,
            cors_origins: Vec::new(),
        }
    }
}

impl ServiceConfig {
    /// Set the listening address.
    pub fn with_addr(mut self, addr: SocketAddr) -> Self {
        self.addr = addr;
        self
    }

    /// Set the body limit in bytes.
    pub fn with_body_limit(mut self, bytes: usize) -> Self {
        self.body_limit_bytes = bytes;
        self
    }

    /// Set the per-request deadline.
    pub fn with_deadline(mut self, deadline: Duration) -> Self {
        self.deadline = deadline;
        self
    }

    /// Set the number of concurrent solves and the queue length.
    pub fn with_concurrency(mut self, slots: usize, queue: usize) -> Self {
        self.max_concurrency = slots;
        self.max_queue = queue;
        self
    }

    /// Require this bearer token.
    pub fn with_token(mut self, token: Token) -> Self {
        self.token = Some(token);
        self
    }

    /// Check every setting; errors name the setting.
    pub fn validate(&self) -> Result<()> {
        positive("body_limit_bytes", self.body_limit_bytes as u64)?;
        positive("max_image_pixels", self.max_image_pixels)?;
        positive("max_trajectory_samples", self.max_trajectory_samples as u64)?;
        positive("max_concurrency", self.max_concurrency as u64)?;
        positive("max_connections", self.max_connections as u64)?;
        positive("max_connections_per_ip", self.max_connections_per_ip as u64)?;
        positive("max_decoded_bytes", self.max_decoded_bytes)?;
        for (field, value) in [
            ("deadline", self.deadline),
            ("header_read_timeout", self.header_read_timeout),
            ("body_read_timeout", self.body_read_timeout),
            ("drain_timeout", self.drain_timeout),
        ] {
            if value.is_zero() || value > Duration::from_secs(3600) {
                return Err(Error::invalid(
                    field,
                    format!("must be in (0, 3600] s, got {value:?}"),
                ));
            }
        }
        if self.max_connections_per_ip > self.max_connections {
            return Err(Error::invalid(
                "max_connections_per_ip",
                format!(
                    "must be at most max_connections ({}), got {}",
                    self.max_connections, self.max_connections_per_ip
                ),
            ));
        }
        check_descriptor_limit(self.max_connections)?;
        if self.max_concurrency > 1024 {
            return Err(Error::invalid(
                "max_concurrency",
                format!("must be at most 1024, got {}", self.max_concurrency),
            ));
        }
        for (i, origin) in self.cors_origins.iter().enumerate() {
            if origin.parse::<axum::http::HeaderValue>().is_err() || origin.is_empty() {
                return Err(Error::invalid(
                    format!("cors_origins[{i}]"),
                    "must be a non-empty header value such as https://cell.local",
                ));
            }
        }
        Ok(())
    }
}

/// File descriptors the process keeps for itself beyond the connections
/// (listener, model and log files, the runtime's own).
pub const RESERVED_DESCRIPTORS: u64 = 64;

/// Refuse a connection cap the process's open-file limit cannot hold (the
/// accept loop would fail with "Too many open files" before the cap).
fn check_descriptor_limit(max_connections: usize) -> Result<()> {
    let Some(limit) = open_file_limit() else {
        return Ok(());
    };
    let needed = max_connections as u64 + RESERVED_DESCRIPTORS;
    if needed > limit {
        return Err(Error::invalid(
            "max_connections",
            format!(
                "{max_connections} connections need {needed} file descriptors, but the process may open {limit} (ulimit -n): lower the cap or raise the limit"
            ),
        ));
    }
    Ok(())
}

/// The soft limit on open files (`Max open files` in `/proc/self/limits`),
/// when the platform says.
fn open_file_limit() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max open files"))?;
    let soft = line.split_whitespace().nth(3)?;
    soft.parse().ok()
}

fn positive(field: &str, value: u64) -> Result<()> {
    if value == 0 {
        Err(Error::invalid(field, "must be positive"))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_loopback() {
        let c = ServiceConfig::default();
        c.validate().unwrap();
        assert!(c.addr.ip().is_loopback());
        assert_eq!(c.body_limit_bytes, 16 << 20);
        assert!(c.token.is_none() && c.cors_origins.is_empty());
        assert_eq!(c.addr.to_string(), DEFAULT_ADDR);
    }

    #[test]
    fn bad_settings_name_the_setting() {
        let e = ServiceConfig::default()
            .with_body_limit(0)
            .validate()
            .unwrap_err();
        assert_eq!(e.field(), Some("body_limit_bytes"));
        let e = ServiceConfig::default()
            .with_deadline(Duration::ZERO)
            .validate()
            .unwrap_err();
        assert_eq!(e.field(), Some("deadline"));
        let e = ServiceConfig::default()
            .with_concurrency(0, 4)
            .validate()
            .unwrap_err();
        assert_eq!(e.field(), Some("max_concurrency"));
    }
}
