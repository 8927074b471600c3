//! Merging scans into a map: the minimum spacing and the cell cap bound its density,
//! checked against brute-force counts on seeded scans.

use qicp_core::testdata::{SplitMix, SyntheticWorld};
use qicp_core::{Merge, Point2, Pose2, QuadTree, Reference, SpatialIndex};
use std::collections::HashMap;

/// Points per cell of side `size`, counted one by one.
fn cell_counts(points: &[Point2<f64>], size: f64) -> HashMap<(i64, i64), u32> {
    let mut counts = HashMap::new();
    for p in points {
        let cell = ((p.x / size).floor() as i64, (p.y / size).floor() as i64);
        *counts.entry(cell).or_insert(0) += 1;
    }
    counts
}

/// Forty scans of a room from poses a few centimetres apart, as revisits that land a little
/// off the map would give.
fn revisits(merge: Merge) -> Reference<QuadTree> {
    let world = SyntheticWorld::room();
    let mut rng = SplitMix::new(7);
    let mut map = Reference::new(QuadTree::default());
    for k in 0..40 {
        let pose = Pose2::new(
            rng.range(-0.05, 0.05),
            rng.range(-0.05, 0.05),
            0.01 * k as f64,
        );
        map.insert_scan(&world.scan(&pose, 0.005, k + 1), &pose, Some(merge))
            .expect("finite points");
    }
    map
}

#[test]
fn no_map_cell_holds_more_points_than_its_cap() {
    let capped = Merge {
        resolution: 0.01,
        cell_size: 0.1,
        max_cell_points: 3,
    };
    let map = revisits(capped);
    let counts = cell_counts(map.index().points(), capped.cell_size);
    let fullest = counts.values().copied().max().expect("points");
    assert_eq!(fullest, capped.max_cell_points, "cells fill up to the cap");
    // The minimum spacing still holds under the cap (brute force).
    let points = map.index().points();
    for (i, p) in points.iter().enumerate() {
        for q in &points[i + 1..] {
            assert!((p - q).norm() >= capped.resolution, "{p} and {q}");
        }
    }
    // Without the cap the same revisits pile more points into the same cells.
    let spacing_only = revisits(Merge::spacing(0.01));
    let uncapped = cell_counts(spacing_only.index().points(), capped.cell_size);
    assert!(
        uncapped.values().copied().max().expect("points") > 2 * capped.max_cell_points,
        "the revisits must overfill cells for this test to mean anything: {:?}",
        uncapped.values().max()
    );
    assert!(map.len() < spacing_only.len());
}

#[test]
fn a_cap_of_zero_keeps_every_point_the_spacing_keeps() {
    let off = Merge {
        max_cell_points: 0,
        ..Merge {
            resolution: 0.01,
            cell_size: 0.1,
            max_cell_points: 1,
        }
    };
    assert_eq!(
        revisits(off).index().points(),
        revisits(Merge::spacing(0.01)).index().points()
    );
}
