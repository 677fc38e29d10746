//! Service metrics through `prometheus-client`, exposed in the Prometheus
//! text format (version 0.0.4): request counts by route, method and status;
//! request latency by route; solver iterations, solve time and returned
//! statuses; the limiter's queue; and the process (CPU, memory, open files,
//! threads; Linux only).
//!
//! [`Metrics`] owns one [`Registry`]; handlers record through typed methods
//! and `GET /metrics` calls [`Metrics::render`]. Labels are route
//! templates, never raw paths, so cardinality stays bounded.

use super::limits::LimiterLoad;
use crate::optim::seeds::restart::RESTART_MAX_ITERATIONS;
use crate::optim::task::{MAX_ITERATIONS, MAX_RESTARTS};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{
    prometheus_text, DescriptorEncoder, EncodeLabelSet, EncodeMetric,
};
use prometheus_client::metrics::counter::{ConstCounter, Counter};
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::{ConstGauge, Gauge};
use prometheus_client::metrics::histogram::{exponential_buckets, Histogram};
use prometheus_client::registry::Registry;
use std::time::{SystemTime, UNIX_EPOCH};

/// Upper bounds (s) of the request-latency buckets.
pub const LATENCY_BUCKETS_S: [f64; 14] = [
    0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0,
];

/// The most SCP iterations one solve can report: the run from the prior
/// mean at the largest accepted cap, then every restart at its own cap.
pub const MOST_ITERATIONS: usize = MAX_ITERATIONS + MAX_RESTARTS * RESTART_MAX_ITERATIONS;

/// Upper bounds of the solver-iteration buckets: 0, then powers of two up
/// to the first one at or above [`MOST_ITERATIONS`].
pub fn iteration_buckets() -> Vec<f64> {
    let doublings = (MOST_ITERATIONS as f64).log2().ceil() as u16 + 1;
    std::iter::once(0.0)
        .chain(exponential_buckets(1.0, 2.0, doublings))
        .collect()
}

/// Upper bounds (s) of the solve-time buckets: 1 ms doubling to about 65 s.
pub fn solve_time_buckets() -> Vec<f64> {
    exponential_buckets(0.001, 2.0, 17).collect()
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    route: String,
    method: String,
    status: u16,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RouteLabels {
    route: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StatusLabels {
    status: String,
}

type HistogramFamily<L> = Family<L, Histogram, fn() -> Histogram>;

fn latency_histogram() -> Histogram {
    Histogram::new(LATENCY_BUCKETS_S)
}

/// All metrics of the service. Shared through [`AppState`].
#[derive(Debug)]
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    latency: HistogramFamily<RouteLabels>,
    iterations: Histogram,
    solve_seconds: Histogram,
    statuses: Family<StatusLabels, Counter>,
    jobs_waiting: Gauge,
    jobs_running: Gauge,
}

impl Default for Metrics {
    fn default() -> Self {
        let requests = Family::<RequestLabels, Counter>::default();
        let latency: HistogramFamily<RouteLabels> = Family::new_with_constructor(latency_histogram);
        let iterations = Histogram::new(iteration_buckets());
        let solve_seconds = Histogram::new(solve_time_buckets());
        let statuses = Family::<StatusLabels, Counter>::default();
        let jobs_waiting = Gauge::default();
        let jobs_running = Gauge::default();
        let mut registry = Registry::default();
        registry.register(
            "dpmp_http_requests",
            "Answered HTTP requests",
            requests.clone(),
        );
        registry.register(
            "dpmp_http_request_duration_seconds",
            "Request latency by route",
            latency.clone(),
        );
        registry.register(
            "dpmp_solver_iterations",
            "SCP iterations per solve, restarts included",
            iterations.clone(),
        );
        registry.register(
            "dpmp_solver_duration_seconds",
            "Optimiser wall time per solve",
            solve_seconds.clone(),
        );
        registry.register(
            "dpmp_solver_status",
            "Solves by returned status",
            statuses.clone(),
        );
        registry.register(
            "dpmp_solver_jobs_waiting",
            "Jobs waiting for a solver slot",
            jobs_waiting.clone(),
        );
        registry.register(
            "dpmp_solver_jobs_running",
            "Jobs running on the blocking pool",
            jobs_running.clone(),
        );
        registry.register_collector(Box::new(ProcessCollector::started_now()));
        Metrics {
            registry,
            requests,
            latency,
            iterations,
            solve_seconds,
            statuses,
            jobs_waiting,
            jobs_running,
        }
    }
}

impl Metrics {
    /// Count one answered request.
    pub fn record_request(&self, route: &str, method: &str, status: u16, seconds: f64) {
        self.requests
            .get_or_create(&RequestLabels {
                route: route.to_string(),
                method: method.to_string(),
                status,
            })
            .inc();
        self.latency
            .get_or_create(&RouteLabels {
                route: route.to_string(),
            })
            .observe(seconds);
    }

    /// Count one finished solve: its status (`optimal`, ...), SCP
    /// iterations (restarts included) and wall time.
    pub fn record_solve(&self, status: &str, iterations: usize, seconds: f64) {
        self.statuses
            .get_or_create(&StatusLabels {
                status: status.to_string(),
            })
            .inc();
        self.iterations.observe(iterations as f64);
        self.solve_seconds.observe(seconds);
    }

    /// The exposition text, with the limiter's queue as of now.
    pub fn render(&self, load: LimiterLoad) -> String {
        self.jobs_waiting.set(gauge_value(load.waiting));
        self.jobs_running.set(gauge_value(load.running));
        let mut out = String::with_capacity(8192);
        // Writing into a String cannot fail; an encoder error would be a
        // bug in a collector, and the scrape then shows what came before.
        if let Err(e) = prometheus_text::encode(&mut out, &self.registry) {
            tracing::warn!(error = %e, "metrics encoding stopped early");
        }
        out
    }
}

fn gauge_value(n: usize) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}

/// The standard `process_*` metrics, read from `/proc/self` at each scrape
/// (nothing on systems without it).
#[derive(Debug)]
struct ProcessCollector {
    started_unix_s: f64,
}

impl ProcessCollector {
    fn started_now() -> Self {
        let started_unix_s = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        ProcessCollector { started_unix_s }
    }
}

/// What `/proc/self` says about this process.
#[derive(Debug, PartialEq)]
struct ProcessStat {
    cpu_seconds: f64,
    threads: i64,
    virtual_bytes: i64,
    resident_bytes: i64,
}

/// Clock ticks per second of `/proc/self/stat`'s CPU times (`USER_HZ`,
/// 100 on every Linux architecture the service builds for).
const USER_HZ: f64 = 100.0;
/// Bytes per page of `/proc/self/stat`'s resident set size.
const PAGE_BYTES: i64 = 4096;

/// Parse `/proc/self/stat` (fields after the parenthesised command name,
/// which may itself contain spaces and parentheses).
fn parse_stat(stat: &str) -> Option<ProcessStat> {
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // `rest` starts at field 3 (state): field n is fields[n - 3].
    let field = |n: usize| fields.get(n - 3).and_then(|v| v.parse::<i64>().ok());
    Some(ProcessStat {
        cpu_seconds: (field(14)? + field(15)?) as f64 / USER_HZ,
        threads: field(20)?,
        virtual_bytes: field(23)?,
        resident_bytes: field(24)? * PAGE_BYTES,
    })
}

fn open_fds() -> Option<i64> {
    let entries = std::fs::read_dir("/proc/self/fd").ok()?;
    i64::try_from(entries.count()).ok()
}

/// Encode one constant metric (gauge or counter) under `name`.
fn encode_const(
    encoder: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    metric: impl EncodeMetric,
) -> std::fmt::Result {
    let descriptor = encoder.encode_descriptor(name, help, None, metric.metric_type())?;
    metric.encode(descriptor)
}

impl Collector for ProcessCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> std::fmt::Result {
        encode_const(
            &mut encoder,
            "process_start_time_seconds",
            "Start time of the process since the Unix epoch, in seconds",
            ConstGauge::new(self.started_unix_s),
        )?;
        let Some(stat) = std::fs::read_to_string("/proc/self/stat")
            .ok()
            .as_deref()
            .and_then(parse_stat)
        else {
            return Ok(());
        };
        let gauges = [
            (
                "process_resident_memory_bytes",
                "Resident memory size in bytes",
                stat.resident_bytes,
            ),
            (
                "process_virtual_memory_bytes",
                "Virtual memory size in bytes",
                stat.virtual_bytes,
            ),
            ("process_threads", "Operating-system threads", stat.threads),
        ];
        encode_const(
            &mut encoder,
            "process_cpu_seconds",
            "User and system CPU time spent, in seconds",
            ConstCounter::new(stat.cpu_seconds),
        )?;
        for (name, help, value) in gauges {
            encode_const(&mut encoder, name, help, ConstGauge::new(value))?;
        }
        if let Some(fds) = open_fds() {
            encode_const(
                &mut encoder,
                "process_open_fds",
                "Open file descriptors",
                ConstGauge::new(fds),
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value of the sample line that starts with `prefix`.
    fn sample(text: &str, prefix: &str) -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("no line starting with {prefix:?} in\n{text}"));
        line.rsplit(' ').next().unwrap().parse().unwrap()
    }

    #[test]
    fn exposition_has_counts_buckets_gauges_and_process_metrics() {
        let m = Metrics::default();
        m.record_request("/v1/optimize", "POST", 200, 0.004);
        m.record_request("/v1/optimize", "POST", 200, 0.03);
        m.record_request("/v1/optimize", "POST", 422, 0.0005);
        m.record_solve("optimal", 3, 0.012);
        let text = m.render(LimiterLoad {
            waiting: 1,
            running: 2,
        });
        let latency = "dpmp_http_request_duration_seconds_bucket{route=\"/v1/optimize\"";
        let expected = [
            (
                "dpmp_http_requests_total{route=\"/v1/optimize\",method=\"POST\",status=\"200\"}"
                    .to_string(),
                2.0,
            ),
            (format!("{latency},le=\"0.005\"}}"), 2.0),
            (format!("{latency},le=\"+Inf\"}}"), 3.0),
            ("dpmp_solver_iterations_bucket{le=\"2\"}".into(), 0.0),
            ("dpmp_solver_iterations_bucket{le=\"4\"}".into(), 1.0),
            ("dpmp_solver_iterations_count".into(), 1.0),
            (
                "dpmp_solver_duration_seconds_bucket{le=\"0.008\"}".into(),
                0.0,
            ),
            (
                "dpmp_solver_duration_seconds_bucket{le=\"0.016\"}".into(),
                1.0,
            ),
            ("dpmp_solver_status_total{status=\"optimal\"}".into(), 1.0),
            ("dpmp_solver_jobs_waiting".into(), 1.0),
            ("dpmp_solver_jobs_running".into(), 2.0),
        ];
        for (line, value) in &expected {
            assert_eq!(sample(&text, line), *value, "{line}");
        }
        assert!((sample(&text, "dpmp_solver_duration_seconds_sum") - 0.012).abs() < 1e-12);
        assert!(sample(&text, "process_start_time_seconds") > 1.6e9);
        if std::path::Path::new("/proc/self/stat").exists() {
            assert!(sample(&text, "process_resident_memory_bytes") > 1e5);
            assert!(sample(&text, "process_cpu_seconds_total") >= 0.0);
            assert!(sample(&text, "process_threads") >= 1.0);
            assert!(sample(&text, "process_open_fds") >= 3.0);
        }
        // Every sample line is `name{labels} value` with a numeric value,
        // and every family has HELP and TYPE.
        for line in text.lines().filter(|l| !l.starts_with('#')) {
            let value = line.rsplit(' ').next().unwrap();
            assert!(value.parse::<f64>().is_ok(), "{line}");
        }
        assert!(text.contains("# TYPE dpmp_solver_iterations histogram"));
        assert!(text.contains("# TYPE process_cpu_seconds_total counter"));
    }

    #[test]
    fn iteration_buckets_cover_the_cap_and_every_restart() {
        let buckets = iteration_buckets();
        assert_eq!(buckets[0], 0.0);
        assert!(buckets.windows(2).all(|w| w[0] < w[1]));
        let top = *buckets.last().unwrap();
        assert!(top >= MOST_ITERATIONS as f64, "top bucket {top}");
        // The next-to-last bucket is below it: no bucket is wasted.
        assert!(buckets[buckets.len() - 2] < MOST_ITERATIONS as f64);
        // The default options (100 iterations, 4 restarts) land well inside.
        assert!(buckets
            .iter()
            .any(|&b| b >= (100 + 4 * RESTART_MAX_ITERATIONS) as f64 && b < top));
    }

    #[test]
    fn proc_stat_parses_with_spaces_and_parentheses_in_the_name() {
        let stat = "4242 (dpmp (serve) x) S 1 4242 4242 0 -1 4194560 1000 0 0 0 250 50 0 0 20 0 7 0 12345 123456789 2048 18446744073709551615";
        let p = parse_stat(stat).unwrap();
        assert_eq!(
            p,
            ProcessStat {
                cpu_seconds: 3.0,
                threads: 7,
                virtual_bytes: 123_456_789,
                resident_bytes: 2048 * PAGE_BYTES,
            }
        );
        assert_eq!(parse_stat("garbage"), None);
        assert_eq!(parse_stat("1 (x) S 1 2"), None);
    }
}
