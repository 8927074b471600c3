//! The correspondence plug-in point: how scan points are paired with reference points,
//! expressed as queries on any [`SpatialIndex`].

use crate::Pose2;
use crate::index::{Neighbour, PointId, SpatialIndex, dist_sq};
use nalgebra::Point2;

/// A scan point paired with a reference point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Index of the scan point (into [`Scan::points`](crate::Scan::points)).
    pub scan: u32,
    /// Id of the reference point.
    pub reference: PointId,
    /// Squared distance between them under the current estimate.
    pub dist_sq: f64,
}

/// One correspondence search: the scan under the current estimate.
#[derive(Debug, Clone, Copy)]
pub struct Query<'a> {
    /// Scan points in the scan's own (laser) frame.
    pub local: &'a [Point2<f64>],
    /// The same points moved into the reference frame by `pose`.
    pub points: &'a [Point2<f64>],
    /// Current estimate of the scan's pose in the reference frame.
    pub pose: Pose2,
    /// Pairs farther apart than this are outliers and are not formed (m).
    pub max_dist: f64,
}

/// Pairs scan points with reference points.
pub trait CorrespondenceMetric {
    /// Called once per scan, before its first [`pair`](Self::pair), with the scan's points in
    /// its own frame. Metrics that index the scan itself build that index here.
    fn begin_scan(&mut self, _local: &[Point2<f64>]) {}

    /// Fills `out` with the pairs for this estimate.
    fn pair<I: SpatialIndex>(&mut self, reference: &I, query: &Query<'_>, out: &mut Vec<Pair>);
}

/// The closest-point rule: each scan point pairs with its nearest reference point.
#[derive(Debug, Clone, Copy, Default)]
pub struct ClosestPoint;

impl CorrespondenceMetric for ClosestPoint {
    fn pair<I: SpatialIndex>(&mut self, reference: &I, query: &Query<'_>, out: &mut Vec<Pair>) {
        out.clear();
        let limit = query.max_dist * query.max_dist;
        for (k, p) in query.points.iter().enumerate() {
            if let Some(n) = reference.nearest_within(p, limit) {
                out.push(Pair {
                    scan: k as u32,
                    reference: n.id,
                    dist_sq: n.dist_sq,
                });
            }
        }
    }
}

/// Slack of the matching-range rule's search radius beyond r·window (m).
const RANGE_RULE_MARGIN: f64 = 0.1;

/// The matching-range rule searches a little farther than it needs (m), so that its
/// candidates still cover the next iterations' searches while the estimate moves less than
/// this.
const RANGE_RULE_CACHE_SLACK: f64 = 0.05;

/// One scan point's cached radius search: every reference point within `radius` of `center`.
#[derive(Debug, Clone, Default)]
struct CachedSearch {
    center: Point2<f64>,
    radius: f64,
    found: Vec<crate::Neighbour>,
    /// [`NearestCache`] only: the slack of this entry's next fill (m).
    slack: f64,
}

/// Identity of a reference for the caches: its [revision](SpatialIndex::revision) where the
/// index counts them, and its length and first point. The caches are kept while the
/// reference does not change: from scan to scan where the index counts its revisions (most
/// scans leave the map as it was), otherwise between the iterations of one scan.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Identity {
    revision: Option<u64>,
    len: usize,
    first: Point2<f64>,
}

impl Identity {
    fn of<I: SpatialIndex>(reference: &I) -> Self {
        Self {
            revision: reference.revision(),
            len: reference.len(),
            first: reference
                .points()
                .first()
                .copied()
                .unwrap_or_else(Point2::origin),
        }
    }
}

/// What a new scan keeps of a cache filled from `cached_for`: everything while a reference
/// that counts its revisions stays at the one it had (checked at the next search), nothing
/// from one that does not count (another object may have taken its length and first point,
/// or it may have changed without changing them).
fn kept_for_next_scan(cached_for: Option<Identity>) -> Option<Identity> {
    cached_for.filter(|c| c.revision.is_some())
}

/// Nearest-neighbour searches cached while the reference stays the same (between the
/// iterations of one scan, and from scan to scan where the index counts its revisions; see
/// [`Identity`]), one entry per scan point. A miss asks the index for the nearest point and then keeps every point within that
/// distance plus a slack; while the scan point stays inside that disc, the
/// answer is found among the kept points alone, with the same distance as a fresh search
/// (any point nearer than the kept answer lies inside the disc). Late iterations move the
/// points by millimetres, so most of their queries become a scan of a dozen points. The slack
/// adapts per entry between [`MIN_SLACK`](NearestCache::MIN_SLACK) and
/// [`SLACK`](NearestCache::SLACK) so that a fill keeps about 8-32 points: a q-wsm map that
/// holds every point of every relevant scan put hundreds into a 5 cm slack.
#[derive(Debug, Clone, Default)]
struct NearestCache {
    entries: Vec<CachedSearch>,
    cached_for: Option<Identity>,
}

impl NearestCache {
    /// How far a point may move and still be answered from its entry (m).
    const SLACK: f64 = 0.05;
    /// Smallest slack an entry adapts down to (m).
    const MIN_SLACK: f64 = 0.005;
    /// An entry that kept more points than this halves its slack for its next fill; one
    /// that kept fewer than [`FEW`](Self::FEW) doubles it (up to [`SLACK`](Self::SLACK)).
    const MANY: usize = 32;
    /// See [`MANY`](Self::MANY).
    const FEW: usize = 8;
    /// Neighbourhoods wider than this are not kept (m): far from everything, a point's
    /// disc would hold too many points to be worth scanning.
    const MAX_RADIUS: f64 = 0.3;

    /// Forgets every entry.
    #[cfg(test)]
    fn reset(&mut self) {
        self.cached_for = None;
    }

    /// A new scan: the entries stay where the reference counts its revisions
    /// ([`kept_for_next_scan`]); the next search checks it is still the same.
    fn next_scan(&mut self) {
        self.cached_for = kept_for_next_scan(self.cached_for);
    }

    /// Prepares for `n` scan points searched in `reference`; entries from another reference
    /// are dropped.
    fn prepare<I: SpatialIndex>(&mut self, reference: &I, n: usize) {
        let identity = Identity::of(reference);
        if self.cached_for != Some(identity) {
            for e in &mut self.entries {
                e.radius = -1.0;
            }
            self.cached_for = Some(identity);
        }
        if self.entries.len() < n {
            self.entries.resize_with(n, || CachedSearch {
                radius: -1.0,
                slack: Self::SLACK,
                ..CachedSearch::default()
            });
        }
    }

    /// [`SpatialIndex::nearest_within`] for scan point `k` at `p` (call [`prepare`] first).
    ///
    /// [`prepare`]: Self::prepare
    fn nearest_within<I: SpatialIndex>(
        &mut self,
        reference: &I,
        k: usize,
        p: &Point2<f64>,
        max_dist_sq: f64,
    ) -> Option<Neighbour> {
        let entry = &mut self.entries[k];
        if entry.radius >= 0.0 {
            // Every reference point within `inner` of p is in the entry.
            let inner = entry.radius - dist_sq(&entry.center, p).sqrt();
            if inner > 0.0 {
                // A hair of margin so rounding never claims a point the disc may not hold.
                let inner_sq = inner * inner * (1.0 - 1e-9);
                // The first nearest kept point, then the gate: the same answer as gating
                // first, with one comparison per point.
                let (mut best_d, mut best_k) = (f64::INFINITY, usize::MAX);
                for (k, n) in entry.found.iter().enumerate() {
                    let d = dist_sq(&n.point, p);
                    if d < best_d {
                        (best_d, best_k) = (d, k);
                    }
                }
                // No kept point (an empty disc) leaves `best_k` past the end: no answer here.
                let best = entry
                    .found
                    .get(best_k)
                    .filter(|_| best_d <= max_dist_sq)
                    .map(|n| Neighbour {
                        id: n.id,
                        point: n.point,
                        dist_sq: best_d,
                    });
                match best {
                    Some(b) if b.dist_sq <= inner_sq => return Some(b),
                    None if max_dist_sq <= inner_sq => return None,
                    _ => {}
                }
            }
        }
        // The nearest point, and every point within its distance plus the slack, in one
        // search where the index can (the quad tree can).
        let (nearest, radius) = reference.nearest_and_around(
            p,
            max_dist_sq,
            entry.slack,
            Self::MAX_RADIUS,
            &mut entry.found,
        );
        if let Some(radius) = radius {
            entry.center = *p;
            entry.radius = radius;
            // Dense maps fill a wide disc with hundreds of points, sparse ones leave a narrow
            // one empty: each entry (the same beam scan after scan) finds its own width.
            if entry.found.len() > Self::MANY {
                entry.slack = (entry.slack * 0.5).max(Self::MIN_SLACK);
            } else if entry.found.len() < Self::FEW {
                entry.slack = (entry.slack * 2.0).min(Self::SLACK);
            }
        } else {
            entry.radius = -1.0;
        }
        nearest
    }
}

/// IDC's matching-range rule (Lu & Milios 1997, Sec. 4.2): in polar coordinates about the
/// sensor, a scan point at (r, φ) pairs with the reference point inside the angular window
/// φ ± `window` whose range is closest to r; of candidates with the same |Δr| the one with the
/// lowest [`PointId`] wins, so the pairs do not depend on the index's search order. Like every
/// pair it must lie within the outlier gate `max_dist` of the point: in a symmetric corridor
/// the opposite wall has the same range inside a wide window.
///
/// The candidates of each scan point come from a radius search that is kept between calls
/// while the reference stays the same (within one scan, and from scan to scan where the index
/// counts its [revisions](SpatialIndex::revision)): while the point has moved less than the
/// search's slack it is filtered again instead of repeated, with the same answer as a fresh
/// search.
#[derive(Debug, Clone, Default)]
pub struct MatchingRange {
    /// Half-width of the angular window (rad).
    pub window: f64,
    cache: Vec<CachedSearch>,
    /// Identity of the reference the cache was filled from.
    cached_for: Option<Identity>,
}

impl MatchingRange {
    /// The rule with the given window.
    #[must_use]
    pub fn new(window: f64) -> Self {
        Self {
            window,
            ..Self::default()
        }
    }
}

impl CorrespondenceMetric for MatchingRange {
    fn begin_scan(&mut self, _local: &[Point2<f64>]) {
        self.cached_for = kept_for_next_scan(self.cached_for);
    }

    fn pair<I: SpatialIndex>(&mut self, reference: &I, query: &Query<'_>, out: &mut Vec<Pair>) {
        out.clear();
        // A cache filled from another reference (or before it changed) is dropped.
        let identity = Identity::of(reference);
        if self.cached_for != Some(identity) {
            for c in &mut self.cache {
                c.radius = -1.0;
            }
            self.cached_for = Some(identity);
        }
        if self.cache.len() < query.points.len() {
            self.cache.resize_with(query.points.len(), || CachedSearch {
                radius: -1.0,
                ..CachedSearch::default()
            });
        }
        let o = Point2::new(query.pose.x, query.pose.y);
        let cos_window = self.window.min(std::f64::consts::PI).cos();
        for (k, p) in query.points.iter().enumerate() {
            let d = p - o;
            let r = d.norm();
            if r == 0.0 {
                continue;
            }
            let u = d / r;
            // The best candidate (nearly equal range, inside the window) lies within about
            // r·window of p; farther ones differ in range and lose anyway.
            let reach = query
                .max_dist
                .min(r * self.window.min(1.0) + RANGE_RULE_MARGIN);
            let search = &mut self.cache[k];
            // The cached search covers this one when its disc holds the disc of radius reach
            // about p; it is repeated when p left it. When it is more than twice too wide
            // (the window shrank) it is cut down to the smaller disc about the same centre,
            // which still holds every point within reach of p (found points carry their
            // squared distance to the centre).
            let off_centre = dist_sq(&search.center, p).sqrt();
            if off_centre + reach + 1e-9 > search.radius {
                search.center = *p;
                search.radius = reach + RANGE_RULE_CACHE_SLACK;
                reference.within_radius(p, search.radius, &mut search.found);
            } else if 2.0 * reach < search.radius {
                search.radius = (off_centre + reach + RANGE_RULE_CACHE_SLACK).min(search.radius);
                let keep = search.radius * search.radius;
                search.found.retain(|n| n.dist_sq <= keep);
            }
            let reach_sq = reach * reach;
            let mut best: Option<(f64, PointId, f64)> = None;
            // Squared ranges that could still beat the best |Δr|, as a band's middle and
            // half-width with a little slack so the exact test below decides every close
            // call: most candidates are dropped by the band without a square root.
            let (mut band_mid, mut band_half) = (0.0, f64::INFINITY);
            for n in &search.found {
                let d2 = dist_sq(&n.point, p);
                let e = n.point - o;
                let re_sq = e.norm_squared();
                // One branch, rarely taken, for both tests, each a number at most 0 where it
                // passes (a difference of finite floats is 0 only where they are equal, so
                // the reach test is exact). Most candidates fail one of them, in no order a
                // branch predictor could learn: a branch per test (the compiler makes one
                // even of `&`) made q-idc's whole Intel run 6 % slower.
                let outside_reach = d2 - reach_sq;
                let outside_band = (re_sq - band_mid).abs() - band_half;
                // Written out: `f64::max`'s care for NaN, which neither can be, costs a blend.
                let outside = if outside_reach > outside_band {
                    outside_reach
                } else {
                    outside_band
                };
                // A NaN (a pose that is not finite) pairs nothing.
                if outside > 0.0 || outside.is_nan() {
                    continue;
                }
                let re = re_sq.sqrt();
                // Inside the window: the bearing of e is within ±window of the bearing of d.
                if re * cos_window > e.dot(&u) {
                    continue;
                }
                let dr = (re - r).abs();
                // Equal |Δr| goes to the lowest id, so every index pairs alike: logged ranges
                // are quantized (1 cm in CARMEN logs) and exact ties are common.
                if best.is_none_or(|b| dr < b.0 || (dr == b.0 && n.id < b.1)) {
                    best = Some((dr, n.id, d2));
                    // |re − r| < dr ⇔ (r − dr)² < re² < (r + dr)² for re ≥ 0.
                    let lo_sq = if dr < r {
                        (r - dr) * (r - dr) * (1.0 - 1e-9)
                    } else {
                        -1.0
                    };
                    let hi_sq = (r + dr) * (r + dr) * (1.0 + 1e-9);
                    (band_mid, band_half) = (0.5 * (lo_sq + hi_sq), 0.5 * (hi_sq - lo_sq));
                }
            }
            if let Some((_, id, d2)) = best {
                out.push(Pair {
                    scan: k as u32,
                    reference: id,
                    dist_sq: d2,
                });
            }
        }
    }
}

/// Mutual nearest neighbours (paper Alg. 2): scan point p pairs with its nearest reference
/// point cA only if p is in turn cA's nearest point of the scan (searched in a temporary index
/// `S` of the scan built once per scan in the scan's own frame).
///
/// Guard: when fewer than [`MutualNearest::MIN_PAIRS`] pairs are mutual (a few posts in view
/// with a large initial error), the closest-point pairs are used for that iteration instead,
/// so sparse scenes still converge; once the estimate is close the mutual pairs take over.
#[derive(Debug, Clone, Default)]
pub struct MutualNearest<S> {
    scan_index: S,
    closest: Vec<Pair>,
    /// Searches in the reference, per scan point.
    in_reference: NearestCache,
    /// Searches in the scan index, per scan point (for that point's reference partner).
    in_scan: NearestCache,
}

impl<S> MutualNearest<S> {
    /// Fewest mutual pairs that are used as they are.
    pub const MIN_PAIRS: usize = 12;
}

impl<S: SpatialIndex> CorrespondenceMetric for MutualNearest<S> {
    fn begin_scan(&mut self, local: &[Point2<f64>]) {
        // paper Alg. 2: Qscan = temporary quad tree for all scan points p ∈ st
        self.scan_index.clear();
        for p in local {
            // Scan points are finite by construction; a refused one simply cannot pair.
            let _ = self.scan_index.insert(*p);
        }
        // The map's searches stay valid while the map does; the scan's index was just
        // rebuilt, which a counting index tells by its revision.
        self.in_reference.next_scan();
        self.in_scan.next_scan();
    }

    fn pair<I: SpatialIndex>(&mut self, reference: &I, query: &Query<'_>, out: &mut Vec<Pair>) {
        out.clear();
        self.closest.clear();
        let limit = query.max_dist * query.max_dist;
        self.in_reference.prepare(reference, query.points.len());
        self.in_scan.prepare(&self.scan_index, query.points.len());
        for (k, p) in query.points.iter().enumerate() {
            // cA = nearest neighbour of p in Qt
            let Some(ca) = self.in_reference.nearest_within(reference, k, p, limit) else {
                continue;
            };
            let pair = Pair {
                scan: k as u32,
                reference: ca.id,
                dist_sq: ca.dist_sq,
            };
            self.closest.push(pair);
            // cB = nearest neighbour of cA in Qscan (taken in the scan frame)
            let ca_local = query.pose.inverse_transform_point(&ca.point);
            let Some(cb) =
                self.in_scan
                    .nearest_within(&self.scan_index, k, &ca_local, f64::INFINITY)
            else {
                continue;
            };
            // if cB = p: a tie at the same distance counts as p too
            let mutual = cb.id as usize == k || cb.dist_sq >= dist_sq(&query.local[k], &ca_local);
            if mutual {
                out.push(pair);
            }
        }
        if out.len() < Self::MIN_PAIRS {
            std::mem::swap(out, &mut self.closest);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::QuadTree;

    /// A grid of `n`×`n` points `step` apart, from the origin.
    fn grid(n: usize, step: f64) -> QuadTree {
        let mut t = QuadTree::default();
        for i in 0..n {
            for j in 0..n {
                t.insert(Point2::new(i as f64 * step, j as f64 * step))
                    .expect("a finite point");
            }
        }
        t
    }

    /// Queries near the middle of a grid, `rounds` scans of a few iterations each, every
    /// answer compared with a fresh search.
    fn run(cache: &mut NearestCache, map: &QuadTree, centre: f64, rounds: usize) {
        let queries: Vec<Point2<f64>> = (0..10)
            .map(|k| Point2::new(centre + 0.0007 * k as f64, centre - 0.0011 * k as f64))
            .collect();
        for round in 0..rounds {
            cache.reset();
            cache.prepare(map, queries.len());
            for it in 0..4 {
                let shift = 0.0003 * (round * 4 + it) as f64;
                for (k, q) in queries.iter().enumerate() {
                    let p = Point2::new(q.x + shift, q.y - 0.5 * shift);
                    let got = cache.nearest_within(map, k, &p, 0.04);
                    let want = map.nearest_within(&p, 0.04);
                    assert_eq!(got.map(|n| n.dist_sq), want.map(|n| n.dist_sq));
                }
            }
        }
    }

    /// An entry that holds an empty disc (nothing within a gate) answers a later query with no
    /// gate by a fresh search, not from its empty list.
    #[test]
    fn an_empty_cached_disc_asked_without_a_gate_searches_afresh() {
        let mut map = QuadTree::default();
        map.insert(Point2::new(5.0, 0.0)).expect("a finite point");
        let mut cache = NearestCache::default();
        cache.prepare(&map, 1);
        let p = Point2::origin();
        assert_eq!(cache.nearest_within(&map, 0, &p, 0.01), None);
        let got = cache.nearest_within(&map, 0, &p, f64::INFINITY);
        assert_eq!(got.map(|n| n.dist_sq), Some(25.0));
    }

    /// In a dense map an entry's slack narrows to the floor (a 5 cm slack would keep thousands
    /// of points of a 2 mm grid); in a sparse one it widens back to the ceiling. Answers equal
    /// fresh searches throughout.
    #[test]
    fn the_slack_follows_the_density_and_answers_stay_exact() {
        let mut cache = NearestCache::default();
        let dense = grid(150, 0.002);
        run(&mut cache, &dense, 0.15, 8);
        assert!(
            cache
                .entries
                .iter()
                .all(|e| e.slack == NearestCache::MIN_SLACK),
            "{:?}",
            cache.entries.iter().map(|e| e.slack).collect::<Vec<_>>()
        );
        let sparse = grid(20, 0.15);
        run(&mut cache, &sparse, 1.5, 8);
        assert!(
            cache.entries.iter().all(|e| e.slack == NearestCache::SLACK),
            "{:?}",
            cache.entries.iter().map(|e| e.slack).collect::<Vec<_>>()
        );
    }
}
