//! The conformance suite every [`SpatialIndex`] must pass: the same answers as the
//! [`BruteForce`] oracle on seeded data sets chosen to break indexes (uniform, laser-like
//! lines, heavy duplicates, axis-aligned lines, points far outside the first bounds, tiny
//! clusters), refusals of bad points, the empty and one-point cases, and revisions that
//! follow every change of the point set.
//!
//! Behind the `testkit` feature. A new index runs it in its own tests with one macro call:
//!
//! ```ignore
//! qicp_core::index_conformance! { my_index: my_crate::MyIndex }
//! ```

use crate::testdata::{SplitMix, laser_scans, uniform};
use crate::{BruteForce, IndexError, Neighbour, Point2, SpatialIndex};

fn queries(points: &[Point2<f64>], n: usize, seed: u64) -> Vec<Point2<f64>> {
    let mut r = SplitMix::new(seed);
    let mut q: Vec<Point2<f64>> = (0..n)
        .map(|_| Point2::new(r.range(-60.0, 60.0), r.range(-60.0, 60.0)))
        .collect();
    // Queries exactly on stored points and just beside them.
    for p in points.iter().step_by((points.len() / 50).max(1)) {
        q.push(*p);
        q.push(Point2::new(p.x + 1e-7, p.y - 3e-3));
    }
    q
}

fn sorted_dists(v: &[Neighbour]) -> Vec<f64> {
    let mut d: Vec<f64> = v.iter().map(|n| n.dist_sq).collect();
    d.sort_by(f64::total_cmp);
    d
}

fn sorted_ids(v: &[Neighbour]) -> Vec<u32> {
    let mut ids: Vec<u32> = v.iter().map(|n| n.id).collect();
    ids.sort_unstable();
    ids
}

/// Builds `I` and the oracle on `points` and compares every kind of query: nearest,
/// nearest within four limits, radius queries of four radii and k-nearest for k = 1, 3, 10,
/// at 300 seeded queries and on and beside stored points.
pub fn check_against_oracle<I: SpatialIndex + Default>(points: &[Point2<f64>], seed: u64) {
    let (index, oracle) = build::<I>(points);
    assert_eq!(index.len(), points.len());
    compare(&index, &oracle, points, seed);
}

/// `I` and the oracle, each with `points` inserted in order.
fn build<I: SpatialIndex + Default>(points: &[Point2<f64>]) -> (I, BruteForce) {
    let mut index = I::default();
    let mut oracle = BruteForce::new();
    for p in points {
        let a = index.insert(*p).expect("the conformance case is valid");
        let b = oracle.insert(*p).expect("the conformance case is valid");
        assert_eq!(a, b, "ids are insertion order");
    }
    (index, oracle)
}

/// Removes a seeded third of `points` from `I` and from the oracle, then a point already
/// removed again, then inserts the removed points' coordinates anew (into the emptied
/// buckets and duplicate chains): every query answers as the oracle's after each step. An
/// index that cannot remove points ([`SpatialIndex::remove`] gives `None`) must say so for
/// every id, and is left at that.
pub fn check_removal<I: SpatialIndex + Default>(points: &[Point2<f64>], seed: u64) {
    let (mut index, mut oracle) = build::<I>(points);
    let mut r = SplitMix::new(seed ^ 0x5eed);
    let doomed: Vec<u32> = (0..points.len() as u32)
        .filter(|_| r.range(0.0, 3.0) < 1.0)
        .collect();
    let Some(&first) = doomed.first() else {
        return;
    };
    if index.remove(first).is_none() {
        assert!(
            doomed.iter().all(|&id| index.remove(id).is_none()),
            "an index removes all points or none"
        );
        return;
    }
    assert_eq!(oracle.remove(first), Some(true));
    for &id in &doomed[1..] {
        assert_eq!(index.remove(id), Some(true), "point {id} was held");
        assert_eq!(oracle.remove(id), Some(true));
    }
    assert_eq!(index.remove(first), Some(false), "a point is removed once");
    assert_eq!(
        index.remove(points.len() as u32),
        Some(false),
        "no such point"
    );
    assert_eq!(index.points(), points, "ids stay put");
    compare(&index, &oracle, points, seed);
    let mut all = points.to_vec();
    for &id in &doomed {
        let p = points[id as usize];
        let a = index.insert(p).expect("a finite point");
        assert_eq!(a, oracle.insert(p).expect("a finite point"));
        all.push(p);
    }
    compare(&index, &oracle, &all, seed + 1);
}

/// Every kind of query of `index` against the oracle's (see [`check_against_oracle`]).
fn compare<I: SpatialIndex>(index: &I, oracle: &BruteForce, points: &[Point2<f64>], seed: u64) {
    assert_eq!(index.points(), oracle.points());
    let (mut got, mut want) = (Vec::new(), Vec::new());
    for q in queries(points, 300, seed) {
        let (a, b) = (index.nearest(&q), oracle.nearest(&q));
        assert_eq!(a.map(|n| n.dist_sq), b.map(|n| n.dist_sq), "nearest of {q}");
        if let Some(a) = a {
            assert_eq!(points[a.id as usize], a.point, "id and point agree");
        }
        for limit in [0.0, 0.01, 0.25, 4.0] {
            let (a, b) = (
                index.nearest_within(&q, limit),
                oracle.nearest_within(&q, limit),
            );
            assert_eq!(
                a.map(|n| n.dist_sq),
                b.map(|n| n.dist_sq),
                "nearest_within {limit} of {q}"
            );
        }
        for radius in [0.0, 0.05, 0.5, 3.0] {
            index.within_radius(&q, radius, &mut got);
            oracle.within_radius(&q, radius, &mut want);
            assert_eq!(
                sorted_ids(&got),
                sorted_ids(&want),
                "within {radius} of {q}"
            );
        }
        for (limit, slack, max_reach) in [
            (0.25, 0.05, 0.3),
            (4.0, 0.0, 1.0),
            (0.01, 0.5, 0.05),
            // No point within the limit, whose disc is still searched.
            (0.01, 0.02, 0.3),
            (0.0, 0.0, 0.0),
            (f64::INFINITY, 0.01, f64::INFINITY),
        ] {
            let a = index.nearest_and_around(&q, limit, slack, max_reach, &mut got);
            let b =
                crate::index::nearest_then_around(oracle, &q, limit, slack, max_reach, &mut want);
            assert_eq!(
                (a.0.map(|n| n.dist_sq), a.1),
                (b.0.map(|n| n.dist_sq), b.1),
                "nearest_and_around {limit} {slack} {max_reach} of {q}"
            );
            assert_eq!(sorted_ids(&got), sorted_ids(&want), "around {q}");
            // The same points in the same order as the index's own two searches.
            let c =
                crate::index::nearest_then_around(index, &q, limit, slack, max_reach, &mut want);
            assert_eq!((a.0.map(|n| n.id), a.1), (c.0.map(|n| n.id), c.1));
            assert_eq!(got, want, "in within_radius's order, around {q}");
        }
        for k in [1, 3, 10] {
            index.k_nearest(&q, k, &mut got);
            oracle.k_nearest(&q, k, &mut want);
            assert_eq!(
                got.iter().map(|n| n.dist_sq).collect::<Vec<_>>(),
                want.iter().map(|n| n.dist_sq).collect::<Vec<_>>(),
                "{k} nearest of {q}"
            );
            assert!(
                got.windows(2).all(|w| w[0].dist_sq <= w[1].dist_sq),
                "sorted"
            );
        }
    }
    // Equal distance sets also for the radius query.
    index.within_radius(&Point2::new(0.0, 0.0), 10.0, &mut got);
    oracle.within_radius(&Point2::new(0.0, 0.0), 10.0, &mut want);
    assert_eq!(sorted_dists(&got), sorted_dists(&want));
}

/// Heavy duplicates: 3,000 draws from 40 points, and one scan inserted 20 times (a robot
/// standing still).
pub fn duplicates(seed: u64) -> Vec<Point2<f64>> {
    let base = uniform(40, 10.0, seed);
    let mut r = SplitMix::new(seed + 1);
    let mut pts = Vec::new();
    for _ in 0..3000 {
        pts.push(base[(r.next_u64() % base.len() as u64) as usize]);
    }
    // A robot standing still: one scan inserted over and over.
    let scan = laser_scans(181, seed + 2);
    for _ in 0..20 {
        pts.extend_from_slice(&scan);
    }
    pts
}

/// Two axis-aligned lines of points (kiddo's weak spot).
pub fn axis_aligned_lines() -> Vec<Point2<f64>> {
    let mut pts = Vec::new();
    for k in 0..400 {
        pts.push(Point2::new(5.0, k as f64 * 0.05));
        pts.push(Point2::new(k as f64 * 0.05, -2.0));
    }
    pts
}

/// Points spread over ten orders of magnitude, far outside the first bounds.
pub fn far_outside(seed: u64) -> Vec<Point2<f64>> {
    let mut pts = uniform(500, 2.0, seed);
    let mut r = SplitMix::new(seed);
    for _ in 0..500 {
        let s = 10f64.powf(r.range(0.0, 6.0));
        pts.push(Point2::new(r.range(-s, s), r.range(-s, s)));
    }
    pts.push(Point2::new(-2.0e9, 2.0e9));
    pts
}

/// Non-finite and out-of-range points are refused, `extend` is all or nothing, a NaN query
/// finds nothing.
pub fn refuses_bad_points<I: SpatialIndex + Default>() {
    let mut index = I::default();
    index
        .insert(Point2::new(1.0, 1.0))
        .expect("the conformance case is valid");
    for bad in [
        Point2::new(f64::NAN, 0.0),
        Point2::new(0.0, f64::INFINITY),
        Point2::new(f64::NEG_INFINITY, f64::NAN),
    ] {
        assert!(matches!(
            index.insert(bad),
            Err(IndexError::NonFinite { .. })
        ));
    }
    assert!(matches!(
        index.insert(Point2::new(1e300, 0.0)),
        Err(IndexError::OutOfRange { .. })
    ));
    // extend is all or nothing.
    let batch = vec![Point2::new(2.0, 2.0), Point2::new(f64::NAN, 1.0)];
    assert!(index.extend(batch).is_err());
    assert_eq!(index.len(), 1, "a refused point leaves the index unchanged");
    assert_eq!(
        index
            .nearest(&Point2::new(0.0, 0.0))
            .expect("the conformance case is valid")
            .id,
        0
    );
    // A NaN query finds nothing rather than something wrong.
    assert!(index.nearest(&Point2::new(f64::NAN, 0.0)).is_none());
    let ids = index
        .extend(vec![Point2::new(2.0, 2.0), Point2::new(3.0, 3.0)])
        .expect("the conformance case is valid");
    assert_eq!(ids, 1..3);
}

/// Queries on an empty and a one-point index; ids restart after `clear`.
pub fn empty_and_single<I: SpatialIndex + Default>() {
    let mut index = I::default();
    let q = Point2::new(0.5, 0.5);
    let mut out = vec![];
    assert!(index.is_empty());
    assert!(index.nearest(&q).is_none());
    index.within_radius(&q, 10.0, &mut out);
    assert!(out.is_empty());
    index.k_nearest(&q, 3, &mut out);
    assert!(out.is_empty());
    index
        .insert(Point2::new(1.5, 0.5))
        .expect("the conformance case is valid");
    assert_eq!(
        index
            .nearest(&q)
            .expect("the conformance case is valid")
            .dist_sq,
        1.0
    );
    assert!(index.nearest_within(&q, 0.99).is_none());
    assert!(
        index.nearest_within(&q, 1.0).is_some(),
        "the limit is inclusive"
    );
    index.k_nearest(&q, 3, &mut out);
    assert_eq!(out.len(), 1);
    index.clear();
    assert!(index.is_empty() && index.nearest(&q).is_none());
    assert_eq!(
        index.insert(q).expect("the conformance case is valid"),
        0,
        "ids restart after clear"
    );
}

/// An index that counts its revisions ([`SpatialIndex::revision`]) takes a new one at every
/// change of its point set (an insertion, a removal of a held point, a clear) and keeps it
/// through refused points, removals of points it does not hold, and searches; a new index
/// is at 0. One that does not count says `None` throughout.
pub fn revisions<I: SpatialIndex + Default>() {
    let mut index = I::default();
    if index.revision().is_none() {
        index.insert(Point2::new(1.0, 2.0)).expect("a finite point");
        index.clear();
        assert_eq!(index.revision(), None, "an index counts always or never");
        return;
    }
    assert_eq!(index.revision(), Some(0), "a new index");
    let mut seen = vec![index.revision()];
    let mut step = |index: &I, what: &str, changed: bool| {
        let r = index.revision();
        assert!(r.is_some(), "{what}: an index counts always or never");
        assert_eq!(!seen.contains(&r), changed, "{what}: {r:?} after {seen:?}");
        seen.push(r);
    };
    index.insert(Point2::new(1.0, 2.0)).expect("a finite point");
    step(&index, "an insertion", true);
    index.insert(Point2::new(3.0, 2.0)).expect("a finite point");
    step(&index, "a second insertion", true);
    assert!(index.insert(Point2::new(f64::NAN, 0.0)).is_err());
    step(&index, "a refused point", false);
    let _ = index.nearest_within(&Point2::new(1.0, 2.0), 1.0);
    let mut out = Vec::new();
    index.within_radius(&Point2::new(1.0, 2.0), 5.0, &mut out);
    step(&index, "searches", false);
    if index.remove(0) == Some(true) {
        step(&index, "a removal", true);
        assert_eq!(index.remove(0), Some(false));
        step(&index, "a removal of a point already out", false);
    }
    index.clear();
    step(&index, "a clear", true);
    index.insert(Point2::new(1.0, 2.0)).expect("a finite point");
    step(&index, "an insertion after a clear", true);
}

/// Generates the conformance tests (`#[test]` functions, one module per index) for each
/// `name: Type` given; `Type` must implement [`SpatialIndex`] and `Default`.
#[macro_export]
macro_rules! index_conformance {
    ($($name:ident: $index:ty),* $(,)?) => {$(
        mod $name {
            use $crate::conformance::*;
            use $crate::testdata::{laser_scans, uniform};
            #[test] fn uniform_points() { for s in 0..3 { check_against_oracle::<$index>(&uniform(5000, 100.0, s), s) } }
            #[test] fn laser_like_lines() { check_against_oracle::<$index>(&laser_scans(20_000, 7), 7) }
            #[test] fn heavy_duplicates() { check_against_oracle::<$index>(&duplicates(3), 3) }
            #[test] fn axis_aligned() { check_against_oracle::<$index>(&axis_aligned_lines(), 4) }
            #[test] fn far_outside_first_bounds() { check_against_oracle::<$index>(&far_outside(5), 5) }
            #[test] fn tiny_clusters() { check_against_oracle::<$index>(&uniform(2000, 1e-5, 6), 6) }
            #[test] fn removal_uniform() { check_removal::<$index>(&uniform(3000, 50.0, 8), 8) }
            #[test] fn removal_laser_like() { check_removal::<$index>(&laser_scans(8_000, 9), 9) }
            #[test] fn removal_heavy_duplicates() { check_removal::<$index>(&duplicates(10), 10) }
            #[test] fn removal_axis_aligned() { check_removal::<$index>(&axis_aligned_lines(), 12) }
            #[test] fn removal_tiny_clusters() { check_removal::<$index>(&uniform(2000, 1e-5, 11), 11) }
            #[test] fn bad_points() { refuses_bad_points::<$index>() }
            #[test] fn empty_and_single_point() { empty_and_single::<$index>() }
            #[test] fn revisions_follow_every_change() { revisions::<$index>() }
        }
    )*};
}
