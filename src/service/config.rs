//! Service settings ([`ServiceConfig`]): address, request limits, deadline,
//! concurrency and the optional bearer token.

use super::auth::Token;
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
        if self.deadline.is_zero() || self.deadline > Duration::from_secs(3600) {
            return Err(Error::invalid(
                "deadline",
                format!("must be in (0, 3600] s, got {:?}", self.deadline),
            ));
        }
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
