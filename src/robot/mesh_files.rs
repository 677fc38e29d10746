//! Where the mesh files a URDF names are read from.
//!
//! A URDF `<mesh filename=…>` is one of:
//! - a relative path, resolved against the URDF file's folder;
//! - `file:///abs/path` or an absolute path;
//! - `package://PKG/rest`, resolved (first hit wins) against: each folder of
//!   `DPMP_PACKAGE_PATH` and `ROS_PACKAGE_PATH` (`dir/PKG/rest`, or
//!   `dir/rest` when `dir` itself is named `PKG`); the URDF's folder and its
//!   ancestors (the one named `PKG`, or one holding `PKG/rest`); and finally
//!   the URDF's parent folder and the URDF's folder (`rest` below them), the
//!   layout of a ROS package with `urdf/` beside `meshes/`.
//!
//! The shipped Panda is embedded in the binary, meshes included, so that an
//! installed `dpmp` needs no files: [`MeshFiles::Embedded`].

use std::path::{Path, PathBuf};

/// A source of mesh files for one URDF.
#[derive(Clone, Debug)]
pub enum MeshFiles {
    /// URDF text with no file behind it: a mesh is an error.
    None,
    /// The folder of the URDF file.
    Folder(PathBuf),
    /// Files embedded in the binary, by the exact name the URDF uses.
    Embedded(&'static [(&'static str, &'static [u8])]),
}

impl MeshFiles {
    /// Read the mesh `filename`: its resolved location (for messages) and
    /// bytes, or a message saying what was tried.
    pub fn read(&self, filename: &str) -> Result<(String, Vec<u8>), String> {
        match self {
            MeshFiles::None => Err(format!(
                "mesh '{filename}' cannot be resolved: the URDF was given as text, not as a file \
                 (load it with a path so relative and package:// names resolve)"
            )),
            MeshFiles::Embedded(files) => files
                .iter()
                .find(|(name, _)| *name == filename)
                .map(|(name, bytes)| (format!("embedded:{name}"), bytes.to_vec()))
                .ok_or_else(|| format!("mesh '{filename}' is not among the embedded meshes")),
            MeshFiles::Folder(dir) => {
                let candidates = candidates(dir, filename);
                let found = candidates.iter().find(|p| p.is_file()).ok_or_else(|| {
                    let tried: Vec<String> =
                        candidates.iter().map(|p| p.display().to_string()).collect();
                    format!(
                        "mesh file '{filename}' not found (tried {})",
                        tried.join(", ")
                    )
                })?;
                let bytes = std::fs::read(found)
                    .map_err(|e| format!("mesh file {}: {e}", found.display()))?;
                Ok((found.display().to_string(), bytes))
            }
        }
    }
}

/// Every location `filename` may name, in the order they are tried.
fn candidates(dir: &Path, filename: &str) -> Vec<PathBuf> {
    if let Some(path) = filename.strip_prefix("file://") {
        return vec![PathBuf::from(path)];
    }
    let Some(rest) = filename.strip_prefix("package://") else {
        return vec![dir.join(filename)];
    };
    let (package, inner) = rest.split_once('/').unwrap_or((rest, ""));
    let mut out = Vec::new();
    for var in ["DPMP_PACKAGE_PATH", "ROS_PACKAGE_PATH"] {
        if let Some(paths) = std::env::var_os(var) {
            for root in std::env::split_paths(&paths) {
                out.push(root.join(package).join(inner));
                if root.file_name().is_some_and(|n| n == package) {
                    out.push(root.join(inner));
                }
            }
        }
    }
    for ancestor in dir.ancestors() {
        if ancestor.file_name().is_some_and(|n| n == package) {
            out.push(ancestor.join(inner));
        }
        out.push(ancestor.join(package).join(inner));
    }
    if let Some(parent) = dir.parent() {
        out.push(parent.join(inner));
    }
    out.push(dir.join(inner));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn package_names_resolve_against_a_ros_package_layout() {
        let root = tempfile::tempdir().unwrap();
        let pkg = root.path().join("franka_description");
        std::fs::create_dir_all(pkg.join("urdf")).unwrap();
        std::fs::create_dir_all(pkg.join("meshes/collision")).unwrap();
        std::fs::write(pkg.join("meshes/collision/l.stl"), b"abc").unwrap();
        let files = MeshFiles::Folder(pkg.join("urdf"));
        let (path, bytes) = files
            .read("package://franka_description/meshes/collision/l.stl")
            .unwrap();
        assert_eq!(bytes, b"abc");
        assert!(path.ends_with("meshes/collision/l.stl"), "{path}");
        let (_, bytes) = files.read("../meshes/collision/l.stl").unwrap();
        assert_eq!(bytes, b"abc");
        let e = files
            .read("package://franka_description/meshes/none.stl")
            .unwrap_err();
        assert!(e.contains("not found") && e.contains("none.stl"), "{e}");
        let e = MeshFiles::None.read("x.stl").unwrap_err();
        assert!(e.contains("as text"), "{e}");
    }
}
