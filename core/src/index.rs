//! The spatial-index plug-in point: a growing set of 2D points answering nearest-neighbour,
//! k-nearest and radius queries.
//!
//! Every implementation must return the same *distances* as [`BruteForce`] (ties between
//! equidistant points may be broken differently). Distances are computed everywhere with
//! [`dist_sq`], so equal answers are bit-identical, not merely close. A correspondence rule
//! whose own criterion can tie breaks the tie by [`PointId`] (IDC's matching-range rule, where
//! quantized ranges tie often); a nearest-neighbour tie between two exactly equidistant points
//! is left to the index.

use nalgebra::Point2;
use std::ops::Range;
use thiserror::Error;

/// Identifier of an inserted point: its insertion order, starting at 0.
pub type PointId = u32;

/// Largest absolute coordinate an index accepts (m). About 2.1 million km: far beyond any
/// map, small enough that the quad tree's cell arithmetic stays exact.
pub const MAX_COORDINATE: f64 = 2_147_483_648.0;

/// Why a point was refused.
#[derive(Debug, Error, Clone, Copy, PartialEq)]
pub enum IndexError {
    /// A coordinate is NaN or infinite.
    #[error("point ({x}, {y}) has a non-finite coordinate")]
    NonFinite {
        /// x coordinate.
        x: f64,
        /// y coordinate.
        y: f64,
    },
    /// A coordinate is beyond [`MAX_COORDINATE`].
    #[error("point ({x}, {y}) lies beyond ±{MAX_COORDINATE} m")]
    OutOfRange {
        /// x coordinate.
        x: f64,
        /// y coordinate.
        y: f64,
    },
    /// The index holds `u32::MAX` points already.
    #[error("the index is full ({0} points)")]
    Full(usize),
}

/// One answer to a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbour {
    /// The point's id (insertion order).
    pub id: PointId,
    /// The point.
    pub point: Point2<f64>,
    /// Squared Euclidean distance to the query.
    pub dist_sq: f64,
}

/// Squared Euclidean distance, computed the one way every index uses.
#[inline(always)]
#[must_use]
pub fn dist_sq(a: &Point2<f64>, b: &Point2<f64>) -> f64 {
    let dx = a.x - b.x;
    let dy = a.y - b.y;
    dx * dx + dy * dy
}

/// Checks that a point may enter an index.
pub fn check_point(p: &Point2<f64>, len: usize) -> Result<(), IndexError> {
    if !(p.x.is_finite() && p.y.is_finite()) {
        return Err(IndexError::NonFinite { x: p.x, y: p.y });
    }
    if p.x.abs() > MAX_COORDINATE || p.y.abs() > MAX_COORDINATE {
        return Err(IndexError::OutOfRange { x: p.x, y: p.y });
    }
    if len >= u32::MAX as usize {
        return Err(IndexError::Full(len));
    }
    Ok(())
}

/// [`SpatialIndex::nearest_and_around`] as two searches: the nearest point within the limit,
/// then, when it lies within `max_reach`, every point within its distance plus `slack`. The
/// reference every one-pass answer must equal.
pub fn nearest_then_around<I: SpatialIndex + ?Sized>(
    index: &I,
    q: &Point2<f64>,
    max_dist_sq: f64,
    slack: f64,
    max_reach: f64,
    out: &mut Vec<Neighbour>,
) -> (Option<Neighbour>, Option<f64>) {
    let nearest = index.nearest_within(q, max_dist_sq);
    let radius = around_radius(nearest.as_ref(), max_dist_sq, slack, max_reach);
    match radius {
        Some(r) => index.within_radius(q, r, out),
        None => out.clear(),
    }
    (nearest, radius)
}

/// The radius of [`SpatialIndex::nearest_and_around`]'s neighbourhood: the nearest point's
/// distance (or, with none, the limit's) plus `slack`, when that distance is within
/// `max_reach`. Every implementation computes it here, so that equal answers are
/// bit-identical.
#[must_use]
pub fn around_radius(
    nearest: Option<&Neighbour>,
    max_dist_sq: f64,
    slack: f64,
    max_reach: f64,
) -> Option<f64> {
    let reach = nearest.map_or(max_dist_sq, |n| n.dist_sq).sqrt();
    (reach <= max_reach).then_some(reach + slack)
}

/// A revision no index has had before: the value an index takes each time its point set
/// changes ([`SpatialIndex::revision`]). Unique across every index of the process, so two
/// indexes share a revision only where one is a clone of the other, unchanged since.
#[must_use]
pub fn fresh_revision() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// A set of 2D points that grows by insertion and answers proximity queries.
///
/// Queries with a non-finite query point return nothing. Matchers are generic over this trait,
/// so their inner loops are monomorphic.
pub trait SpatialIndex {
    /// Inserts one point and returns its id. A refused point leaves the index unchanged.
    fn insert(&mut self, p: Point2<f64>) -> Result<PointId, IndexError>;

    /// Removes every point; ids restart at 0. Keeps allocations where it can.
    fn clear(&mut self);

    /// All points in id order.
    fn points(&self) -> &[Point2<f64>];

    /// The nearest point at squared distance `<= max_dist_sq`, if any.
    fn nearest_within(&self, q: &Point2<f64>, max_dist_sq: f64) -> Option<Neighbour>;

    /// Every point at squared distance `<= radius²`, in no particular order.
    fn within_radius(&self, q: &Point2<f64>, radius: f64, out: &mut Vec<Neighbour>);

    /// The `k` nearest points (fewer if the index is smaller), sorted by distance.
    fn k_nearest(&self, q: &Point2<f64>, k: usize, out: &mut Vec<Neighbour>);

    /// [`nearest_within`](Self::nearest_within) and, in the same call, the neighbourhood a
    /// cache of nearest-neighbour answers keeps: when the nearest point (or, with none, the
    /// limit) lies within `max_reach` of `q`, `out` receives exactly what
    /// [`within_radius`](Self::within_radius) gives for the radius `reach + slack` (the same
    /// points in the same order) and that radius is returned; otherwise `out` is left empty
    /// and the radius is `None`. The default runs the two searches ([`nearest_then_around`]);
    /// an index may answer both in one pass, as the quad tree does.
    fn nearest_and_around(
        &self,
        q: &Point2<f64>,
        max_dist_sq: f64,
        slack: f64,
        max_reach: f64,
        out: &mut Vec<Neighbour>,
    ) -> (Option<Neighbour>, Option<f64>) {
        nearest_then_around(self, q, max_dist_sq, slack, max_reach, out)
    }

    /// Takes point `id` out of every later search; its id is not reused and
    /// [`points`](Self::points) still holds it, so other ids stay put. `Some(true)` when it was
    /// held, `Some(false)` when it was not (or is removed already), `None` when this index
    /// cannot remove points (the default): the caller rebuilds the index instead.
    fn remove(&mut self, _id: PointId) -> Option<bool> {
        None
    }

    /// Which state of the point set this is: a value that changes with every insertion,
    /// removal and clear ([`fresh_revision`]; 0 for a new, empty index), so that a caller may
    /// keep what its searches found from one use to the next while it stays the same (the
    /// correspondence caches keep their neighbourhoods from scan to scan while the map does
    /// not change). `None` (the default) where the index does not count: callers then keep
    /// nothing between uses.
    fn revision(&self) -> Option<u64> {
        None
    }

    /// The nearest point, if the index is not empty.
    fn nearest(&self, q: &Point2<f64>) -> Option<Neighbour> {
        self.nearest_within(q, f64::INFINITY)
    }

    /// Number of points.
    fn len(&self) -> usize {
        self.points().len()
    }

    /// True when the index holds no point.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Inserts many points, all or none: if any is refused, nothing is inserted.
    /// Returns the range of the new ids.
    fn extend<P>(&mut self, points: P) -> Result<Range<PointId>, IndexError>
    where
        P: IntoIterator<Item = Point2<f64>>,
        P::IntoIter: Clone,
        Self: Sized,
    {
        let it = points.into_iter();
        let start = self.len();
        for (k, p) in it.clone().enumerate() {
            check_point(&p, start + k)?;
        }
        for p in it {
            self.insert(p)?;
        }
        Ok(start as PointId..self.len() as PointId)
    }
}

/// The oracle: a plain list searched linearly. Every other index is tested against it.
#[derive(Debug, Clone, Default)]
pub struct BruteForce {
    points: Vec<Point2<f64>>,
    /// Per point: taken out of the searches ([`SpatialIndex::remove`]).
    removed: Vec<bool>,
    revision: u64,
}

impl BruteForce {
    /// An empty index.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// The points searches see, with their ids: all but the removed ones.
    fn held(&self) -> impl Iterator<Item = (usize, &Point2<f64>)> {
        self.points
            .iter()
            .enumerate()
            .filter(|(i, _)| !self.removed[*i])
    }
}

impl SpatialIndex for BruteForce {
    fn insert(&mut self, p: Point2<f64>) -> Result<PointId, IndexError> {
        check_point(&p, self.points.len())?;
        self.points.push(p);
        self.removed.push(false);
        self.revision = fresh_revision();
        Ok((self.points.len() - 1) as PointId)
    }

    fn clear(&mut self) {
        self.points.clear();
        self.removed.clear();
        self.revision = fresh_revision();
    }

    fn remove(&mut self, id: PointId) -> Option<bool> {
        let removed = self
            .removed
            .get_mut(id as usize)
            .is_some_and(|r| !std::mem::replace(r, true));
        if removed {
            self.revision = fresh_revision();
        }
        Some(removed)
    }

    fn revision(&self) -> Option<u64> {
        Some(self.revision)
    }

    fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    fn nearest_within(&self, q: &Point2<f64>, max_dist_sq: f64) -> Option<Neighbour> {
        if !(q.x.is_finite() && q.y.is_finite()) {
            return None;
        }
        let mut best: Option<Neighbour> = None;
        for (i, p) in self.held() {
            let d = dist_sq(p, q);
            if d <= max_dist_sq && best.is_none_or(|b| d < b.dist_sq) {
                best = Some(Neighbour {
                    id: i as PointId,
                    point: *p,
                    dist_sq: d,
                });
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
        for (i, p) in self.held() {
            let d = dist_sq(p, q);
            if d <= r2 {
                out.push(Neighbour {
                    id: i as PointId,
                    point: *p,
                    dist_sq: d,
                });
            }
        }
    }

    fn k_nearest(&self, q: &Point2<f64>, k: usize, out: &mut Vec<Neighbour>) {
        out.clear();
        if k == 0 || !(q.x.is_finite() && q.y.is_finite()) {
            return;
        }
        out.extend(self.held().map(|(i, p)| Neighbour {
            id: i as PointId,
            point: *p,
            dist_sq: dist_sq(p, q),
        }));
        out.sort_by(|a, b| a.dist_sq.total_cmp(&b.dist_sq).then(a.id.cmp(&b.id)));
        out.truncate(k);
    }
}
