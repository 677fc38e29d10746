//! Progress on stderr for long library work (dataset generation and import,
//! the robot's geometry check, CLI loops); nothing when not asked for.
//!
//! On a terminal it is an indicatif bar. Elsewhere (a log file, CI, a
//! pipe) indicatif draws nothing, so [`Progress`] writes a plain line at
//! every tenth of the work instead: `data: 30/300 targets (10%), 1.2 s`.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Progress over `len` steps of something; cheap to share between threads
/// (`inc` takes `&self`).
#[derive(Debug)]
pub struct Progress {
    bar: ProgressBar,
    lines: Option<Lines>,
}

/// The plain-line form's state.
#[derive(Debug)]
struct Lines {
    what: String,
    len: u64,
    done: AtomicU64,
    started: Instant,
}

impl Progress {
    /// Steps done; a plain line each time a tenth is passed.
    pub fn inc(&self, steps: u64) {
        self.bar.inc(steps);
        if let Some(lines) = &self.lines {
            let before = lines.done.fetch_add(steps, Ordering::Relaxed);
            let after = before + steps;
            let tenth = |n: u64| (n * 10) / lines.len.max(1);
            if tenth(after) > tenth(before) {
                eprintln!(
                    "{after}/{} {} ({}%), {:.1} s",
                    lines.len,
                    lines.what,
                    (after * 100) / lines.len.max(1),
                    lines.started.elapsed().as_secs_f64()
                );
            }
        }
    }

    /// Remove the bar (the lines stay: they are a log).
    pub fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
    }
}

/// Progress over `len` steps counting `what` (e.g. `targets`), or none
/// when `show` is false (see the module docs for its two forms).
pub fn bar(show: bool, len: u64, what: &str) -> Progress {
    if !show {
        return Progress {
            bar: ProgressBar::hidden(),
            lines: None,
        };
    }
    if !std::io::stderr().is_terminal() {
        return Progress {
            bar: ProgressBar::hidden(),
            lines: Some(Lines {
                what: what.to_string(),
                len,
                done: AtomicU64::new(0),
                started: Instant::now(),
            }),
        };
    }
    let bar = ProgressBar::new(len);
    let template = format!("{{bar:40}} {{pos}}/{{len}} {what}  {{per_sec}}  eta {{eta}}");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    Progress { bar, lines: None }
}
