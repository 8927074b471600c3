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

use crate::index::{IndexError, Neighbour, PointId, SpatialIndex, check_point, fresh_revision};
use nalgebra::Point2;

mod search;

/// Cells of half-size below this (2⁻²⁰ m, about a micrometre) do not split.
pub const MIN_HALF: f64 = 1.0 / 1_048_576.0;
/// Half-size of the first root cell (m); the root grows as points arrive outside it.
pub const INITIAL_HALF: f64 = 32.0;

const NONE: u32 = u32::MAX;
/// Deepest possible tree: from a root of half-size 2^32 down to [`MIN_HALF`].
#[cfg(test)]
const MAX_DEPTH: usize = 54;

/// The quad tree with the default bucket size.
pub type QuadTree = QuadTreeN<16>;

/// A node holds no geometry: a cell's centre and half-size follow from the root's on the way
/// down (halving is exact), so a node is 8 bytes and the nodes of a 100k-point map stay in L2.
#[derive(Debug, Clone, Copy)]
struct Node {
    /// Index of the first of four consecutive children, or `NONE` for a leaf.
    children: u32,
    /// For a leaf: its bucket, or `NONE` while the leaf is empty.
    leaf: u32,
}

const EMPTY_LEAF: Node = Node {
    children: NONE,
    leaf: NONE,
};

/// Centre and half-size of a cell.
#[derive(Debug, Clone, Copy)]
struct Cell {
    cx: f64,
    cy: f64,
    half: f64,
}

impl Cell {
    #[inline(always)]
    fn quadrant(&self, x: f64, y: f64) -> u32 {
        u32::from(x >= self.cx) | (u32::from(y >= self.cy) << 1)
    }

    /// Child cell `q` (bit 0: east, bit 1: north). Exact: `half` is a power of two.
    #[inline(always)]
    fn child(&self, q: u32) -> Cell {
        let h = self.half * 0.5;
        Cell {
            cx: if q & 1 == 1 { self.cx + h } else { self.cx - h },
            cy: if q & 2 == 2 { self.cy + h } else { self.cy - h },
            half: h,
        }
    }

    fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.cx - self.half
            && x < self.cx + self.half
            && y >= self.cy - self.half
            && y < self.cy + self.half
    }
}

/// A bucketed quad tree with `B` points per leaf. Use the [`QuadTree`] alias unless you are
/// tuning the bucket size.
#[derive(Debug, Clone)]
pub struct QuadTreeN<const B: usize> {
    /// Node 0 is the root.
    nodes: Vec<Node>,
    root: Cell,
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
    revision: u64,
}

impl<const B: usize> Default for QuadTreeN<B> {
    fn default() -> Self {
        const { assert!(B >= 2, "a quad tree bucket must hold at least two points") };
        Self {
            nodes: Vec::new(),
            root: Cell {
                cx: 0.0,
                cy: 0.0,
                half: INITIAL_HALF,
            },
            slot_x: Vec::new(),
            slot_y: Vec::new(),
            slot_id: Vec::new(),
            leaf_len: Vec::new(),
            leaf_next: Vec::new(),
            points: Vec::new(),
            dup_next: Vec::new(),
            revision: 0,
        }
    }
}

impl<const B: usize> QuadTreeN<B> {
    /// An empty tree.
    #[must_use]
    pub fn new() -> Self {
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

    /// Doubles the root towards `(x, y)`; the old root becomes one quadrant of the new one.
    /// The root keeps index 0, so nothing that refers to it changes.
    fn grow_towards(&mut self, x: f64, y: f64) {
        let old = self.root;
        let root = Cell {
            cx: if x < old.cx {
                old.cx - old.half
            } else {
                old.cx + old.half
            },
            cy: if y < old.cy {
                old.cy - old.half
            } else {
                old.cy + old.half
            },
            half: old.half * 2.0,
        };
        let old_quadrant = root.quadrant(old.cx, old.cy);
        let first = self.nodes.len() as u32;
        for q in 0..4 {
            let child = if q == old_quadrant {
                self.nodes[0]
            } else {
                EMPTY_LEAF
            };
            self.nodes.push(child);
        }
        self.nodes[0] = Node {
            children: first,
            leaf: NONE,
        };
        self.root = root;
    }

    /// [`SpatialIndex::remove`] of point `id` at `(x, y)`.
    fn remove_point(&mut self, id: PointId, x: f64, y: f64) -> bool {
        if self.nodes.is_empty() || !self.root.contains(x, y) {
            return false;
        }
        let (mut n, mut cell) = (0usize, self.root);
        while self.nodes[n].children != NONE {
            let q = cell.quadrant(x, y);
            n = (self.nodes[n].children + q) as usize;
            cell = cell.child(q);
        }
        let mut leaf = self.nodes[n].leaf;
        while leaf != NONE {
            let base = leaf as usize * B;
            let len = self.leaf_len[leaf as usize] as usize;
            if let Some(s) =
                (base..base + len).find(|&s| self.slot_x[s] == x && self.slot_y[s] == y)
            {
                let head = self.slot_id[s];
                let mut chain = Vec::new();
                self.for_each_duplicate(head, |d| chain.push(d));
                let Some(k) = chain.iter().position(|&d| d == id) else {
                    return false;
                };
                chain.swap_remove(k);
                self.dup_next[id as usize] = NONE;
                match chain.iter().min().copied() {
                    Some(first) => {
                        // The lowest id heads the chain; the rest follow in any order.
                        self.slot_id[s] = first;
                        let mut prev = first;
                        for &d in chain.iter().filter(|&&d| d != first) {
                            self.dup_next[prev as usize] = d;
                            prev = d;
                        }
                        self.dup_next[prev as usize] = NONE;
                    }
                    None => {
                        let last = base + len - 1;
                        self.slot_x[s] = self.slot_x[last];
                        self.slot_y[s] = self.slot_y[last];
                        self.slot_id[s] = self.slot_id[last];
                        self.slot_x[last] = f64::INFINITY;
                        self.slot_y[last] = f64::INFINITY;
                        self.slot_id[last] = NONE;
                        self.leaf_len[leaf as usize] -= 1;
                    }
                }
                return true;
            }
            leaf = self.leaf_next[leaf as usize];
        }
        false
    }

    /// Turns leaf `n` (of cell `cell`) into an internal node and moves its points to four new
    /// leaves.
    fn split(&mut self, n: usize, cell: Cell) {
        let bucket = self.nodes[n].leaf;
        let base = bucket as usize * B;
        let moved: Vec<(f64, f64, PointId)> = (0..self.leaf_len[bucket as usize] as usize)
            .map(|k| {
                (
                    self.slot_x[base + k],
                    self.slot_y[base + k],
                    self.slot_id[base + k],
                )
            })
            .collect();
        // The old bucket goes to the first child that receives a point.
        self.slot_x[base..base + B].fill(f64::INFINITY);
        self.slot_y[base..base + B].fill(f64::INFINITY);
        self.slot_id[base..base + B].fill(NONE);
        self.leaf_len[bucket as usize] = 0;
        let mut spare = Some(bucket);
        let first = self.nodes.len() as u32;
        self.nodes.extend([EMPTY_LEAF; 4]);
        self.nodes[n] = Node {
            children: first,
            leaf: NONE,
        };
        for (x, y, id) in moved {
            let c = (first + cell.quadrant(x, y)) as usize;
            if self.nodes[c].leaf == NONE {
                self.nodes[c].leaf = spare.take().unwrap_or_else(|| self.new_leaf());
            }
            self.push_slot(self.nodes[c].leaf, x, y, id);
        }
    }
}

impl<const B: usize> SpatialIndex for QuadTreeN<B> {
    fn insert(&mut self, p: Point2<f64>) -> Result<PointId, IndexError> {
        check_point(&p, self.points.len())?;
        let id = self.points.len() as PointId;
        self.points.push(p);
        self.dup_next.push(NONE);
        self.revision = fresh_revision();
        let (x, y) = (p.x, p.y);
        if self.nodes.is_empty() {
            let leaf = self.new_leaf();
            self.nodes.push(Node {
                children: NONE,
                leaf,
            });
            self.root = Cell {
                cx: (x / INITIAL_HALF).round() * INITIAL_HALF,
                cy: (y / INITIAL_HALF).round() * INITIAL_HALF,
                half: INITIAL_HALF,
            };
        }
        while !self.root.contains(x, y) {
            self.grow_towards(x, y);
        }
        let mut n = 0usize;
        let mut cell = self.root;
        loop {
            let node = self.nodes[n];
            if node.children != NONE {
                let q = cell.quadrant(x, y);
                n = (node.children + q) as usize;
                cell = cell.child(q);
                continue;
            }
            if node.leaf == NONE {
                let leaf = self.new_leaf();
                self.nodes[n].leaf = leaf;
                self.push_slot(leaf, x, y, id);
                return Ok(id);
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
            if cell.half > MIN_HALF {
                self.split(n, cell);
                continue;
            }
            let extra = self.new_leaf();
            self.leaf_next[last as usize] = extra;
            self.push_slot(extra, x, y, id);
            return Ok(id);
        }
    }

    /// The point's slot loses it (the bucket's last slot takes its place) or, when it heads a
    /// chain of duplicates, passes to the lowest remaining id of the chain, so that ties are
    /// still won by the lowest id, as in [`BruteForce`](crate::BruteForce).
    fn remove(&mut self, id: PointId) -> Option<bool> {
        let Some(&p) = self.points.get(id as usize) else {
            return Some(false);
        };
        let removed = self.remove_point(id, p.x, p.y);
        if removed {
            self.revision = fresh_revision();
        }
        Some(removed)
    }

    fn revision(&self) -> Option<u64> {
        Some(self.revision)
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
        self.revision = fresh_revision();
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

    /// One traversal for both answers. Its bound is the larger of the nearest search's
    /// (the best distance so far) and the neighbourhood's (that distance, capped at
    /// `max_reach`, plus `slack`, squared); both only shrink, so every leaf the two searches
    /// would visit is visited, in the same order, and every point that ends within the
    /// final radius was collected when its leaf was seen. The points collected beyond it are
    /// dropped at the end, which leaves `within_radius`'s answer, order included.
    fn nearest_and_around(
        &self,
        q: &Point2<f64>,
        max_dist_sq: f64,
        slack: f64,
        max_reach: f64,
        out: &mut Vec<Neighbour>,
    ) -> (Option<Neighbour>, Option<f64>) {
        if !(q.x.is_finite() && q.y.is_finite())
            || max_dist_sq.is_nan()
            || !(slack >= 0.0 && slack.is_finite())
            || max_reach.is_nan()
        {
            return crate::index::nearest_then_around(self, q, max_dist_sq, slack, max_reach, out);
        }
        out.clear();
        let around = |reach_sq: f64| {
            let r = reach_sq.sqrt().min(max_reach).max(0.0) + slack;
            r * r
        };
        let best_d = std::cell::Cell::new(max_dist_sq.next_up());
        let collect = std::cell::Cell::new(around(max_dist_sq));
        let bound = std::cell::Cell::new(best_d.get().max(collect.get()));
        let mut best_slot = usize::MAX;
        self.traverse(
            q.x,
            q.y,
            || bound.get(),
            |leaf| {
                let base = leaf as usize * B;
                for s in base..base + self.leaf_len[leaf as usize] as usize {
                    let dx = self.slot_x[s] - q.x;
                    let dy = self.slot_y[s] - q.y;
                    let d = dx * dx + dy * dy;
                    if d < best_d.get() {
                        best_d.set(d);
                        best_slot = s;
                        collect.set(around(d));
                        bound.set(d.max(collect.get()));
                    }
                    if d <= collect.get() {
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
        let nearest = (best_slot != usize::MAX).then(|| self.neighbour(self.slot_id[best_slot], q));
        let radius = crate::index::around_radius(nearest.as_ref(), max_dist_sq, slack, max_reach);
        match radius {
            Some(r) => {
                let r2 = r * r;
                out.retain(|n| n.dist_sq <= r2);
            }
            None => out.clear(),
        }
        (nearest, radius)
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
        self.traverse(q.x, q.y, bound, |leaf| {
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
