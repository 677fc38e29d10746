//! Files written whole or not at all: every output file of dpmp (datasets,
//! checkpoints, annotations, problem files, reports) goes through
//! [`write_atomic`], so a crash or a full disk never leaves a partial file
//! under the final name. [`read_json`] is the matching reader.

use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Write `bytes` to `path` through a temporary file in the same directory
/// (created if missing) and a rename; on failure the temporary file is
/// removed and the error names `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e.to_string()))?;
    }
    let name = path
        .file_name()
        .ok_or_else(|| Error::file(path, "not a file path"))?
        .to_string_lossy();
    let tmp: PathBuf = path.with_file_name(format!(".{name}.tmp{}", std::process::id()));
    let result = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::write(path, format!("cannot write: {e}"))
    })
}

/// Read and parse a JSON file, naming the file (and serde's location) on
/// error; duplicate keys are refused ([`crate::strict_json`]).
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
    if let Some(d) = crate::strict_json::find_duplicate_key(text.as_bytes()) {
        return Err(Error::file(path, format!("{}: {d}", d.path)));
    }
    serde_json::from_str(&text).map_err(|e| Error::file(path, format!("malformed JSON: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_files_and_leaves_nothing_behind_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("a.json");
        write_atomic(&path, b"{}").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"{}");
        write_atomic(&path, b"[1]").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"[1]");
        // A directory in the way: the rename fails, no temp file remains.
        let blocked = dir.path().join("sub").join("d");
        std::fs::create_dir_all(blocked.join("x")).unwrap();
        let e = write_atomic(&blocked, b"x").unwrap_err();
        assert!(e.to_string().contains("cannot write"), "{e}");
        let names: Vec<_> = std::fs::read_dir(dir.path().join("sub"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains(".tmp")), "{names:?}");
    }
}
