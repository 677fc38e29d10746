//! Which faces of a [`ConvexHull`](super::hull::ConvexHull) touch which: the
//! local structure the fast hull query ([`super::hull_query`]) walks instead
//! of scanning every face.
//!
//! - the faces around every vertex;
//! - the neighbours of every face (the faces sharing at least one vertex
//!   with it);
//! - the neighbours of every vertex (the vertices sharing an edge with it);
//! - a few *seed* faces spread over the directions (for each of the 26
//!   directions of a cube's faces, edges and corners, the face whose normal
//!   points most nearly along it), where a walk starts.
//!
//! All of it is combinatorial (face and vertex indices), so a rigidly moved
//! hull shares it unchanged.

use crate::geometry::convex_gap::Skeleton;
use nalgebra::Vector3;

/// Lists of indices stored one after another (compressed rows).
#[derive(Debug, Default)]
pub struct IndexLists {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl IndexLists {
    fn from_lists(lists: Vec<Vec<u32>>) -> IndexLists {
        let mut offsets = Vec::with_capacity(lists.len() + 1);
        let mut items = Vec::new();
        offsets.push(0);
        for list in lists {
            items.extend(list);
            offsets.push(items.len() as u32);
        }
        IndexLists { offsets, items }
    }

    /// List `i`.
    pub fn get(&self, i: usize) -> &[u32] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

/// The face adjacency of a hull (see the module docs).
#[derive(Debug, Default)]
pub struct HullTopology {
    /// Faces around every vertex.
    pub vertex_faces: IndexLists,
    /// Faces sharing a vertex with every face (itself excluded).
    pub face_neighbours: IndexLists,
    /// Vertices sharing an edge with every vertex: the hull's skeleton,
    /// which a linear function climbs to its maximum (the support map of
    /// [`crate::geometry::convex_gap`]).
    pub vertex_neighbours: IndexLists,
    /// Faces whose normals are closest to 26 directions spread over the
    /// sphere (duplicates removed).
    pub seeds: Vec<u32>,
    /// The seed face of each direction `(i, j, k) ∈ {-1, 0, 1}³`, at index
    /// `(i + 1) + 3 (j + 1) + 9 (k + 1)` (the centre holds the first seed).
    direction_seeds: [u32; 27],
    /// A vertex of each direction's seed face: where a climb of the
    /// skeleton towards that direction starts.
    direction_vertices: [u32; 27],
}

impl HullTopology {
    /// The topology of the triangles `faces` over `n_vertices` vertices,
    /// with the outward face normals `normals` (one per face).
    pub fn new(n_vertices: usize, faces: &[[u32; 3]], normals: &[Vector3<f64>]) -> HullTopology {
        let mut around = vec![Vec::new(); n_vertices];
        for (f, face) in faces.iter().enumerate() {
            for &v in face {
                around[v as usize].push(f as u32);
            }
        }
        let neighbours = faces
            .iter()
            .enumerate()
            .map(|(f, face)| {
                let mut list: Vec<u32> = face
                    .iter()
                    .flat_map(|&v| around[v as usize].iter().copied())
                    .filter(|&g| g as usize != f)
                    .collect();
                list.sort_unstable();
                list.dedup();
                list
            })
            .collect();
        let mut joined = vec![Vec::new(); n_vertices];
        for face in faces {
            for k in 0..3 {
                let (a, b) = (face[k], face[(k + 1) % 3]);
                joined[a as usize].push(b);
                joined[b as usize].push(a);
            }
        }
        for list in &mut joined {
            list.sort_unstable();
            list.dedup();
        }
        let direction_seeds = direction_seeds(normals);
        let direction_vertices =
            direction_seeds.map(|f| faces.get(f as usize).map_or(0, |face| face[0]));
        let mut seeds: Vec<u32> = Vec::new();
        for (i, &f) in direction_seeds.iter().enumerate() {
            if i != 13 && !normals.is_empty() && !seeds.contains(&f) {
                seeds.push(f);
            }
        }
        HullTopology {
            vertex_faces: IndexLists::from_lists(around),
            face_neighbours: IndexLists::from_lists(neighbours),
            vertex_neighbours: IndexLists::from_lists(joined),
            seeds,
            direction_seeds,
            direction_vertices,
        }
    }

    /// The seed face whose direction is nearest `u` (any length; each
    /// component rounds to -1, 0 or 1 relative to the largest).
    pub fn seed_towards(&self, u: &Vector3<f64>) -> u32 {
        self.direction_seeds[direction_index(u)]
    }
}

impl Skeleton for HullTopology {
    fn neighbours(&self, i: usize) -> &[u32] {
        self.vertex_neighbours.get(i)
    }

    fn start_towards(&self, dir: &Vector3<f64>) -> usize {
        self.direction_vertices[direction_index(dir)] as usize
    }
}

/// The index in `{-1, 0, 1}³` (see [`HullTopology::seed_towards`]) of the
/// direction nearest `u`: each component rounded to -1, 0 or 1 relative to
/// the largest (0, the first, for a zero or NaN `u`).
fn direction_index(u: &Vector3<f64>) -> usize {
    let m = u.amax();
    if m.is_nan() || m <= 0.0 {
        return 0;
    }
    let step = |c: f64| ((c / m).round() + 1.0) as usize;
    step(u.x) + 3 * step(u.y) + 9 * step(u.z)
}

/// For each direction `(i, j, k) ∈ {-1, 0, 1}³` (see
/// [`HullTopology::seed_towards`]), the face whose normal is most nearly
/// along it; the centre gets the seed of +x.
fn direction_seeds(normals: &[Vector3<f64>]) -> [u32; 27] {
    let along = |u: Vector3<f64>| {
        normals
            .iter()
            .enumerate()
            .max_by(|(_, a), (_, b)| a.dot(&u).total_cmp(&b.dot(&u)))
            .map_or(0, |(f, _)| f as u32)
    };
    std::array::from_fn(|i| {
        let c = |k: usize| k as f64 - 1.0;
        let u = Vector3::new(c(i % 3), c((i / 3) % 3), c(i / 9));
        along(if u == Vector3::zeros() {
            Vector3::x()
        } else {
            u
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tetrahedron: every face shares a vertex with the other three, and
    /// each seed is the face whose normal is nearest its direction.
    #[test]
    fn tetrahedron_faces_all_neighbour_each_other() {
        let v = [Vector3::zeros(), Vector3::x(), Vector3::y(), Vector3::z()];
        let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let normals: Vec<Vector3<f64>> = faces
            .iter()
            .map(|f: &[u32; 3]| {
                let [a, b, c] = f.map(|i| v[i as usize]);
                (b - a).cross(&(c - a)).normalize()
            })
            .collect();
        let t = HullTopology::new(4, &faces, &normals);
        for f in 0..4 {
            let n = t.face_neighbours.get(f);
            assert_eq!(n.len(), 3);
            assert!(!n.contains(&(f as u32)));
        }
        for v in 0..4 {
            assert_eq!(t.vertex_faces.get(v).len(), 3);
        }
        // -z, -y, -x and the slanted face (1, 1, 1).
        assert_eq!(t.seed_towards(&Vector3::new(0.3, 0.1, -2.0)), 0);
        assert_eq!(t.seed_towards(&Vector3::new(0.3, -2.0, 0.0)), 1);
        assert_eq!(t.seed_towards(&Vector3::new(-1.0, 0.2, 0.1)), 2);
        assert_eq!(t.seed_towards(&Vector3::new(1.0, 0.9, 1.1)), 3);
        // A climb towards a direction starts on that direction's seed face.
        for (dir, face) in [
            (-Vector3::z(), 0),
            (-Vector3::x(), 2),
            (Vector3::repeat(1.0), 3),
        ] {
            assert!(faces[face].contains(&(t.start_towards(&dir) as u32)));
        }
        let mut seeds = t.seeds.clone();
        seeds.sort_unstable();
        assert_eq!(seeds, vec![0, 1, 2, 3]);
    }
}
