//! A kd-tree index on the `kiddo` crate.

use crate::index::{
    IndexError, Neighbour, PointId, SpatialIndex, check_point, dist_sq, fresh_revision,
};
use kiddo::SquaredEuclidean;
use nalgebra::Point2;
use std::collections::HashMap;

/// kiddo's bucket size: a leaf holds this many points before it splits.
const BUCKET: usize = 32;
type Inner = kiddo::float::kdtree::KdTree<f64, u32, 2, BUCKET, u32>;

/// A kd-tree on `kiddo`, growing by insertion.
///
/// kiddo cannot split a leaf whose points all share one coordinate on the split axis, and
/// panics when more than a bucket (32) of them meet (kiddo issue #475): 33 points on a
/// vertical line are enough. This wrapper counts every exact x and y value; a point whose x or
/// y is already shared by `BUCKET - 1` points stays out of kiddo, in an overflow list that every
/// query searches linearly. Real laser data never gets there; axis-aligned synthetic walls and
/// a robot standing still do, and stay correct. [`KdTree::overflow_len`] reports the count.
#[derive(Debug, Default)]
pub struct KdTree {
    tree: Option<Inner>,
    points: Vec<Point2<f64>>,
    axis_counts: [HashMap<u64, u32>; 2],
    overflow: Vec<PointId>,
    revision: u64,
}

impl KdTree {
    /// An empty tree.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Points kept out of kiddo because they share a coordinate with too many others.
    #[must_use]
    pub fn overflow_len(&self) -> usize {
        self.overflow.len()
    }

    fn neighbour(&self, id: PointId, q: &Point2<f64>) -> Neighbour {
        let point = self.points[id as usize];
        Neighbour {
            id,
            point,
            dist_sq: dist_sq(&point, q),
        }
    }
}

fn key(v: f64) -> u64 {
    // +0.0 and −0.0 compare equal, so kiddo treats them as one value.
    if v == 0.0 { 0 } else { v.to_bits() }
}

impl SpatialIndex for KdTree {
    fn insert(&mut self, p: Point2<f64>) -> Result<PointId, IndexError> {
        check_point(&p, self.points.len())?;
        let id = self.points.len() as PointId;
        self.points.push(p);
        self.revision = fresh_revision();
        let kx = key(p.x);
        let ky = key(p.y);
        let crowded = [kx, ky]
            .iter()
            .zip(&self.axis_counts)
            .any(|(k, counts)| counts.get(k).copied().unwrap_or(0) >= BUCKET as u32 - 1);
        if crowded {
            self.overflow.push(id);
        } else {
            *self.axis_counts[0].entry(kx).or_insert(0) += 1;
            *self.axis_counts[1].entry(ky).or_insert(0) += 1;
            self.tree
                .get_or_insert_with(Inner::new)
                .add(&[p.x, p.y], id);
        }
        Ok(id)
    }

    fn clear(&mut self) {
        self.tree = None;
        self.points.clear();
        self.axis_counts.iter_mut().for_each(HashMap::clear);
        self.overflow.clear();
        self.revision = fresh_revision();
    }

    fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    fn revision(&self) -> Option<u64> {
        Some(self.revision)
    }

    /// Out of the overflow list, or out of kiddo (whose coordinate counts then drop).
    fn remove(&mut self, id: PointId) -> Option<bool> {
        let Some(&p) = self.points.get(id as usize) else {
            return Some(false);
        };
        if let Some(k) = self.overflow.iter().position(|&o| o == id) {
            self.overflow.swap_remove(k);
            self.revision = fresh_revision();
            return Some(true);
        }
        let removed = self
            .tree
            .as_mut()
            .is_some_and(|t| t.remove(&[p.x, p.y], id) > 0);
        if removed {
            self.revision = fresh_revision();
            for (k, counts) in [key(p.x), key(p.y)].iter().zip(&mut self.axis_counts) {
                if let Some(c) = counts.get_mut(k) {
                    *c -= 1;
                }
            }
        }
        Some(removed)
    }

    fn nearest_within(&self, q: &Point2<f64>, max_dist_sq: f64) -> Option<Neighbour> {
        if !(q.x.is_finite() && q.y.is_finite()) {
            return None;
        }
        let mut best = self
            .tree
            .as_ref()
            .filter(|t| t.size() > 0)
            .map(|t| self.neighbour(t.nearest_one::<SquaredEuclidean>(&[q.x, q.y]).item, q))
            .filter(|n| n.dist_sq <= max_dist_sq);
        for &id in &self.overflow {
            let n = self.neighbour(id, q);
            if n.dist_sq <= max_dist_sq && best.is_none_or(|b| n.dist_sq < b.dist_sq) {
                best = Some(n);
            }
        }
        best
    }

    fn within_radius(&self, q: &Point2<f64>, radius: f64, out: &mut Vec<Neighbour>) {
        out.clear();
        if !(q.x.is_finite() && q.y.is_finite()) || radius.is_nan() || radius < 0.0 {
            return;
        }
        let r2 = radius * radius;
        if let Some(t) = &self.tree {
            // kiddo's own comparison may be strict; ask a hair wider and filter exactly.
            for n in t.within_unsorted::<SquaredEuclidean>(&[q.x, q.y], r2.next_up()) {
                let n = self.neighbour(n.item, q);
                if n.dist_sq <= r2 {
                    out.push(n);
                }
            }
        }
        for &id in &self.overflow {
            let n = self.neighbour(id, q);
            if n.dist_sq <= r2 {
                out.push(n);
            }
        }
    }

    fn k_nearest(&self, q: &Point2<f64>, k: usize, out: &mut Vec<Neighbour>) {
        out.clear();
        if k == 0 || !(q.x.is_finite() && q.y.is_finite()) {
            return;
        }
        if let Some(t) = &self.tree {
            out.extend(
                t.nearest_n::<SquaredEuclidean>(&[q.x, q.y], k)
                    .into_iter()
                    .map(|n| self.neighbour(n.item, q)),
            );
        }
        if !self.overflow.is_empty() {
            out.extend(self.overflow.iter().map(|&id| self.neighbour(id, q)));
            out.sort_by(|a, b| a.dist_sq.total_cmp(&b.dist_sq).then(a.id.cmp(&b.id)));
            out.truncate(k);
        }
    }
}
