//! The correlative look-ups of re-anchoring on a revisit (`matchers/src/revisit.rs`): the
//! exhaustive search of a ±1 m, ±3° window (`search_among`) against the bounded one
//! (`search_over`, the same answer above its threshold), once where a pose of the window
//! reaches the threshold and once where none does (the usual case on new ground), and the
//! score of one pose without drawing the raster (`score_among`).
//!
//! How to run: `cargo bench -p qicp-matchers --bench correlative` (under a minute), or with
//! `-- --test` to run each benchmark once as a smoke test.
//!
//! The map is a room seen from eight seeded poses (the old map) and the scan one more view of
//! it, looked up 0.45 m and 1.5° off, as a revisit with that much drift would be.

use criterion::{Criterion, criterion_group, criterion_main};
use qicp_core::testdata::{SplitMix, SyntheticWorld};
use qicp_core::{Pose2, QuadTree, Reference, SpatialIndex};
use qicp_matchers::correlative::{CorrelativeParams, CorrelativeSearch};
use std::hint::black_box;

fn look_ups(c: &mut Criterion) {
    let room = SyntheticWorld::room();
    let mut rng = SplitMix::new(11);
    let mut reference = Reference::new(QuadTree::default());
    for k in 0..8 {
        let at = Pose2::new(
            rng.range(-1.5, 1.5),
            rng.range(-0.5, 0.5),
            rng.range(-0.5, 0.5),
        );
        let scan = room.scan(&at, 0.01, k + 1);
        reference.insert_scan(&scan, &at, None).expect("finite");
    }
    let below = u32::try_from(reference.index().len()).expect("small map");
    let truth = Pose2::new(0.3, 0.1, 0.2);
    let scan = room.scan(&truth, 0.01, 99);
    let drifted = Pose2::new(0.45, -0.3, 1.5f64.to_radians()) * truth;
    // Re-anchoring's window at the default raster.
    let mut search = CorrelativeSearch::new(CorrelativeParams {
        window_xy: 1.0,
        window_deg: 3.0,
        ..CorrelativeParams::default()
    });
    let (best, _) = search
        .search_among(&reference, scan.points(), &drifted, Some(below))
        .expect("the room explains the scan");
    let mut group = c.benchmark_group("correlative");
    group.bench_function("search_among", |b| {
        b.iter(|| search.search_among(&reference, black_box(scan.points()), &drifted, Some(below)));
    });
    // A threshold the best pose reaches, and one no pose does.
    for (case, min_score) in [
        ("reached", best.score - 0.05),
        ("not_reached", best.score + 0.01),
    ] {
        group.bench_function(format!("search_over/{case}"), |b| {
            b.iter(|| {
                search.search_over(
                    &reference,
                    black_box(scan.points()),
                    &drifted,
                    Some(below),
                    min_score,
                )
            });
        });
    }
    group.bench_function("score_among", |b| {
        b.iter(|| search.score_among(&reference, black_box(scan.points()), &truth, below));
    });
    group.finish();
}

criterion_group!(benches, look_ups);
criterion_main!(benches);
