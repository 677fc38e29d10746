//! A bounding-box tree over the parts of one obstacle with many of them (a
//! point cloud: one ball per point), so a query against a robot shape
//! visits only the parts whose boxes come within the query's distance —
//! the cost follows what is near the robot, not the size of the cloud.
//!
//! Built once when the scene compiles, in linear time after one sort: the
//! parts are ordered along a Morton (Z-order) curve through their box
//! centres, and each node's run of that order is split at the highest bit
//! in which its codes differ until a leaf holds at most [`LEAF_PARTS`] (the
//! curve keeps each half compact).
//! The order is a total one (ties by part index) and the visit order is
//! fixed by the build, so queries are deterministic.

use super::broadphase::Bounds;
use rayon::prelude::*;

/// Largest number of parts in a leaf.
pub const LEAF_PARTS: usize = 8;

/// Obstacles with more parts than this get a tree (below it a scan is as
/// fast).
pub const TREE_MIN_PARTS: usize = 16;

/// One node: its box and either its two children or its parts.
#[derive(Clone, Debug)]
struct Node {
    bounds: Bounds,
    /// Range into [`PartTree::order`] (a leaf's parts).
    start: usize,
    end: usize,
    /// Indices of the two children (`None`: a leaf).
    children: Option<(usize, usize)>,
}

/// A bounding-box tree over part boxes.
#[derive(Clone, Debug)]
pub struct PartTree {
    nodes: Vec<Node>,
    /// Part indices, each leaf's a contiguous run.
    order: Vec<usize>,
}

impl PartTree {
    /// The tree over `bounds` (one box per part); `None` when empty.
    pub fn new(bounds: &[Bounds]) -> Option<PartTree> {
        let all = bounds.iter().copied().reduce(|a, b| a.merged(&b))?;
        let extent = (all.max - all.min).map(|e| e.max(f64::MIN_POSITIVE));
        // One u64 per part: its Morton code above its index, so a plain
        // sort orders the parts along the curve, ties by index.
        let index_bits = usize::BITS - bounds.len().leading_zeros();
        let axis_bits = ((u64::BITS - index_bits) / 3).min(MORTON_AXIS_BITS);
        let cells = f64::from((1u32 << axis_bits) - 1);
        let mut keys: Vec<u64> = bounds
            .par_iter()
            .enumerate()
            .map(|(i, b)| {
                let centre = (b.min + b.max) * 0.5 - all.min;
                let cell = |k: usize| ((centre[k] / extent[k]) * cells) as u32;
                (morton(cell(0), cell(1), cell(2)) << index_bits) | i as u64
            })
            .collect();
        radix_sort(&mut keys, index_bits);
        let index_mask = (1u64 << index_bits) - 1;
        let mut tree = PartTree {
            nodes: Vec::with_capacity(2 * bounds.len() / LEAF_PARTS + 1),
            order: keys.iter().map(|&k| (k & index_mask) as usize).collect(),
        };
        tree.build(bounds, &keys, 0, bounds.len());
        Some(tree)
    }

    /// Build the node over the parts `order[start..end]` (their keys
    /// `codes`, sorted); returns its index. A node's box is its children's
    /// merged.
    fn build(&mut self, bounds: &[Bounds], codes: &[u64], start: usize, end: usize) -> usize {
        let index = self.nodes.len();
        self.nodes.push(Node {
            bounds: bounds[self.order[start]],
            start,
            end,
            children: None,
        });
        if end - start <= LEAF_PARTS {
            for &part in &self.order[start + 1..end] {
                self.nodes[index].bounds = self.nodes[index].bounds.merged(&bounds[part]);
            }
            return index;
        }
        let mid = split(codes, start, end);
        let left = self.build(bounds, codes, start, mid);
        let right = self.build(bounds, codes, mid, end);
        self.nodes[index].bounds = self.nodes[left].bounds.merged(&self.nodes[right].bounds);
        self.nodes[index].children = Some((left, right));
        index
    }

    /// Visit, in the tree's fixed order, every part whose box is closer to
    /// the query than the current limit (starting at `limit`; boxes the
    /// query overlaps are always visited). `gap` is a lower bound on the
    /// distance from the query to anything in a box (for a query box,
    /// [`Bounds::gap`]); `visit` gets the part index and returns the limit
    /// for the rest (a branch-and-bound search lowers it as it finds closer
    /// parts).
    pub fn visit(
        &self,
        gap: impl Fn(&Bounds) -> f64,
        mut limit: f64,
        mut visit: impl FnMut(usize) -> f64,
    ) {
        let mut stack = vec![(0usize, gap(&self.nodes[0].bounds))];
        while let Some((n, node_gap)) = stack.pop() {
            if node_gap >= limit && node_gap > 0.0 {
                continue;
            }
            let node = &self.nodes[n];
            match node.children {
                Some((left, right)) => {
                    // The nearer child first, so the limit falls sooner.
                    let l = (left, gap(&self.nodes[left].bounds));
                    let r = (right, gap(&self.nodes[right].bounds));
                    if l.1 <= r.1 {
                        stack.extend([r, l]);
                    } else {
                        stack.extend([l, r]);
                    }
                }
                None => {
                    for &part in &self.order[node.start..node.end] {
                        limit = visit(part);
                    }
                }
            }
        }
    }
}

/// Where the run `codes[start..end]` (sorted, distinct, at least two)
/// splits: at the first code with the highest bit in which the run's codes
/// differ set — the cut of the octree cell they share, along its longest
/// axis in the curve's order — so both halves are compact. Parts in one
/// cell differ only in their index bits, which split the run by index.
fn split(codes: &[u64], start: usize, end: usize) -> usize {
    let differ = codes[start] ^ codes[end - 1];
    let bit = 1u64 << (63 - differ.leading_zeros());
    start + codes[start..end].partition_point(|c| c & bit == 0)
}

/// Sort `keys` by their bits from `from_bit` up, stably (keys equal there
/// keep their order): a least-significant-digit radix sort,
/// [`RADIX_BITS`] bits a pass, skipping the digits every key shares.
fn radix_sort(keys: &mut Vec<u64>, from_bit: u32) {
    let mut spare = vec![0u64; keys.len()];
    let mut starts = vec![0usize; 1 << RADIX_BITS];
    let mut shift = from_bit;
    while shift < u64::BITS {
        let digit = |k: u64| ((k >> shift) as usize) & ((1 << RADIX_BITS) - 1);
        starts.fill(0);
        for &k in keys.iter() {
            starts[digit(k)] += 1;
        }
        if !starts.contains(&keys.len()) {
            let mut total = 0;
            for start in starts.iter_mut() {
                (*start, total) = (total, total + *start);
            }
            for &k in keys.iter() {
                let d = digit(k);
                spare[starts[d]] = k;
                starts[d] += 1;
            }
            std::mem::swap(keys, &mut spare);
        }
        shift += RADIX_BITS;
    }
}

/// Bits of the key sorted per pass of [`radix_sort`].
const RADIX_BITS: u32 = 11;

/// Most bits per axis of the Morton grid over the parts' box (fewer when
/// the parts' indices need the room).
const MORTON_AXIS_BITS: u32 = 21;

/// The Morton code of a cell: the bits of `x`, `y` and `z` interleaved.
fn morton(x: u32, y: u32, z: u32) -> u64 {
    spread(x) | (spread(y) << 1) | (spread(z) << 2)
}

/// The low 21 bits of `v`, each moved to every third bit.
fn spread(v: u32) -> u64 {
    let mut x = u64::from(v) & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};

    /// Boxes of random balls in a 1 m cube.
    fn balls(n: usize, seed: u64) -> Vec<Bounds> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let c = Vector3::new(rng.gen(), rng.gen(), rng.gen());
                Bounds::ball(&c, rng.gen_range(0.001..0.02))
            })
            .collect()
    }

    #[test]
    fn a_visit_finds_exactly_the_parts_a_scan_finds() {
        for seed in 0..20 {
            let parts = balls(500 + 37 * seed as usize, seed);
            let tree = PartTree::new(&parts).unwrap();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed + 100);
            for _ in 0..20 {
                let c = Vector3::new(rng.gen(), rng.gen(), rng.gen());
                let query = Bounds::ball(&c, rng.gen_range(0.0..0.2));
                let limit = rng.gen_range(0.0..0.1);
                let mut visited = Vec::new();
                tree.visit(
                    |b| b.gap(&query),
                    limit,
                    |i| {
                        visited.push(i);
                        limit
                    },
                );
                visited.sort_unstable();
                let expected: Vec<usize> = (0..parts.len())
                    .filter(|&i| {
                        let gap = parts[i].gap(&query);
                        gap < limit || gap == 0.0
                    })
                    .collect();
                // The tree may visit a few more (a leaf's other parts), never fewer.
                for e in &expected {
                    assert!(
                        visited.binary_search(e).is_ok(),
                        "seed {seed}: part {e} missed"
                    );
                }
                assert!(visited.windows(2).all(|w| w[0] != w[1]), "visited twice");
            }
        }
    }

    #[test]
    fn the_radix_sort_orders_by_the_high_bits_and_keeps_ties_in_order() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (n, from_bit, spread) in [
            (0, 0, 64),
            (1, 5, 64),
            (1000, 0, 64),
            (5000, 13, 40),
            (3000, 20, 30),
        ] {
            let keys: Vec<u64> = (0..n).map(|_| rng.gen::<u64>() >> (64 - spread)).collect();
            let mut sorted = keys.clone();
            radix_sort(&mut sorted, from_bit);
            let mut expected = keys.clone();
            expected.sort_by_key(|k| k.checked_shr(from_bit).unwrap_or(0));
            assert_eq!(sorted, expected, "n {n}, from bit {from_bit}");
        }
    }

    #[test]
    fn morton_codes_interleave_the_cell_bits() {
        assert_eq!(morton(1, 0, 0), 1);
        assert_eq!(morton(0, 1, 0), 2);
        assert_eq!(morton(0, 0, 1), 4);
        assert_eq!(morton(3, 0, 0), 0b1001);
        let top = (1u32 << MORTON_AXIS_BITS) - 1;
        assert_eq!(morton(top, top, top), (1u64 << 63) - 1);
        // Brute force on random cells: bit k of x lands at bit 3k.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for _ in 0..100 {
            let (x, y, z) = (
                rng.gen_range(0..1u32 << MORTON_AXIS_BITS),
                rng.gen_range(0..1u32 << MORTON_AXIS_BITS),
                rng.gen_range(0..1u32 << MORTON_AXIS_BITS),
            );
            let expected = (0..21).fold(0u64, |code, k| {
                code | (u64::from(x >> k & 1) << (3 * k))
                    | (u64::from(y >> k & 1) << (3 * k + 1))
                    | (u64::from(z >> k & 1) << (3 * k + 2))
            });
            assert_eq!(morton(x, y, z), expected);
        }
    }

    #[test]
    fn a_falling_limit_still_finds_the_nearest_part() {
        let parts = balls(2000, 7);
        let tree = PartTree::new(&parts).unwrap();
        let query = Bounds::ball(&Vector3::new(0.5, 0.5, 0.5), 0.01);
        let mut best = (f64::INFINITY, usize::MAX);
        let mut visits = 0;
        tree.visit(
            |b| b.gap(&query),
            f64::INFINITY,
            |i| {
                visits += 1;
                let gap = parts[i].gap(&query);
                if gap < best.0 {
                    best = (gap, i);
                }
                best.0
            },
        );
        let scan = (0..parts.len())
            .map(|i| parts[i].gap(&query))
            .fold(f64::INFINITY, f64::min);
        assert_eq!(best.0, scan);
        assert!(visits < 200, "{visits} of 2000 parts visited");
        assert!(PartTree::new(&[]).is_none());
    }
}
