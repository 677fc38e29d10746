//! `dpmp serve`: run the HTTP service (see [`crate::service`]).
//!
//! ```text
//! dpmp serve [--addr 127.0.0.1:8080] [--model DIR | --no-model] [--robot URDF --base LINK --tip LINK]
//!            [--token-file FILE] [--body-limit-mib 16] [--max-pixels N] [--max-obstacles N]
//!            [--max-samples N] [--deadline-ms 2000] [--concurrency N] [--queue N]
//!            [--header-timeout-ms 10000] [--body-timeout-ms 30000]
//!            [--max-connections 512] [--max-connections-per-ip 128]
//!            [--drain-timeout-ms 5000] [--max-decoded-mib 512]
//!            [--cors-origin URL]... [--log-json]
//! ```
//! The token may also come from `DPMP_API_TOKEN`; it is never logged.

use crate::net::Model;
use crate::service::token::{Token, TOKEN_ENV};
use crate::service::{AppState, ServiceConfig};
use crate::{Error, Result};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Arguments of `dpmp serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, default_value = crate::service::config::DEFAULT_ADDR)]
    pub addr: String,
    /// Trained network directory (model.safetensors + config.json; also
    /// from DPMP_MODEL_DIR); it must load. Without it: the shipped model,
    /// which the binary carries (found from any working folder).
    #[arg(long, env = MODEL_DIR_ENV, conflicts_with = "no_model")]
    pub model: Option<PathBuf>,
    /// Run without a network model: `/v1/plan` answers 503
    /// model_unavailable, `/v1/optimize` works.
    #[arg(long)]
    pub no_model: bool,
    /// The robot.
    #[command(flatten)]
    pub robot: super::RobotArgs,
    /// File holding the bearer token (overrides DPMP_API_TOKEN).
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Largest request body in MiB.
    #[arg(long, default_value_t = 16)]
    pub body_limit_mib: usize,
    /// Largest image in pixels (width x height), checked before decoding
    /// [default: 16777216 = 4096 x 4096].
    #[arg(long)]
    pub max_pixels: Option<u64>,
    /// Largest number of obstacles per request [default: 256].
    #[arg(long)]
    pub max_obstacles: Option<usize>,
    /// Largest number of extra samples per request [default: 32].
    #[arg(long)]
    pub max_samples: Option<usize>,
    /// Per-request deadline in milliseconds.
    #[arg(long, default_value_t = 2000)]
    pub deadline_ms: u64,
    /// Solves running at once [default: the CPU cores].
    #[arg(long)]
    pub concurrency: Option<usize>,
    /// Requests allowed to wait for a solver before 429 [default: 256].
    #[arg(long)]
    pub queue: Option<usize>,
    /// Time a client has to send a request's headers, also between
    /// requests on a kept-alive connection (ms).
    #[arg(long, default_value_t = 10_000)]
    pub header_timeout_ms: u64,
    /// Time a client has to send a request's body once the headers are in
    /// (ms); slower → 408.
    #[arg(long, default_value_t = 30_000)]
    pub body_timeout_ms: u64,
    /// Open connections at most (the oldest idle one gives way to a new
    /// one; all busy → 503).
    #[arg(long, default_value_t = 512)]
    pub max_connections: usize,
    /// Open connections from one IP address at most.
    #[arg(long, default_value_t = 128)]
    pub max_connections_per_ip: usize,
    /// How long a shutdown waits for requests in flight before it closes
    /// every connection (ms); a second SIGINT/SIGTERM exits at once.
    #[arg(long, default_value_t = 5_000)]
    pub drain_timeout_ms: u64,
    /// Decoded image bytes held at once across requests (MiB).
    #[arg(long, default_value_t = 512)]
    pub max_decoded_mib: u64,
    /// Allow CORS from this origin (repeatable; CORS is off without it).
    #[arg(long = "cors-origin")]
    pub cors_origins: Vec<String>,
    /// Log as JSON lines instead of text.
    #[arg(long)]
    pub log_json: bool,
    /// Print the typical /v1/optimize request for this seed (the load
    /// benchmark's body: real-like prior, 10 obstacles, 150 samples, 2 cm
    /// clearance) and exit without serving.
    #[arg(long, value_name = "SEED")]
    pub print_typical_request: Option<u64>,
}

/// The environment variable naming the model directory (for an installed
/// binary that runs outside the repository).
pub const MODEL_DIR_ENV: &str = "DPMP_MODEL_DIR";

/// Run `dpmp serve`.
pub fn run(args: ServeArgs) -> Result<()> {
    init_logging(args.log_json);
    let robot = args.robot.load()?;
    if let Some(seed) = args.print_typical_request {
        let settings = crate::fixtures::ExampleSettings::default();
        let request = crate::fixtures::typical_request(&robot, seed, &settings)?;
        return crate::cli::print_json(&request);
    }
    let config = config_from_args(&args)?;
    log_auth(&config);
    let model = load_model(args.model.as_deref(), args.no_model)?;
    let state = AppState::new(config, robot, model)?;
    crate::service::serve(state)
}

/// `--model DIR` must load; `--no-model` runs without one (said in the
/// log); otherwise the shipped model.
fn load_model(dir: Option<&Path>, no_model: bool) -> Result<Option<Model>> {
    if no_model {
        tracing::warn!(
            "running without a model (--no-model): /v1/plan answers 503 model_unavailable; /v1/optimize works"
        );
        return Ok(None);
    }
    let model = Model::load_or_shipped(dir)?;
    tracing::info!(
        model = model.name(),
        source = model.source(),
        "model loaded"
    );
    Ok(Some(model))
}

/// Build the [`ServiceConfig`] from the flags and the environment.
pub fn config_from_args(args: &ServeArgs) -> Result<ServiceConfig> {
    let defaults = ServiceConfig::default();
    let addr: SocketAddr = args.addr.parse().map_err(|e| {
        Error::invalid(
            "--addr",
            format!(
                "expected HOST:PORT like 127.0.0.1:8080, got {:?}: {e}",
                args.addr
            ),
        )
    })?;
    let body_limit_bytes = args
        .body_limit_mib
        .checked_mul(1 << 20)
        .filter(|b| *b > 0 && args.body_limit_mib <= 1024)
        .ok_or_else(|| Error::invalid("--body-limit-mib", "must be in 1..=1024"))?;
    for (flag, ms) in [
        ("--deadline-ms", args.deadline_ms),
        ("--header-timeout-ms", args.header_timeout_ms),
        ("--body-timeout-ms", args.body_timeout_ms),
        ("--drain-timeout-ms", args.drain_timeout_ms),
    ] {
        if ms == 0 || ms > 3_600_000 {
            return Err(Error::invalid(flag, "must be in 1..=3600000"));
        }
    }
    let max_decoded_bytes = args
        .max_decoded_mib
        .checked_mul(1 << 20)
        .filter(|_| (1..=1 << 20).contains(&args.max_decoded_mib))
        .ok_or_else(|| Error::invalid("--max-decoded-mib", "must be in 1..=1048576"))?;
    let config = ServiceConfig {
        addr,
        body_limit_bytes,
        max_image_pixels: args.max_pixels.unwrap_or(defaults.max_image_pixels),
        max_obstacles: args.max_obstacles.unwrap_or(defaults.max_obstacles),
        max_samples: args.max_samples.unwrap_or(defaults.max_samples),
        deadline: Duration::from_millis(args.deadline_ms),
        max_concurrency: args.concurrency.unwrap_or(defaults.max_concurrency),
        max_queue: args.queue.unwrap_or(defaults.max_queue),
        header_read_timeout: Duration::from_millis(args.header_timeout_ms),
        body_read_timeout: Duration::from_millis(args.body_timeout_ms),
        max_connections: args.max_connections,
        max_connections_per_ip: args.max_connections_per_ip,
        drain_timeout: Duration::from_millis(args.drain_timeout_ms),
        max_decoded_bytes,
        token: load_token(args.token_file.as_deref(), std::env::var_os(TOKEN_ENV))?,
        cors_origins: args.cors_origins.clone(),
        ..defaults
    };
    config.validate().map_err(crate::cli::as_flag_error)?;
    Ok(config)
}

/// The token from `--token-file`, else from `DPMP_API_TOKEN` (`env`, its
/// value if set), else none. A set but empty (or blank) variable is refused
/// like an empty file: it must not turn auth off without a word.
fn load_token(
    file: Option<&std::path::Path>,
    env: Option<std::ffi::OsString>,
) -> Result<Option<Token>> {
    if let Some(path) = file {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        return Token::new("--token-file", &text).map(Some);
    }
    let Some(value) = env else {
        return Ok(None);
    };
    let text = value.into_string().map_err(|_| {
        Error::invalid(
            TOKEN_ENV,
            "is not valid UTF-8: set a token of visible ASCII characters",
        )
    })?;
    if text.trim().is_empty() {
        return Err(Error::invalid(
            TOKEN_ENV,
            "is set but empty: set a token (1..=4096 visible ASCII characters), or unset the variable to serve without auth",
        ));
    }
    Token::new(TOKEN_ENV, &text).map(Some)
}

/// Say at start whether the protected routes need the token.
fn log_auth(config: &ServiceConfig) {
    if config.token.is_some() {
        tracing::info!("auth on: /v1/* and /metrics need the bearer token");
    } else {
        tracing::warn!(
            "auth off: every route answers without a token (set --token-file or DPMP_API_TOKEN)"
        );
    }
}

/// Structured logs to stderr; `RUST_LOG` filters (default `info`).
pub(crate) fn init_logging(json: bool) {
    init_logging_with(json, "info")
}

/// Logging to stderr with `default` as the filter unless `RUST_LOG` is set.
pub(crate) fn init_logging_with(json: bool, default: &str) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    // Colours only on a terminal: escape codes in a log file are noise.
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr);
    // A second initialisation (tests) is harmless and ignored.
    let _ = if json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Wrapper {
        #[command(flatten)]
        args: ServeArgs,
    }

    fn parse(flags: &[&str]) -> ServeArgs {
        let mut argv = vec!["serve"];
        argv.extend_from_slice(flags);
        Wrapper::try_parse_from(argv).unwrap().args
    }

    /// The defaults written in the help are the configuration's.
    #[test]
    fn the_help_states_the_configuration_defaults() {
        use clap::CommandFactory;
        let help = crate::cli::Cli::command()
            .find_subcommand_mut("serve")
            .unwrap()
            .render_long_help()
            .to_string();
        let d = ServiceConfig::default();
        for text in [
            format!("[default: {} = 4096 x 4096]", d.max_image_pixels),
            format!("per request [default: {}]", d.max_obstacles),
            format!("samples per request [default: {}]", d.max_samples),
            format!("before 429 [default: {}]", d.max_queue),
        ] {
            assert!(help.contains(&text), "{text} not in:\n{help}");
        }
    }

    #[test]
    fn flags_become_settings() {
        let c = config_from_args(&parse(&[
            "--addr",
            "127.0.0.1:0",
            "--body-limit-mib",
            "2",
            "--deadline-ms",
            "150",
            "--concurrency",
            "3",
            "--queue",
            "5",
        ]))
        .unwrap();
        assert_eq!(c.addr.port(), 0);
        assert_eq!(c.body_limit_bytes, 2 << 20);
        assert_eq!(c.deadline, Duration::from_millis(150));
        assert_eq!((c.max_concurrency, c.max_queue), (3, 5));
    }

    #[test]
    fn bad_flags_name_the_flag() {
        for (flags, field) in [
            (vec!["--addr", "nowhere"], "--addr"),
            (vec!["--body-limit-mib", "0"], "--body-limit-mib"),
            (vec!["--deadline-ms", "0"], "--deadline-ms"),
            (vec!["--concurrency", "0"], "--max-concurrency"),
            (vec!["--drain-timeout-ms", "0"], "--drain-timeout-ms"),
            (vec!["--max-decoded-mib", "0"], "--max-decoded-mib"),
            (vec!["--max-connections", "0"], "--max-connections"),
            (
                vec!["--max-connections", "4", "--max-connections-per-ip", "8"],
                "--max-connections-per-ip",
            ),
        ] {
            let e = config_from_args(&parse(&flags)).unwrap_err();
            assert_eq!(e.field(), Some(field), "{flags:?}");
        }
    }

    #[test]
    fn token_file_is_read_and_validated() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("token");
        std::fs::write(&path, "abc123\n").unwrap();
        let t = load_token(Some(&path), None).unwrap().unwrap();
        assert!(t.matches(b"abc123"));
        std::fs::write(&path, "\n").unwrap();
        assert_eq!(
            load_token(Some(&path), None).unwrap_err().field(),
            Some("--token-file")
        );
        let missing = dir.path().join("missing");
        assert!(matches!(
            load_token(Some(&missing), None).unwrap_err(),
            Error::File { .. }
        ));
    }

    #[test]
    fn an_empty_token_variable_is_refused_not_taken_as_no_auth() {
        assert!(load_token(None, None).unwrap().is_none());
        let t = load_token(None, Some("s3cret".into())).unwrap().unwrap();
        assert!(t.matches(b"s3cret"));
        for blank in ["", "  ", "\t\n"] {
            let e = load_token(None, Some(blank.into())).unwrap_err();
            assert_eq!(e.field(), Some(TOKEN_ENV), "{blank:?}");
            assert!(e.to_string().contains("set but empty"), "{e}");
        }
        // The file wins over the variable, empty or not.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("token");
        std::fs::write(&path, "abc").unwrap();
        assert!(load_token(Some(&path), Some("".into())).unwrap().is_some());
    }
}
