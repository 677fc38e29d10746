//! Triangle meshes of link collision geometry: reading binary STL, ASCII STL
//! and Wavefront OBJ, scaling, and validation.
//!
//! A [`TriangleMesh`] is the robot's collision truth: the fast geometry the
//! optimiser uses ([`super::hull`]) is derived from it and must contain it.
//! Parsing never panics; every failure is a message that the caller wraps
//! with the file and the URDF element.

use std::collections::HashMap;

/// A triangle soup in metres (after the URDF `scale`).
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleMesh {
    /// Triangles as three vertices each.
    pub triangles: Vec<[[f64; 3]; 3]>,
}

/// The mesh file formats dpmp reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Binary or ASCII STL (told apart by content).
    Stl,
    /// Wavefront OBJ (`v` and `f` records; polygons are fanned).
    Obj,
}

impl MeshFormat {
    /// The format of a file name by its extension (case-insensitive).
    pub fn from_file_name(name: &str) -> Result<MeshFormat, String> {
        let ext = name.rsplit('.').next().unwrap_or("").to_ascii_lowercase();
        match ext.as_str() {
            "stl" => Ok(MeshFormat::Stl),
            "obj" => Ok(MeshFormat::Obj),
            _ => Err(format!(
                "unsupported mesh format '.{ext}' (dpmp reads .stl and .obj)"
            )),
        }
    }
}

impl TriangleMesh {
    /// Parse `bytes` in `format`, multiply every coordinate by `scale`, and
    /// validate: at least one triangle, every coordinate finite.
    pub fn parse(
        bytes: &[u8],
        format: MeshFormat,
        scale: [f64; 3],
    ) -> Result<TriangleMesh, String> {
        if !scale.iter().all(|s| s.is_finite() && *s != 0.0) {
            return Err(format!(
                "scale {scale:?} must be three finite, non-zero numbers"
            ));
        }
        let triangles = match format {
            MeshFormat::Stl if is_ascii_stl(bytes) => parse_ascii_stl(bytes)?,
            MeshFormat::Stl => parse_binary_stl(bytes)?,
            MeshFormat::Obj => parse_obj(bytes)?,
        };
        if triangles.is_empty() {
            return Err("the mesh has no triangles".into());
        }
        if let Some(t) = triangles
            .iter()
            .position(|tri| !tri.iter().flatten().all(|c| c.is_finite()))
        {
            return Err(format!("triangle {t} has a non-finite coordinate"));
        }
        let triangles = triangles
            .into_iter()
            .map(|tri| tri.map(|v| [0, 1, 2].map(|i| v[i] * scale[i])))
            .collect();
        Ok(TriangleMesh { triangles })
    }

    /// The distinct vertices (exact duplicates merged), in first-seen order.
    pub fn vertices(&self) -> Vec<[f64; 3]> {
        let mut seen = HashMap::new();
        let mut out = Vec::new();
        for v in self.triangles.iter().flatten() {
            let key = v.map(f64::to_bits);
            if seen.insert(key, ()).is_none() {
                out.push(*v);
            }
        }
        out
    }

    /// Number of edges used by other than exactly two triangles (0 for a
    /// closed, manifold surface). Vertices are matched exactly.
    pub fn open_edges(&self) -> usize {
        let mut count: HashMap<([u64; 3], [u64; 3]), usize> = HashMap::new();
        for tri in &self.triangles {
            for k in 0..3 {
                let (a, b) = (tri[k].map(f64::to_bits), tri[(k + 1) % 3].map(f64::to_bits));
                let key = if a <= b { (a, b) } else { (b, a) };
                *count.entry(key).or_default() += 1;
            }
        }
        count.values().filter(|&&c| c != 2).count()
    }

    /// The same mesh with every vertex mapped by `f` (e.g. into a link frame).
    pub fn mapped(&self, f: impl Fn(&[f64; 3]) -> [f64; 3]) -> TriangleMesh {
        TriangleMesh {
            triangles: self.triangles.iter().map(|t| t.map(|v| f(&v))).collect(),
        }
    }

    /// Points on the surface spaced at most `spacing` apart along each
    /// triangle's edges (a barycentric grid per triangle, vertices included).
    pub fn surface_samples(&self, spacing: f64) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for [a, b, c] in &self.triangles {
            let longest = [dist(a, b), dist(b, c), dist(c, a)]
                .into_iter()
                .fold(0.0, f64::max);
            let m = ((longest / spacing).ceil() as usize).max(1);
            for i in 0..=m {
                for j in 0..=(m - i) {
                    let (wi, wj) = (i as f64 / m as f64, j as f64 / m as f64);
                    let wk = 1.0 - wi - wj;
                    out.push([0, 1, 2].map(|t| wi * a[t] + wj * b[t] + wk * c[t]));
                }
            }
        }
        out
    }
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// ASCII STL starts with `solid` and contains `facet`; a binary file may
/// start with `solid` in its header too, so both words are required and the
/// binary size rule is checked first.
fn is_ascii_stl(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(512)];
    let starts_solid = head
        .iter()
        .skip_while(|b| b.is_ascii_whitespace())
        .take(5)
        .eq(b"solid".iter());
    starts_solid && !binary_size_matches(bytes) && find_word(bytes, b"facet")
}

fn binary_size_matches(bytes: &[u8]) -> bool {
    bytes.len() >= 84 && {
        let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        count
            .checked_mul(50)
            .and_then(|n| n.checked_add(84))
            .is_some_and(|n| n == bytes.len())
    }
}

fn find_word(bytes: &[u8], word: &[u8]) -> bool {
    bytes.windows(word.len()).any(|w| w == word)
}

/// Parse binary STL bytes: 80-byte header, `u32` triangle count, then 50
/// bytes per triangle (normal, three vertices as little-endian `f32`,
/// attribute count). The size must match the count.
pub fn parse_binary_stl(bytes: &[u8]) -> Result<Vec<[[f64; 3]; 3]>, String> {
    if bytes.len() < 84 {
        return Err(format!(
            "too short for a binary STL ({} bytes) and not ASCII STL",
            bytes.len()
        ));
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    if !binary_size_matches(bytes) {
        return Err(format!(
            "binary STL with {count} triangles must be {} bytes, got {}",
            84u128 + 50 * count as u128,
            bytes.len()
        ));
    }
    Ok((0..count)
        .map(|t| {
            let base = 84 + 50 * t + 12;
            let coord = |k: usize| {
                let b = &bytes[base + 4 * k..base + 4 * k + 4];
                f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64
            };
            [0, 1, 2].map(|v| [coord(3 * v), coord(3 * v + 1), coord(3 * v + 2)])
        })
        .collect())
}

/// Parse ASCII STL: every `vertex x y z` line, three per `facet`.
pub fn parse_ascii_stl(bytes: &[u8]) -> Result<Vec<[[f64; 3]; 3]>, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "ASCII STL is not valid UTF-8")?;
    let mut vertices = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if words.next() == Some("vertex") {
            vertices.push(parse_xyz(words, n + 1)?);
        }
    }
    if vertices.len() % 3 != 0 {
        return Err(format!(
            "ASCII STL has {} vertices, not a multiple of 3",
            vertices.len()
        ));
    }
    Ok(vertices.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Parse Wavefront OBJ: `v x y z` vertices and `f` faces (`i`, `i/t`,
/// `i//n`, `i/t/n`, negative indices relative to the end); polygons with
/// more than three corners are fanned from their first corner.
pub fn parse_obj(bytes: &[u8]) -> Result<Vec<[[f64; 3]; 3]>, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "OBJ is not valid UTF-8")?;
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut triangles = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => vertices.push(parse_xyz(words, n + 1)?),
            Some("f") => {
                let corners = words
                    .map(|w| obj_index(w, vertices.len(), n + 1))
                    .collect::<Result<Vec<usize>, String>>()?;
                if corners.len() < 3 {
                    return Err(format!("line {}: a face needs at least 3 corners", n + 1));
                }
                for k in 1..corners.len() - 1 {
                    triangles.push([
                        vertices[corners[0]],
                        vertices[corners[k]],
                        vertices[corners[k + 1]],
                    ]);
                }
            }
            _ => {}
        }
    }
    Ok(triangles)
}

fn obj_index(word: &str, n_vertices: usize, line: usize) -> Result<usize, String> {
    let first = word.split('/').next().unwrap_or("");
    let i: i64 = first
        .parse()
        .map_err(|_| format!("line {line}: bad face index '{word}'"))?;
    let index = if i > 0 { i - 1 } else { n_vertices as i64 + i };
    if i == 0 || index < 0 || index >= n_vertices as i64 {
        return Err(format!(
            "line {line}: face index {i} is outside the {n_vertices} vertices read so far"
        ));
    }
    Ok(index as usize)
}

fn parse_xyz<'a>(
    mut words: impl Iterator<Item = &'a str>,
    line: usize,
) -> Result<[f64; 3], String> {
    let mut xyz = [0.0; 3];
    for c in &mut xyz {
        let w = words
            .next()
            .ok_or_else(|| format!("line {line}: expected three coordinates"))?;
        *c = w
            .parse()
            .map_err(|_| format!("line {line}: '{w}' is not a number"))?;
    }
    Ok(xyz)
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: [f64; 3] = [1.0, 1.0, 1.0];

    fn one_triangle_binary() -> Vec<u8> {
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

    const TETRA_OBJ: &str = "# tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n\
                             f 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n";

    #[test]
    fn binary_stl_parses_and_rejects_bad_sizes_and_nan() {
        let m = TriangleMesh::parse(&one_triangle_binary(), MeshFormat::Stl, UNIT).unwrap();
        assert_eq!(
            m.triangles,
            vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]]
        );
        let mut short = one_triangle_binary();
        short.pop();
        let e = TriangleMesh::parse(&short, MeshFormat::Stl, UNIT).unwrap_err();
        assert!(e.contains("must be 134 bytes"), "{e}");
        assert!(TriangleMesh::parse(&[0u8; 10], MeshFormat::Stl, UNIT).is_err());
        let mut nan = one_triangle_binary();
        nan[96..100].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = TriangleMesh::parse(&nan, MeshFormat::Stl, UNIT).unwrap_err();
        assert!(e.contains("non-finite"), "{e}");
        let mut empty = vec![0u8; 80];
        empty.extend(0u32.to_le_bytes());
        let e = TriangleMesh::parse(&empty, MeshFormat::Stl, UNIT).unwrap_err();
        assert!(e.contains("no triangles"), "{e}");
    }

    #[test]
    fn ascii_stl_and_binary_stl_read_the_same_triangle() {
        let ascii = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 1 0 0\n   \
                     vertex 0 1 0\n   vertex 0 0 1\n  endloop\n endfacet\nendsolid t\n";
        let a = TriangleMesh::parse(ascii.as_bytes(), MeshFormat::Stl, UNIT).unwrap();
        let b = TriangleMesh::parse(&one_triangle_binary(), MeshFormat::Stl, UNIT).unwrap();
        assert_eq!(a, b);
        let bad = ascii.replace("vertex 0 1 0", "vertex 0 x 0");
        let e = TriangleMesh::parse(bad.as_bytes(), MeshFormat::Stl, UNIT).unwrap_err();
        assert!(e.contains("line 5") && e.contains("'x'"), "{e}");
    }

    #[test]
    fn obj_faces_are_fanned_and_scaled_and_closedness_is_counted() {
        let m =
            TriangleMesh::parse(TETRA_OBJ.as_bytes(), MeshFormat::Obj, [2.0, 1.0, 0.5]).unwrap();
        assert_eq!(m.triangles.len(), 4);
        assert_eq!(m.vertices().len(), 4);
        assert_eq!(m.open_edges(), 0);
        assert!(m.vertices().contains(&[2.0, 0.0, 0.0]));
        assert!(m.vertices().contains(&[0.0, 0.0, 0.5]));
        let quad = TriangleMesh::parse(
            b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/2 3/3/3 -1//4\n",
            MeshFormat::Obj,
            UNIT,
        )
        .unwrap();
        assert_eq!(quad.triangles.len(), 2);
        assert_eq!(quad.open_edges(), 4);
        let e = TriangleMesh::parse(b"v 0 0 0\nf 1 2 3\n", MeshFormat::Obj, UNIT).unwrap_err();
        assert!(e.contains("line 2") && e.contains("index 2"), "{e}");
        let e = TriangleMesh::parse(TETRA_OBJ.as_bytes(), MeshFormat::Obj, [1.0, 0.0, 1.0])
            .unwrap_err();
        assert!(e.contains("scale"), "{e}");
    }

    #[test]
    fn surface_samples_respect_the_spacing() {
        let m = TriangleMesh::parse(TETRA_OBJ.as_bytes(), MeshFormat::Obj, UNIT).unwrap();
        let s = m.surface_samples(0.1);
        // Longest edge sqrt(2) -> 15 steps per triangle: 136 points each.
        assert_eq!(s.len(), 4 * 136);
        assert!(MeshFormat::from_file_name("a.DAE").is_err());
        assert_eq!(MeshFormat::from_file_name("x/y.OBJ"), Ok(MeshFormat::Obj));
    }
}
