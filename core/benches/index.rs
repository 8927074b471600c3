//! Spatial-index benchmarks: building by insertion, nearest-neighbour queries and a cache
//! refill (`nearest_and_around`, one pass against two searches), for the quad
//! tree, the kd-tree and (up to 10k points) brute force, sweeping 1k … 1M points of the
//! realistic `laser_scans` layout; and IDC's matching-range rule over one scan's iterations
//! against a map of the room (`matching_range`), the pairing q-idc spends most of its time in.
//!
//! How to run: `cargo bench -p qicp-core --bench index` (a few minutes), or
//! `cargo bench -p qicp-core --bench index -- --test` to run each benchmark once as a smoke test.
//! Filter with a name, e.g. `-- nearest/quadtree`.
//!
//! Queries are the next points of the same seeded stream as the data: fresh sweeps from new
//! poses in the same building, so they lie near its surfaces like a scan being matched.

use criterion::{
    BenchmarkId, Criterion, SamplingMode, Throughput, criterion_group, criterion_main,
};
use qicp_core::testdata::{SplitMix, SyntheticWorld, laser_scans};
use qicp_core::{
    BruteForce, CorrespondenceMetric, KdTree, MatchingRange, Point2, Pose2, QuadTree, Query,
    SpatialIndex, nearest_then_around,
};
use std::hint::black_box;
use std::time::Duration;

const SIZES: [usize; 4] = [1_000, 10_000, 100_000, 1_000_000];
/// Brute force answers a query in O(N): leave it out above this.
const BRUTE_MAX: usize = 10_000;
/// Queries per measured iteration of the nearest-neighbour benchmarks.
const QUERIES: usize = 1_000;
const SEED: u64 = 7;

/// The first `n` points of the stream are the data, the next [`QUERIES`] the queries.
fn workload(n: usize) -> (Vec<Point2<f64>>, Vec<Point2<f64>>) {
    let mut data = laser_scans(n + QUERIES, SEED);
    let queries = data.split_off(n);
    (data, queries)
}

fn build<I: SpatialIndex + Default>(points: &[Point2<f64>]) -> I {
    let mut index = I::default();
    for p in points {
        // The points are finite and within range: insertion cannot fail.
        let _ = index.insert(black_box(*p));
    }
    index
}

fn query_all<I: SpatialIndex>(index: &I, queries: &[Point2<f64>]) -> f64 {
    let mut sum = 0.0;
    for q in queries {
        if let Some(n) = index.nearest(black_box(q)) {
            sum += n.dist_sq;
        }
    }
    sum
}

/// Large builds take a good fraction of a second: a flat sampling of few samples keeps the
/// sweep within minutes.
fn tune<M: criterion::measurement::Measurement>(
    g: &mut criterion::BenchmarkGroup<'_, M>,
    n: usize,
) {
    g.sample_size(if n >= 100_000 { 10 } else { 30 });
    g.sampling_mode(if n >= 100_000 {
        SamplingMode::Flat
    } else {
        SamplingMode::Auto
    });
    g.warm_up_time(Duration::from_millis(500));
    // Ten builds of a million points take 5–15 s: ask for that much rather than be warned.
    g.measurement_time(Duration::from_secs(if n >= 1_000_000 { 15 } else { 2 }));
}

fn insertion(c: &mut Criterion) {
    let mut g = c.benchmark_group("insert");
    for n in SIZES {
        let (data, _) = workload(n);
        tune(&mut g, n);
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::new("quadtree", n), &data, |b, d| {
            b.iter(|| build::<QuadTree>(d));
        });
        g.bench_with_input(BenchmarkId::new("kdtree", n), &data, |b, d| {
            b.iter(|| build::<KdTree>(d));
        });
        if n <= BRUTE_MAX {
            g.bench_with_input(BenchmarkId::new("brute", n), &data, |b, d| {
                b.iter(|| build::<BruteForce>(d));
            });
        }
    }
    g.finish();
}

fn nearest(c: &mut Criterion) {
    let mut g = c.benchmark_group("nearest");
    for n in SIZES {
        let (data, queries) = workload(n);
        tune(&mut g, 0);
        g.throughput(Throughput::Elements(QUERIES as u64));
        let quad: QuadTree = build(&data);
        g.bench_with_input(BenchmarkId::new("quadtree", n), &queries, |b, q| {
            b.iter(|| query_all(&quad, q));
        });
        drop(quad);
        let kd: KdTree = build(&data);
        g.bench_with_input(BenchmarkId::new("kdtree", n), &queries, |b, q| {
            b.iter(|| query_all(&kd, q));
        });
        drop(kd);
        if n <= BRUTE_MAX {
            let brute: BruteForce = build(&data);
            g.bench_with_input(BenchmarkId::new("brute", n), &queries, |b, q| {
                b.iter(|| query_all(&brute, q));
            });
        }
    }
    g.finish();
}

/// A nearest-neighbour cache's refill: the nearest point within 1 m and every point within its
/// distance plus 2 cm, as one call (the quad tree's one traversal) against the two searches
/// it replaces (`nearest_then_around`).
fn nearest_and_around(c: &mut Criterion) {
    let mut g = c.benchmark_group("nearest_and_around");
    for n in [10_000, 100_000] {
        let (data, queries) = workload(n);
        tune(&mut g, 0);
        g.throughput(Throughput::Elements(QUERIES as u64));
        let quad: QuadTree = build(&data);
        let mut out = Vec::new();
        g.bench_with_input(BenchmarkId::new("one-pass", n), &queries, |b, qs| {
            b.iter(|| {
                let mut found = 0;
                for q in qs {
                    let _ = quad.nearest_and_around(black_box(q), 1.0, 0.02, 0.3, &mut out);
                    found += out.len();
                }
                found
            });
        });
        g.bench_with_input(BenchmarkId::new("two-searches", n), &queries, |b, qs| {
            b.iter(|| {
                let mut found = 0;
                for q in qs {
                    let _ = nearest_then_around(&quad, black_box(q), 1.0, 0.02, 0.3, &mut out);
                    found += out.len();
                }
                found
            });
        });
    }
    g.finish();
}

/// Scans matched per measured iteration of [`matching_range`].
const RANGE_SCANS: usize = 20;
/// Iterations per scan, the window narrowing from 15° to 1° and the gate from 1 m to 0.2 m
/// as q-idc's schedule does, the estimate moving a few millimetres each time.
const RANGE_ITERATIONS: usize = 10;

/// The matching-range rule as q-idc runs it: a map of the room seen from 12 poses (every
/// point, about as dense as an IDC map at 2 cm spacing), then scans from new poses paired over
/// [`RANGE_ITERATIONS`] iterations each, from a start 5 cm and 2° off.
fn matching_range(c: &mut Criterion) {
    let room = SyntheticWorld::room();
    let mut r = SplitMix::new(SEED);
    let mut pose = || Pose2::new(r.range(-3.0, 3.0), r.range(-2.5, 2.5), r.range(-3.1, 3.1));
    let mut map = QuadTree::default();
    for k in 0..12 {
        let at = pose();
        for p in room.scan(&at, 0.01, k).points() {
            let _ = map.insert(at.transform_point(p));
        }
    }
    let scans: Vec<(Pose2, Vec<Point2<f64>>)> = (0..RANGE_SCANS as u64)
        .map(|k| {
            let at = pose();
            (at, room.scan(&at, 0.01, 100 + k).points().to_vec())
        })
        .collect();
    let mut g = c.benchmark_group("matching_range");
    tune(&mut g, 0);
    g.throughput(Throughput::Elements(RANGE_SCANS as u64));
    let mut rule = MatchingRange::default();
    let (mut moved, mut pairs) = (Vec::new(), Vec::new());
    g.bench_function(BenchmarkId::new("scan", map.len()), |b| {
        b.iter(|| {
            let mut found = 0;
            for (truth, local) in &scans {
                rule.begin_scan(local);
                for it in 0..RANGE_ITERATIONS {
                    let f = it as f64 / (RANGE_ITERATIONS - 1) as f64;
                    let left = 1.0 - f;
                    let estimate = Pose2::new(
                        truth.x + 0.05 * left,
                        truth.y - 0.03 * left,
                        truth.theta + 2f64.to_radians() * left,
                    );
                    rule.window = 15f64.to_radians() * (1.0f64 / 15.0).powf(f);
                    moved.clear();
                    moved.extend(local.iter().map(|p| estimate.transform_point(p)));
                    let query = Query {
                        local,
                        points: &moved,
                        pose: estimate,
                        max_dist: 1.0 - 0.8 * f,
                    };
                    rule.pair(&map, black_box(&query), &mut pairs);
                    found += pairs.len();
                }
            }
            found
        });
    });
    g.finish();
}

criterion_group!(
    benches,
    insertion,
    nearest,
    nearest_and_around,
    matching_range
);
criterion_main!(benches);
