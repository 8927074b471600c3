//! The paper's index: a bucketed point quad tree that grows one scan at a time.
//!
//! Design, and why:
//! - **Cells are exact.** The root is a square of power-of-two half-size centred on a multiple
//!   of that size; children halve it. Every cell bound is then exactly representable, so the
//!   point-to-cell distance used for pruning never exceeds the distance to a point inside the
//!   cell, and answers match [`BruteForce`](crate::BruteForce) bit for bit.
//! - **Incremental.** A full leaf splits in place; a point outside the root makes the root grow
//!   (the old root becomes one quadrant of a root twice its size). Nothing is ever rebuilt.
//! - **Buckets.** Leaves hold `B` points in flat structure-of-arrays slots padded with +∞, so a
//!   leaf scan is a fixed-length loop the compiler vectorises.
//! - **Duplicates cost nothing.** A point equal to one already stored is chained to it (by id)
//!   instead of taking a slot, so a robot standing still or a scan inserted twice neither
//!   deepens the tree nor slows queries. Cells stop splitting below [`MIN_HALF`]; points closer
//!   than that spill into chained overflow leaves.

use crate::index::{IndexError, Neighbour, PointId, SpatialIndex, check_point, dist_sq};
use nalgebra::Point2;

/// Cells of half-size below this (2⁻²⁰ m, about a micrometre) do not split.
pub const MIN_HALF: f64 = 1.0 / 1_048_576.0;
/// Half-size of the first root cell (m); the root grows as points arrive outside it.
pub const INITIAL_HALF: f64 = 32.0;

const NONE: u32 = u32::MAX;
/// Deepest possible tree: from a root of half-size 2^32 down to [`MIN_HALF`].
const MAX_DEPTH: usize = 54;
/// An internal node pops one entry and pushes at most four.
const STACK: usize = 3 * MAX_DEPTH + 4;

/// The quad tree with the default bucket size.
pub type QuadTree = QuadTreeN<16>;

#[derive(Debug, Clone, Copy)]
struct Node {
    cx: f64,
    cy: f64,
    half: f64,
    /// Index of the first of four consecutive children, or `NONE` for a leaf.
    children: u32,
    /// For a leaf: its bucket.
    leaf: u32,
}

/// A bucketed quad tree with `B` points per leaf. Use the [`QuadTree`] alias unless you are
/// tuning the bucket size.
#[derive(Debug, Clone)]
pub struct QuadTreeN<const B: usize> {
    nodes: Vec<Node>,
    /// Bucket slots, `B` per leaf, padded with +∞.
    slot_x: Vec<f64>,
    slot_y: Vec<f64>,
    slot_id: Vec<PointId>,
    leaf_len: Vec<u32>,
    /// Overflow chain of a leaf that may not split.
    leaf_next: Vec<u32>,
    points: Vec<Point2<f64>>,
    /// Next point with the same coordinates as this one, or `NONE`.
    dup_next: Vec<PointId>,
}

impl<const B: usize> Default for QuadTreeN<B> {
    fn default() -> Self {
        Self {
            nodes: Vec::new(),
            slot_x: Vec::new(),
            slot_y: Vec::new(),
            slot_id: Vec::new(),
            leaf_len: Vec::new(),
            leaf_next: Vec::new(),
            points: Vec::new(),
            dup_next: Vec::new(),
        }
    }
}

#[inline(always)]
fn quadrant(n: &Node, x: f64, y: f64) -> u32 {
    u32::from(x >= n.cx) | (u32::from(y >= n.cy) << 1)
}

/// Squared distance from `(x, y)` to the cell of `n`. Cell bounds are exact, and rounding is
/// monotone, so this never exceeds `dist_sq` to any point the cell holds.
#[inline(always)]
fn cell_dist_sq(n: &Node, x: f64, y: f64) -> f64 {
    let dx = ((n.cx - n.half) - x).max(x - (n.cx + n.half)).max(0.0);
    let dy = ((n.cy - n.half) - y).max(y - (n.cy + n.half)).max(0.0);
    dx * dx + dy * dy
}

impl<const B: usize> QuadTreeN<B> {
    /// An empty tree.
    #[must_use]
    pub fn new() -> Self {
        assert!(B >= 2, "a quad tree bucket must hold at least two points");
        Self::default()
    }

    /// Number of nodes (internal and leaves): a measure of memory and depth.
    #[must_use]
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Depth of the deepest leaf (the root alone has depth 0).
    #[must_use]
    pub fn depth(&self) -> usize {
        fn walk<const B: usize>(t: &QuadTreeN<B>, n: u32) -> usize {
            let node = t.nodes[n as usize];
            if node.children == NONE {
                0
            } else {
                1 + (0..4)
                    .map(|c| walk(t, node.children + c))
                    .max()
                    .unwrap_or(0)
            }
        }
        if self.nodes.is_empty() {
            0
        } else {
            walk(self, 0)
        }
    }

    fn new_leaf(&mut self) -> u32 {
        let leaf = self.leaf_len.len() as u32;
        self.slot_x.extend(std::iter::repeat_n(f64::INFINITY, B));
        self.slot_y.extend(std::iter::repeat_n(f64::INFINITY, B));
        self.slot_id.extend(std::iter::repeat_n(NONE, B));
        self.leaf_len.push(0);
        self.leaf_next.push(NONE);
        leaf
    }

    fn push_slot(&mut self, leaf: u32, x: f64, y: f64, id: PointId) {
        let s = leaf as usize * B + self.leaf_len[leaf as usize] as usize;
        self.slot_x[s] = x;
        self.slot_y[s] = y;
        self.slot_id[s] = id;
        self.leaf_len[leaf as usize] += 1;
    }

    fn root_contains(&self, x: f64, y: f64) -> bool {
        let r = &self.nodes[0];
        x >= r.cx - r.half && x < r.cx + r.half && y >= r.cy - r.half && y < r.cy + r.half
    }

    /// Doubles the root towards `(x, y)`; the old root becomes one quadrant of the new one.
    /// The root keeps index 0, so nothing that refers to it changes.
    fn grow_towards(&mut self, x: f64, y: f64) {
        let old = self.nodes[0];
        let cx = if x < old.cx {
            old.cx - old.half
        } else {
            old.cx + old.half
        };
        let cy = if y < old.cy {
            old.cy - old.half
        } else {
            old.cy + old.half
        };
        let root = Node {
            cx,
            cy,
            half: old.half * 2.0,
            children: self.nodes.len() as u32,
            leaf: NONE,
        };
        let old_quadrant = quadrant(&root, old.cx, old.cy);
        for q in 0..4 {
            let child = if q == old_quadrant {
                old
            } else {
                self.child_leaf(&root, q)
            };
            self.nodes.push(child);
        }
        self.nodes[0] = root;
    }

    fn child_leaf(&mut self, parent: &Node, q: u32) -> Node {
        let h = parent.half * 0.5;
        Node {
            cx: if q & 1 == 1 {
                parent.cx + h
            } else {
                parent.cx - h
            },
            cy: if q & 2 == 2 {
                parent.cy + h
            } else {
                parent.cy - h
            },
            half: h,
            children: NONE,
            leaf: self.new_leaf(),
        }
    }

    /// Turns leaf `n` into an internal node and moves its points to four new leaves.
    fn split(&mut self, n: usize) {
        let node = self.nodes[n];
        let base = node.leaf as usize * B;
        let moved: Vec<(f64, f64, PointId)> = (0..self.leaf_len[node.leaf as usize] as usize)
            .map(|k| {
                (
                    self.slot_x[base + k],
                    self.slot_y[base + k],
                    self.slot_id[base + k],
                )
            })
            .collect();
        // The old bucket is reused by the first child.
        self.slot_x[base..base + B].fill(f64::INFINITY);
        self.slot_y[base..base + B].fill(f64::INFINITY);
        self.slot_id[base..base + B].fill(NONE);
        self.leaf_len[node.leaf as usize] = 0;
        let first = self.nodes.len() as u32;
        for q in 0..4 {
            let mut child = if q == 0 {
                let h = node.half * 0.5;
                Node {
                    cx: node.cx - h,
                    cy: node.cy - h,
                    half: h,
                    children: NONE,
                    leaf: node.leaf,
                }
            } else {
                self.child_leaf(&node, q)
            };
            child.children = NONE;
            self.nodes.push(child);
        }
        self.nodes[n].children = first;
        self.nodes[n].leaf = NONE;
        for (x, y, id) in moved {
            let c = self.nodes[(first + quadrant(&node, x, y)) as usize].leaf;
            self.push_slot(c, x, y, id);
        }
    }

    /// Scans one bucket, lowering `best`.
    #[inline(always)]
    fn scan_leaf(&self, leaf: u32, qx: f64, qy: f64, best_d: &mut f64, best_slot: &mut usize) {
        let base = leaf as usize * B;
        let xs = &self.slot_x[base..base + B];
        let ys = &self.slot_y[base..base + B];
        for k in 0..B {
            let dx = xs[k] - qx;
            let dy = ys[k] - qy;
            let d = dx * dx + dy * dy;
            if d < *best_d {
                *best_d = d;
                *best_slot = base + k;
            }
        }
    }

    /// Calls `f(id)` for the point stored in `slot` and every duplicate chained to it.
    fn for_each_duplicate(&self, head: PointId, mut f: impl FnMut(PointId)) {
        let mut id = head;
        while id != NONE {
            f(id);
            id = self.dup_next[id as usize];
        }
    }

    fn neighbour(&self, id: PointId, q: &Point2<f64>) -> Neighbour {
        let point = self.points[id as usize];
        Neighbour {
            id,
            point,
            dist_sq: dist_sq(&point, q),
        }
    }

    /// Depth-first traversal, nearest cell first, pruning cells no closer than `bound()`.
    /// `visit_leaf` sees each leaf bucket (and its overflow chain) that survives pruning.
    #[inline(always)]
    fn traverse(&self, qx: f64, qy: f64, bound: impl Fn() -> f64, mut visit_leaf: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [(0u32, 0.0f64); STACK];
        stack[0] = (0, cell_dist_sq(&self.nodes[0], qx, qy));
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (n, d) = stack[top];
            if d > bound() {
                continue;
            }
            let node = &self.nodes[n as usize];
            if node.children == NONE {
                let mut leaf = node.leaf;
                while leaf != NONE {
                    visit_leaf(leaf);
                    leaf = self.leaf_next[leaf as usize];
                }
                continue;
            }
            let c = node.children;
            let mut kids = [(0u32, 0.0f64); 4];
            for (k, kid) in kids.iter_mut().enumerate() {
                let idx = c + k as u32;
                *kid = (idx, cell_dist_sq(&self.nodes[idx as usize], qx, qy));
            }
            // Sort the four by distance, farthest first, so the nearest is popped next.
            kids.sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
            let b = bound();
            for kid in kids {
                if kid.1 <= b {
                    stack[top] = kid;
                    top += 1;
                }
            }
        }
    }
}

impl<const B: usize> SpatialIndex for QuadTreeN<B> {
    fn insert(&mut self, p: Point2<f64>) -> Result<PointId, IndexError> {
        check_point(&p, self.points.len())?;
        let id = self.points.len() as PointId;
        self.points.push(p);
        self.dup_next.push(NONE);
        let (x, y) = (p.x, p.y);
        if self.nodes.is_empty() {
            let leaf = self.new_leaf();
            self.nodes.push(Node {
                cx: (x / INITIAL_HALF).round() * INITIAL_HALF,
                cy: (y / INITIAL_HALF).round() * INITIAL_HALF,
                half: INITIAL_HALF,
                children: NONE,
                leaf,
            });
        }
        while !self.root_contains(x, y) {
            self.grow_towards(x, y);
        }
        let mut n = 0usize;
        loop {
            let node = self.nodes[n];
            if node.children != NONE {
                n = (node.children + quadrant(&node, x, y)) as usize;
                continue;
            }
            // A duplicate joins the chain of the point it equals.
            let mut leaf = node.leaf;
            let mut last = leaf;
            while leaf != NONE {
                let base = leaf as usize * B;
                for s in base..base + self.leaf_len[leaf as usize] as usize {
                    if self.slot_x[s] == x && self.slot_y[s] == y {
                        let head = self.slot_id[s] as usize;
                        self.dup_next[id as usize] = self.dup_next[head];
                        self.dup_next[head] = id;
                        return Ok(id);
                    }
                }
                last = leaf;
                leaf = self.leaf_next[leaf as usize];
            }
            if (self.leaf_len[last as usize] as usize) < B {
                self.push_slot(last, x, y, id);
                return Ok(id);
            }
            if node.half > MIN_HALF {
                self.split(n);
                continue;
            }
            let extra = self.new_leaf();
            self.leaf_next[last as usize] = extra;
            self.push_slot(extra, x, y, id);
            return Ok(id);
        }
    }

    fn clear(&mut self) {
        self.nodes.clear();
        self.slot_x.clear();
        self.slot_y.clear();
        self.slot_id.clear();
        self.leaf_len.clear();
        self.leaf_next.clear();
        self.points.clear();
        self.dup_next.clear();
    }

    fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    fn nearest_within(&self, q: &Point2<f64>, max_dist_sq: f64) -> Option<Neighbour> {
        if !(q.x.is_finite() && q.y.is_finite()) || max_dist_sq.is_nan() {
            return None;
        }
        // Strict comparisons against the next float up accept distances equal to the limit.
        let best_d = std::cell::Cell::new(max_dist_sq.next_up());
        let mut best_slot = usize::MAX;
        self.traverse(
            q.x,
            q.y,
            || best_d.get(),
            |leaf| {
                let mut d = best_d.get();
                self.scan_leaf(leaf, q.x, q.y, &mut d, &mut best_slot);
                best_d.set(d);
            },
        );
        (best_slot != usize::MAX).then(|| self.neighbour(self.slot_id[best_slot], q))
    }

    fn within_radius(&self, q: &Point2<f64>, radius: f64, out: &mut Vec<Neighbour>) {
        out.clear();
        if !(q.x.is_finite() && q.y.is_finite()) || radius.is_nan() || radius < 0.0 {
            return;
        }
        let r2 = radius * radius;
        self.traverse(
            q.x,
            q.y,
            || r2,
            |leaf| {
                let base = leaf as usize * B;
                for s in base..base + self.leaf_len[leaf as usize] as usize {
                    let dx = self.slot_x[s] - q.x;
                    let dy = self.slot_y[s] - q.y;
                    let d = dx * dx + dy * dy;
                    if d <= r2 {
                        self.for_each_duplicate(self.slot_id[s], |id| {
                            out.push(Neighbour {
                                id,
                                point: self.points[id as usize],
                                dist_sq: d,
                            });
                        });
                    }
                }
            },
        );
    }

    fn k_nearest(&self, q: &Point2<f64>, k: usize, out: &mut Vec<Neighbour>) {
        out.clear();
        if k == 0 || !(q.x.is_finite() && q.y.is_finite()) {
            return;
        }
        // `out` is kept sorted and at most k long; the bound is its k-th distance.
        let found = std::cell::RefCell::new(std::mem::take(out));
        let bound = || {
            let f = found.borrow();
            if f.len() < k {
                f64::INFINITY
            } else {
                f[k - 1].dist_sq
            }
        };
        self.traverse(q.x, q.y, &bound, |leaf| {
            let base = leaf as usize * B;
            for s in base..base + self.leaf_len[leaf as usize] as usize {
                let dx = self.slot_x[s] - q.x;
                let dy = self.slot_y[s] - q.y;
                let d = dx * dx + dy * dy;
                if d >= bound() {
                    continue;
                }
                let mut f = found.borrow_mut();
                self.for_each_duplicate(self.slot_id[s], |id| {
                    let at = f.partition_point(|n| n.dist_sq <= d);
                    if at < k {
                        if f.len() == k {
                            f.pop();
                        }
                        f.insert(
                            at,
                            Neighbour {
                                id,
                                point: self.points[id as usize],
                                dist_sq: d,
                            },
                        );
                    }
                });
            }
        });
        *out = found.into_inner();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_grows_in_every_direction() {
        let mut t = QuadTree::new();
        for p in [
            (0.0, 0.0),
            (1000.0, -3.0),
            (-5e4, 7e4),
            (1e-7, 1e-7),
            (3.0, -9e5),
        ] {
            t.insert(Point2::new(p.0, p.1)).unwrap();
        }
        for p in t.points().to_vec() {
            let n = t.nearest(&p).unwrap();
            assert_eq!(n.dist_sq, 0.0);
        }
    }

    #[test]
    fn duplicates_do_not_deepen_the_tree() {
        let mut t = QuadTree::new();
        for _ in 0..10_000 {
            t.insert(Point2::new(1.5, -2.5)).unwrap();
        }
        assert_eq!(t.node_count(), 1);
        let mut out = Vec::new();
        t.within_radius(&Point2::new(1.5, -2.5), 0.0, &mut out);
        assert_eq!(out.len(), 10_000);
        assert_eq!(t.nearest(&Point2::new(0.0, 0.0)).unwrap().id, 0);
    }

    #[test]
    fn points_closer_than_the_smallest_cell_spill_into_chains() {
        let mut t = QuadTree::new();
        for k in 0..100 {
            t.insert(Point2::new(1.0 + k as f64 * 1e-9, 1.0)).unwrap();
        }
        assert!(t.depth() <= MAX_DEPTH);
        let n = t.nearest(&Point2::new(1.0 + 50e-9, 1.0)).unwrap();
        assert_eq!(n.id, 50);
    }
}
