//! A bounding-box tree over the parts of one obstacle with many of them (a
//! point cloud: one ball per point), so a query against a robot shape
//! visits only the parts whose boxes come within the query's distance —
//! the cost follows what is near the robot, not the size of the cloud.
//!
//! Built once when the scene compiles: parts are split at the median of
//! their box centres along the longest axis of the node's box until a leaf
//! holds at most [`LEAF_PARTS`]. The visit order is fixed by the build, so
//! queries are deterministic.

use super::broadphase::Bounds;

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
        if bounds.is_empty() {
            return None;
        }
        // The split works on a contiguous array of (box centre, part), so
        // the median selections touch no other memory.
        let mut items: Vec<([f64; 3], usize)> = bounds
            .iter()
            .enumerate()
            .map(|(i, b)| ((b.min + b.max).into(), i))
            .collect();
        let mut tree = PartTree {
            nodes: Vec::with_capacity(2 * bounds.len() / LEAF_PARTS + 1),
            order: Vec::new(),
        };
        tree.build(bounds, &mut items, 0);
        tree.order = items.iter().map(|&(_, i)| i).collect();
        Some(tree)
    }

    /// Build the node over `items` (which start at `start` in the final
    /// order); returns its index. A node's box is its children's merged.
    fn build(&mut self, bounds: &[Bounds], items: &mut [([f64; 3], usize)], start: usize) -> usize {
        let index = self.nodes.len();
        self.nodes.push(Node {
            bounds: bounds[items[0].1],
            start,
            end: start + items.len(),
            children: None,
        });
        if items.len() <= LEAF_PARTS {
            self.nodes[index].bounds = items
                .iter()
                .map(|&(_, i)| bounds[i])
                .reduce(|a, b| a.merged(&b))
                .unwrap_or(bounds[items[0].1]);
            return index;
        }
        let axis = longest_axis(items);
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| a.0[axis].total_cmp(&b.0[axis]));
        let (low, high) = items.split_at_mut(mid);
        let left = self.build(bounds, low, start);
        let right = self.build(bounds, high, start + mid);
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

/// The axis along which the box centres of `items` spread most.
fn longest_axis(items: &[([f64; 3], usize)]) -> usize {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (c, _) in items {
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0)
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
