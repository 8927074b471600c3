//! The quad tree's traversal: the depth-first descent, nearest cell first, that every query
//! of [`QuadTreeN`] runs, and the bucket scans it calls.

use super::{Cell, MIN_HALF, NONE, QuadTreeN};
use crate::index::{Neighbour, PointId, dist_sq};
use nalgebra::Point2;

impl<const B: usize> QuadTreeN<B> {
    /// Scans one bucket, lowering `best`.
    #[inline(always)]
    pub(super) fn scan_leaf(
        &self,
        leaf: u32,
        qx: f64,
        qy: f64,
        best_d: &mut f64,
        best_slot: &mut usize,
    ) {
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
    pub(super) fn for_each_duplicate(&self, head: PointId, mut f: impl FnMut(PointId)) {
        let mut id = head;
        while id != NONE {
            f(id);
            id = self.dup_next[id as usize];
        }
    }

    pub(super) fn neighbour(&self, id: PointId, q: &Point2<f64>) -> Neighbour {
        let point = self.points[id as usize];
        Neighbour {
            id,
            point,
            dist_sq: dist_sq(&point, q),
        }
    }

    /// Depth-first traversal, nearest cell first, pruning cells farther than `bound()`.
    /// `visit_leaf` sees each non-empty leaf bucket (and its overflow chain) that survives.
    #[inline(always)]
    pub(super) fn traverse(
        &self,
        qx: f64,
        qy: f64,
        bound: impl Fn() -> f64,
        mut visit_leaf: impl FnMut(u32),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let r = self.root;
        // Squared distance from the query to the root cell, per axis. Cell bounds are exact and
        // rounding is monotone, so no point in a cell is closer than its (ox2 + oy2).
        let ox = ((r.cx - r.half) - qx).max(qx - (r.cx + r.half)).max(0.0);
        let oy = ((r.cy - r.half) - qy).max(qy - (r.cy + r.half)).max(0.0);
        let (ox2, oy2) = (ox * ox, oy * oy);
        if ox2 + oy2 <= bound() {
            self.descend(0, r, qx, qy, ox2, oy2, &bound, &mut visit_leaf);
        }
    }

    /// Visits node `n` of cell `cell`, which lies `ox2` (`oy2`) away from the query along x
    /// (y), squared. A child on the query's side of the centre along an axis inherits the
    /// parent's offset on that axis; a child across lies `(q - centre)²` away on it (its bound
    /// is the centre, exactly). Two subtractions per level, no sort.
    #[allow(clippy::too_many_arguments)]
    fn descend<FB: Fn() -> f64, FL: FnMut(u32)>(
        &self,
        n: u32,
        cell: Cell,
        qx: f64,
        qy: f64,
        ox2: f64,
        oy2: f64,
        bound: &FB,
        visit_leaf: &mut FL,
    ) {
        let node = self.nodes[n as usize];
        if node.children == NONE {
            if node.leaf == NONE {
                return;
            }
            visit_leaf(node.leaf);
            // Only cells that may not split grow overflow chains.
            if cell.half <= MIN_HALF {
                let mut leaf = self.leaf_next[node.leaf as usize];
                while leaf != NONE {
                    visit_leaf(leaf);
                    leaf = self.leaf_next[leaf as usize];
                }
            }
            return;
        }
        let (dx, dy) = (qx - cell.cx, qy - cell.cy);
        let q = u32::from(dx >= 0.0) | (u32::from(dy >= 0.0) << 1);
        let (dx2, dy2) = (dx * dx, dy * dy);
        let c = node.children;
        self.descend(c + q, cell.child(q), qx, qy, ox2, oy2, bound, visit_leaf);
        // The two edge neighbours, nearer first (each with its squared offsets), then the
        // diagonal one.
        let across_x = (q ^ 1, dx2, oy2);
        let across_y = (q ^ 2, ox2, dy2);
        let edges = if dx2 <= dy2 {
            [across_x, across_y]
        } else {
            [across_y, across_x]
        };
        for (child, ex2, ey2) in edges {
            if ex2 + ey2 <= bound() {
                let k = cell.child(child);
                self.descend(c + child, k, qx, qy, ex2, ey2, bound, visit_leaf);
            }
        }
        if dx2 + dy2 <= bound() {
            let k = cell.child(q ^ 3);
            self.descend(c + (q ^ 3), k, qx, qy, dx2, dy2, bound, visit_leaf);
        }
    }
}
