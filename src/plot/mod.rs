//! Shared plotting helpers (plotters): per-joint trajectory panels with
//! uncertainty bands (the paper's figures), used by `dpmp prior plot`,
//! `dpmp optimize --plot`, `dpmp plan --plot` and the reports; and
//! [`scene`], the sensed depth cloud over the scene's obstacles in a top and
//! a side view (`dpmp data preview`, `dpmp plan --world depth --plot`).
//!
//! Text is drawn with an embedded DejaVu Sans (see `DejaVuSans.LICENSE`), so
//! plots need no system fonts. Output format follows the file extension
//! (`.png` or `.svg`); files are written to a temporary name and renamed.

pub mod answer;
mod joints;
pub mod scene;

pub use answer::{prior_and_answer, PriorBand};
pub use joints::{joint_panels, JointSeries};
pub use scene::{scene_picture, ScenePicture};

use crate::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::Once;

static FONT: Once = Once::new();

/// Register the embedded font as plotters' `sans-serif` (idempotent).
pub fn register_font() {
    FONT.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("DejaVuSans.ttf");
        // Registration only fails on a corrupt font, which is embedded and tested.
        let _ =
            plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, bytes);
    });
}

/// Image formats the plot helpers write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Raster PNG.
    Png,
    /// Vector SVG.
    Svg,
}

/// Format from a file extension; errors name `field`.
pub fn format_of(path: &Path, field: &str) -> Result<Format> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
    {
        Some(e) if e == "png" => Ok(Format::Png),
        Some(e) if e == "svg" => Ok(Format::Svg),
        _ => Err(Error::invalid(
            field,
            format!("{}: the file must end in .png or .svg", path.display()),
        )),
    }
}

/// Temporary sibling path with the same extension (plotters picks the
/// encoder from it).
fn temp_path(path: &Path) -> PathBuf {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("png");
    path.with_extension(format!("partial.{ext}"))
}

/// Draw a plot file whole or not at all: `draw` writes a temporary
/// sibling of `path` (same extension, so plotters picks the encoder), which
/// is renamed onto `path` when it succeeds and removed when anything fails.
pub(crate) fn write_via_temp(path: &Path, draw: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    check_folder(path)?;
    let tmp = temp_path(path);
    let result = draw(&tmp)
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| Error::write(path, e.to_string())));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The folder `path` goes in must exist (plotters' own error for a missing
/// one is its debug text).
fn check_folder(path: &Path) -> Result<()> {
    match path.parent() {
        Some(folder) if !folder.as_os_str().is_empty() && !folder.is_dir() => Err(Error::write(
            path,
            format!(
                "cannot write the plot: the folder {} does not exist",
                folder.display()
            ),
        )),
        _ => Ok(()),
    }
}

/// Map any plotters error to a file error for `path`.
pub(crate) fn plot_error<E: std::fmt::Display>(path: &Path) -> impl Fn(E) -> Error + '_ {
    move |e| Error::write(path, format!("cannot draw plot: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plot_into_a_missing_folder_says_so() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("plot.png");
        let e = write_via_temp(&path, |_| Ok(())).unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
        assert!(!e.to_string().contains("Os {"), "{e}");
    }
}
