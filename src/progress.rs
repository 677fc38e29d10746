//! Progress bars on stderr for long library work (dataset generation and
//! import, CLI loops); hidden when not asked for, and drawn by indicatif
//! only on a terminal.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps counting `what` (e.g. `targets`), or a hidden one
/// when `show` is false.
pub fn bar(show: bool, len: u64, what: &str) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    let template = format!("{{bar:40}} {{pos}}/{{len}} {what}  {{per_sec}}  eta {{eta}}");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar
}
