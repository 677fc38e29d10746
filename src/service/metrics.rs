//! Service metrics in the Prometheus text exposition format (version 0.0.4),
//! written by hand: request counts by route, method and status, request
//! latency histograms by route, solver iteration histogram, solver statuses,
//! and the limiter's queue gauges.

use super::limits::LimiterLoad;
use super::state::AppState;
use axum::extract::{MatchedPath, Request, State};
use axum::middleware::Next;
use axum::response::Response;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Mutex;
use std::time::Instant;

/// Upper bounds (s) of the latency buckets.
pub const LATENCY_BUCKETS_S: [f64; 14] = [
    0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0,
];
/// Upper bounds of the solver-iteration buckets.
pub const ITERATION_BUCKETS: [f64; 10] = [0.0, 1.0, 2.0, 3.0, 5.0, 8.0, 13.0, 21.0, 34.0, 55.0];

/// A cumulative histogram with fixed bounds.
#[derive(Clone, Debug)]
struct Histogram {
    bounds: &'static [f64],
    counts: Vec<u64>,
    sum: f64,
    count: u64,
}

impl Histogram {
    fn new(bounds: &'static [f64]) -> Histogram {
        Histogram {
            bounds,
            counts: vec![0; bounds.len()],
            sum: 0.0,
            count: 0,
        }
    }

    fn observe(&mut self, value: f64) {
        for (bound, count) in self.bounds.iter().zip(self.counts.iter_mut()) {
            if value <= *bound {
                *count += 1;
            }
        }
        self.sum += value;
        self.count += 1;
    }

    fn write(&self, out: &mut String, name: &str, labels: &str) {
        let sep = if labels.is_empty() { "" } else { "," };
        for (bound, count) in self.bounds.iter().zip(&self.counts) {
            let _ = writeln!(out, "{name}_bucket{{{labels}{sep}le=\"{bound}\"}} {count}");
        }
        let _ = writeln!(
            out,
            "{name}_bucket{{{labels}{sep}le=\"+Inf\"}} {}",
            self.count
        );
        let braces = if labels.is_empty() {
            String::new()
        } else {
            format!("{{{labels}}}")
        };
        let _ = writeln!(out, "{name}_sum{braces} {}", self.sum);
        let _ = writeln!(out, "{name}_count{braces} {}", self.count);
    }
}

#[derive(Debug)]
struct Inner {
    requests: BTreeMap<(String, String, u16), u64>,
    latency: BTreeMap<String, Histogram>,
    iterations: Histogram,
    statuses: BTreeMap<String, u64>,
}

/// All counters of the service. Shared through [`AppState`].
#[derive(Debug)]
pub struct Metrics {
    inner: Mutex<Inner>,
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics {
            inner: Mutex::new(Inner {
                requests: BTreeMap::new(),
                latency: BTreeMap::new(),
                iterations: Histogram::new(&ITERATION_BUCKETS),
                statuses: BTreeMap::new(),
            }),
        }
    }
}

impl Metrics {
    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock cannot leave the counters invalid.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Count one answered request.
    pub fn record_request(&self, route: &str, method: &str, status: u16, seconds: f64) {
        let mut inner = self.lock();
        *inner
            .requests
            .entry((route.to_string(), method.to_string(), status))
            .or_insert(0) += 1;
        inner
            .latency
            .entry(route.to_string())
            .or_insert_with(|| Histogram::new(&LATENCY_BUCKETS_S))
            .observe(seconds);
    }

    /// Count one finished solve with its status (`optimal`, ...) and SCP
    /// iterations.
    pub fn record_solve(&self, status: &str, iterations: usize) {
        let mut inner = self.lock();
        *inner.statuses.entry(status.to_string()).or_insert(0) += 1;
        inner.iterations.observe(iterations as f64);
    }

    /// The exposition text.
    pub fn render(&self, load: LimiterLoad) -> String {
        let inner = self.lock();
        let mut out = String::with_capacity(4096);
        header(
            &mut out,
            "dpmp_http_requests_total",
            "counter",
            "Answered HTTP requests.",
        );
        for ((route, method, status), n) in &inner.requests {
            let _ = writeln!(
                out,
                "dpmp_http_requests_total{{route=\"{}\",method=\"{}\",status=\"{status}\"}} {n}",
                escape(route),
                escape(method)
            );
        }
        let name = "dpmp_http_request_duration_seconds";
        header(&mut out, name, "histogram", "Request latency by route.");
        for (route, h) in &inner.latency {
            h.write(&mut out, name, &format!("route=\"{}\"", escape(route)));
        }
        let name = "dpmp_solver_iterations";
        header(&mut out, name, "histogram", "SCP iterations per solve.");
        inner.iterations.write(&mut out, name, "");
        let name = "dpmp_solver_status_total";
        header(&mut out, name, "counter", "Solves by returned status.");
        for (status, n) in &inner.statuses {
            let _ = writeln!(out, "{name}{{status=\"{}\"}} {n}", escape(status));
        }
        gauge(
            &mut out,
            "dpmp_solver_jobs_waiting",
            "Jobs waiting for a solver slot.",
            load.waiting,
        );
        gauge(
            &mut out,
            "dpmp_solver_jobs_running",
            "Jobs running on the blocking pool.",
            load.running,
        );
        out
    }
}

fn header(out: &mut String, name: &str, kind: &str, help: &str) {
    let _ = writeln!(out, "# HELP {name} {help}");
    let _ = writeln!(out, "# TYPE {name} {kind}");
}

fn gauge(out: &mut String, name: &str, help: &str, value: usize) {
    header(out, name, "gauge", help);
    let _ = writeln!(out, "{name} {value}");
}

/// Escape a label value (backslash, quote, newline).
fn escape(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

/// Middleware: count every request by its route template (never the raw
/// path, so label cardinality stays bounded; unknown routes count as
/// `unmatched`).
pub async fn track(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| "unmatched".to_string());
    let method = request.method().as_str().to_string();
    let response = next.run(request).await;
    let status = response.status().as_u16();
    let seconds = started.elapsed().as_secs_f64();
    state
        .metrics()
        .record_request(&route, &method, status, seconds);
    tracing::info!(route = %route, method = %method, status, ms = seconds * 1e3, "request");
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exposition_has_counts_buckets_and_gauges() {
        let m = Metrics::default();
        m.record_request("/v1/optimize", "POST", 200, 0.004);
        m.record_request("/v1/optimize", "POST", 200, 0.03);
        m.record_request("/v1/optimize", "POST", 422, 0.0005);
        m.record_solve("optimal", 3);
        let text = m.render(LimiterLoad {
            waiting: 1,
            running: 2,
        });
        assert!(text.contains(
            "dpmp_http_requests_total{route=\"/v1/optimize\",method=\"POST\",status=\"200\"} 2"
        ));
        assert!(text.contains(
            "dpmp_http_request_duration_seconds_bucket{route=\"/v1/optimize\",le=\"0.005\"} 2"
        ));
        assert!(text.contains(
            "dpmp_http_request_duration_seconds_bucket{route=\"/v1/optimize\",le=\"+Inf\"} 3"
        ));
        assert!(text.contains("dpmp_solver_iterations_bucket{le=\"2\"} 0"));
        assert!(text.contains("dpmp_solver_iterations_bucket{le=\"3\"} 1"));
        assert!(text.contains("dpmp_solver_iterations_count 1"));
        assert!(text.contains("dpmp_solver_status_total{status=\"optimal\"} 1"));
        assert!(text.contains("dpmp_solver_jobs_running 2"));
        // Every sample line is `name{labels} value` with a numeric value.
        for line in text.lines().filter(|l| !l.starts_with('#')) {
            let value = line.rsplit(' ').next().unwrap();
            assert!(value.parse::<f64>().is_ok(), "{line}");
        }
    }

    #[test]
    fn label_values_are_escaped() {
        assert_eq!(escape("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
    }
}
