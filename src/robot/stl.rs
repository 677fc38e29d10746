//! A tiny binary-STL reader (the format of Franka's collision meshes).

use crate::{Error, Result};
use std::path::Path;

/// Triangles of a binary STL file, as `[vertex; 3]` in metres (file units).
pub fn read_binary_stl(path: &Path) -> Result<Vec<[[f64; 3]; 3]>> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
    parse_binary_stl(&bytes).map_err(|message| Error::file(path, message))
}

/// Parse binary STL bytes: 80-byte header, `u32` triangle count, then 50
/// bytes per triangle (normal, three vertices as little-endian `f32`,
/// attribute count). The size must match the count and every coordinate be
/// finite.
pub fn parse_binary_stl(bytes: &[u8]) -> std::result::Result<Vec<[[f64; 3]; 3]>, String> {
    let count_bytes = bytes
        .get(80..84)
        .ok_or_else(|| format!("too short for a binary STL ({} bytes)", bytes.len()))?;
    let count = u32::from_le_bytes([
        count_bytes[0],
        count_bytes[1],
        count_bytes[2],
        count_bytes[3],
    ]) as usize;
    let expected = 84 + 50 * count;
    if bytes.len() != expected {
        return Err(format!(
            "binary STL with {count} triangles must be {expected} bytes, got {}",
            bytes.len()
        ));
    }
    (0..count)
        .map(|t| {
            let base = 84 + 50 * t + 12;
            let coord = |k: usize| {
                let b = &bytes[base + 4 * k..base + 4 * k + 4];
                f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64
            };
            let tri = [0, 1, 2].map(|v| [coord(3 * v), coord(3 * v + 1), coord(3 * v + 2)]);
            if tri.iter().flatten().all(|c| c.is_finite()) {
                Ok(tri)
            } else {
                Err(format!("triangle {t} has a non-finite coordinate"))
            }
        })
        .collect()
}

/// The distinct vertices of `triangles`.
pub fn unique_vertices(triangles: &[[[f64; 3]; 3]]) -> Vec<[f64; 3]> {
    super::fit::surface_samples(triangles, 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_triangle() -> Vec<u8> {
        let mut bytes = vec![0u8; 80];
        bytes.extend(1u32.to_le_bytes());
        for v in [
            0.0f32, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0,
        ] {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend([0u8, 0]);
        bytes
    }

    #[test]
    fn parses_a_triangle_and_rejects_bad_sizes() {
        let tris = parse_binary_stl(&one_triangle()).unwrap();
        assert_eq!(
            tris,
            vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]]
        );
        assert_eq!(unique_vertices(&tris).len(), 3);
        let mut short = one_triangle();
        short.pop();
        assert!(parse_binary_stl(&short)
            .unwrap_err()
            .contains("must be 134 bytes"));
        assert!(parse_binary_stl(&[0u8; 10]).is_err());
        let mut nan = one_triangle();
        nan[96..100].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(parse_binary_stl(&nan).unwrap_err().contains("non-finite"));
    }
}
