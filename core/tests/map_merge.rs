//! Merging scans into a map: the minimum spacing, the surface band and the cell cap bound its
//! density, checked against brute-force counts and a brute-force index on seeded scans.

use qicp_core::testdata::{SplitMix, SyntheticWorld};
use qicp_core::{
    BeamGeometry, BruteForce, FullCell, KdTree, Merge, Point2, Pose2, QuadTree, Reference, Scan,
    SpatialIndex,
};
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
    revisits_in(QuadTree::default(), merge)
}

/// [`revisits`] into the index `index`.
fn revisits_in<I: SpatialIndex>(index: I, merge: Merge) -> Reference<I> {
    let world = SyntheticWorld::room();
    let mut rng = SplitMix::new(7);
    let mut map = Reference::new(index);
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
    for full_cell in [FullCell::EvictStalest, FullCell::Skip] {
        let capped = Merge {
            max_cell_points: 3,
            cell_size: 0.1,
            full_cell,
            ..Merge::spacing(0.01)
        };
        let map = revisits(capped);
        let points = map.live_points();
        let counts = cell_counts(&points, capped.cell_size);
        let fullest = counts.values().copied().max().expect("points");
        assert_eq!(
            fullest, capped.max_cell_points,
            "{full_cell:?}: cells fill up to the cap"
        );
        // The minimum spacing still holds among the live points under the cap (brute force).
        for (i, p) in points.iter().enumerate() {
            for q in &points[i + 1..] {
                assert!((p - q).norm() >= capped.resolution, "{p} and {q}");
            }
        }
        // Replaced points leave the index once they make up an eighth of it.
        assert!(8 * map.stale_len() < map.len(), "{full_cell:?}");
        assert_eq!(points.len() + map.stale_len(), map.len());
        let by_id: Vec<_> = (0..map.len() as u32)
            .filter(|&id| map.is_live(id))
            .map(|id| map.index().points()[id as usize])
            .collect();
        assert_eq!(
            points, by_id,
            "{full_cell:?}: live points are those is_live names"
        );
        // Without the cap the same revisits pile more points into the same cells.
        let spacing_only = revisits(Merge::spacing(0.01));
        let uncapped = cell_counts(spacing_only.index().points(), capped.cell_size);
        assert!(
            uncapped.values().copied().max().expect("points") > 2 * capped.max_cell_points,
            "the revisits must overfill cells for this test to mean anything: {:?}",
            uncapped.values().max()
        );
        assert!(points.len() < spacing_only.len());
    }
}

#[test]
fn a_full_cell_replaces_the_point_confirmed_least_recently() {
    // Square cells of 10 cm, the wall at y = 1.05 in the middle of a row of them (a look puts
    // about eight of its samples into a cell), room for two looks in a cell, and a band of
    // 5 mm: a look within it confirms the wall, one farther off enters.
    let merge = |full_cell| Merge {
        max_cell_points: 16,
        cell_size: 0.1,
        full_cell,
        surface_band: 0.005,
        ..Merge::spacing(0.0)
    };
    let build = |full_cell| {
        let mut map = Reference::new(QuadTree::default());
        let mut insert = |x0: f64, offset: f64| {
            let (scan, pose) = wall_scan(x0, offset);
            map.insert_scan(&scan, &pose, Some(merge(full_cell)))
                .expect("finite")
        };
        assert_eq!(insert(0.0, 0.05), 41);
        // A bad match copies the wall 3 cm behind itself; the cells it crosses fill up.
        assert!(insert(0.0, 0.08) > 30);
        // The robot sees the wall where it is: confirmed, nothing enters…
        assert_eq!(insert(0.01, 0.052), 0);
        // … and twice 1.5 cm off it (noise): new points, which full cells must make room for.
        insert(0.02, 0.065);
        insert(-0.02, 0.035);
        map
    };
    let near_wall = |p: &Point2<f64>| (p.y - 1.05).abs() <= 0.016;
    let evicting = build(FullCell::EvictStalest);
    // The cells every look covers whole (the looks' ends, |x| > 0.2, may leave a cell short
    // of full, and a cell with room replaces nothing).
    let kept: Vec<_> = evicting
        .live_points()
        .into_iter()
        .filter(|p| p.x.abs() < 0.2)
        .collect();
    assert!(
        kept.iter().all(near_wall),
        "the wrong copy outlived the looks that confirmed the wall: {:?}",
        kept.iter().filter(|p| !near_wall(p)).collect::<Vec<_>>()
    );
    // A full cell that skips keeps the first copies it got, the wrong one among them.
    let skipping = build(FullCell::Skip);
    assert!(
        skipping
            .live_points()
            .iter()
            .filter(|p| !near_wall(p))
            .count()
            > 30,
        "the skipping cap should keep the wrong copy"
    );
    // Every cell stays within its cap either way.
    for map in [&evicting, &skipping] {
        let counts = cell_counts(&map.live_points(), 0.1);
        assert!(counts.values().all(|&n| n <= 16), "{counts:?}");
    }
}

#[test]
fn a_full_cell_replaces_the_oldest_of_its_equally_stale_points() {
    // One cell of 10 m holds the whole wall; a cap of 3. The first look's first three
    // samples enter and fill it (a look never replaces its own points). A later point then
    // replaces one of the three, all confirmed last by that look: the oldest, the first.
    fn looks<I: SpatialIndex>(index: I, full_cell: FullCell) -> Vec<Vec<Point2<f64>>> {
        let merge = Merge {
            max_cell_points: 3,
            cell_size: 10.0,
            full_cell,
            ..Merge::spacing(0.0)
        };
        let one_point = Scan::new(0.0, BeamGeometry::centered(1, 0.0, 30.0), vec![1.08]);
        let mut map = Reference::new(index);
        let (wall, pose) = wall_scan(1.0, 0.05);
        assert_eq!(map.insert_scan(&wall, &pose, Some(merge)), Ok(3));
        let first = map.live_points();
        let later = map.insert_scan(&one_point.expect("finite"), &pose, Some(merge));
        assert_eq!(later, Ok(usize::from(full_cell == FullCell::EvictStalest)));
        vec![first, map.live_points()]
    }
    let quad = looks(QuadTree::default(), FullCell::EvictStalest);
    let [first, after] = [&quad[0], &quad[1]];
    assert_eq!(after[..2], first[1..], "the first sample is replaced");
    assert!(
        (after[2] - Point2::new(1.0, 1.08)).norm() < 1e-9,
        "{after:?}"
    );
    assert_eq!(looks(BruteForce::default(), FullCell::EvictStalest), quad);
    // A full cell that skips takes nothing.
    let skipping = looks(QuadTree::default(), FullCell::Skip);
    assert_eq!(skipping[1], skipping[0]);
}

#[test]
fn an_evicting_cap_keeps_the_same_points_in_every_index() {
    // Enough revisits that full cells replace points and the index is rebuilt without them.
    let capped = Merge {
        max_cell_points: 3,
        cell_size: 0.1,
        surface_band: 0.005,
        ..Merge::spacing(0.01)
    };
    let quad = revisits(capped);
    let brute = revisits_in(BruteForce::default(), capped);
    let kd = revisits_in(KdTree::default(), capped);
    assert_eq!(brute.index().points(), quad.index().points());
    assert_eq!(kd.index().points(), quad.index().points());
    assert_eq!(brute.live_points(), quad.live_points());
    assert_eq!(brute.stale_len(), quad.stale_len());
    // The rebuilt quad tree answers as a brute-force search over its points does.
    let mut rng = SplitMix::new(11);
    for _ in 0..2000 {
        let q = Point2::new(rng.range(-6.0, 6.0), rng.range(-6.0, 6.0));
        let (a, b) = (quad.index().nearest(&q), brute.index().nearest(&q));
        assert_eq!(a.map(|n| n.dist_sq), b.map(|n| n.dist_sq), "{q}");
    }
}

#[test]
fn a_cap_of_zero_keeps_every_point_the_spacing_keeps() {
    let off = Merge {
        max_cell_points: 0,
        cell_size: 0.1,
        ..Merge::spacing(0.01)
    };
    assert_eq!(
        revisits(off).index().points(),
        revisits(Merge::spacing(0.01)).index().points()
    );
}

/// A band of the laser's noise (the scans' σ is 5 mm) around the surfaces held.
fn banded() -> Merge {
    Merge {
        surface_band: 0.005,
        ..Merge::spacing(0.01)
    }
}

#[test]
fn revisits_thicken_a_surface_the_map_holds_less() {
    let banded_map = revisits(banded());
    let spacing_only = revisits(Merge::spacing(0.01));
    // Forty looks at one room from a few centimetres apart: the spacing alone keeps adding
    // the points that land more than its 1 cm from every point held (1,705 here); a band of
    // the scans' noise drops those within it of the surface held (1,512). Points farther off
    // still enter, so the band slows the growth rather than stopping it.
    assert!(
        (banded_map.len() as f64) < 0.92 * spacing_only.len() as f64,
        "{} points with the band, {} without",
        banded_map.len(),
        spacing_only.len()
    );
    // The walls are all there: every point the spacing kept lies near a point the band kept.
    for p in spacing_only.index().points() {
        let n = banded_map.index().nearest(p).expect("points");
        assert!(
            n.dist_sq.sqrt() < 0.05,
            "{p} is {} m from the map",
            n.dist_sq.sqrt()
        );
    }
    // The band never lets two points closer than the spacing (brute force).
    let points = banded_map.index().points();
    for (i, p) in points.iter().enumerate() {
        for q in &points[i + 1..] {
            assert!((p - q).norm() >= 0.01, "{p} and {q}");
        }
    }
}

#[test]
fn a_surface_band_keeps_the_same_points_in_every_index() {
    let quad = revisits(banded());
    assert_eq!(
        revisits_in(BruteForce::default(), banded())
            .index()
            .points(),
        quad.index().points()
    );
    assert_eq!(
        revisits_in(KdTree::default(), banded()).index().points(),
        quad.index().points()
    );
}

#[test]
fn a_band_that_is_not_finite_and_positive_keeps_every_point_the_spacing_keeps() {
    let spacing_only = revisits(Merge::spacing(0.01));
    for band in [f64::NAN, f64::INFINITY, -0.005] {
        let off = Merge {
            surface_band: band,
            ..banded()
        };
        assert_eq!(
            revisits(off).index().points(),
            spacing_only.index().points(),
            "band {band}"
        );
    }
}

/// A scan whose every beam hits the wall `y = 1` (x from −1 to 1), seen from `(x0, 0)`.
fn wall_scan(x0: f64, offset: f64) -> (Scan, Pose2) {
    let geometry = BeamGeometry::centered(41, 0.5, 30.0);
    let ranges = (0..41)
        .map(|i| (1.0 + offset) / geometry.angle(i).cos())
        .collect();
    let pose = Pose2::new(x0, 0.0, std::f64::consts::FRAC_PI_2);
    (Scan::new(0.0, geometry, ranges).expect("finite"), pose)
}

#[test]
fn a_point_off_the_surface_by_more_than_the_band_still_enters() {
    let merge = Merge {
        surface_band: 0.01,
        ..Merge::spacing(0.0)
    };
    let insert = |map: &mut Reference<QuadTree>, x0: f64, offset: f64| {
        let (scan, pose) = wall_scan(x0, offset);
        map.insert_scan(&scan, &pose, Some(merge)).expect("finite")
    };
    let mut map = Reference::new(QuadTree::default());
    assert_eq!(insert(&mut map, 0.0, 0.0), 41);
    // The same wall seen again 5 mm off, from a little aside: nothing new.
    assert_eq!(insert(&mut map, 0.01, 0.005), 0);
    // A copy 1.5 cm off the wall, within reach of the held samples but off their surface by
    // more than the band, enters whole; so does one 3 cm off.
    assert_eq!(insert(&mut map, 0.0, 0.015), 41);
    assert_eq!(insert(&mut map, 0.0, 0.03), 41);
    // The wall seen farther along: what lies beyond its end (x ≈ 0.255) is new ground.
    let mut fresh = Reference::new(QuadTree::default());
    insert(&mut fresh, 0.0, 0.0);
    let (scan, pose) = wall_scan(0.4, 0.0);
    let past_the_end = scan
        .points()
        .iter()
        .filter(|p| pose.transform_point(p).x > 0.3)
        .count();
    let new = insert(&mut fresh, 0.4, 0.0);
    let added = &fresh.index().points()[41..];
    assert!(
        added.iter().all(|p| p.x > 0.255),
        "a point on the held part entered: {added:?}"
    );
    assert!(
        new >= past_the_end && past_the_end > 20,
        "{new} new, {past_the_end} past the end"
    );
}

#[test]
fn a_reference_is_a_map_once_a_scan_is_merged_into_it_until_cleared() {
    let world = SyntheticWorld::room();
    let scan = world.scan(&Pose2::IDENTITY, 0.005, 1);
    let mut reference = Reference::new(QuadTree::default());
    assert!(!reference.is_map(), "empty");
    reference
        .insert_scan(&scan, &Pose2::IDENTITY, None)
        .expect("finite points");
    assert!(!reference.is_map(), "a scan as reference");
    let merged = Merge::spacing(0.01);
    reference
        .insert_scan(&scan, &Pose2::new(0.02, 0.0, 0.0), Some(merged))
        .expect("finite points");
    assert!(reference.is_map(), "a scan merged in");
    reference.clear();
    assert!(!reference.is_map(), "cleared");
    // The first scan of a map is merged too: a map is a map from its first scan on.
    reference
        .insert_scan(&scan, &Pose2::IDENTITY, Some(merged))
        .expect("finite points");
    assert!(reference.is_map(), "a map of one scan");
}

/// Distance from `p` to the nearest wall or post of `world`.
fn distance_to_world(world: &SyntheticWorld, p: &Point2<f64>) -> f64 {
    let walls = world.walls.iter().map(|w| {
        let (a, b) = (Point2::new(w[0], w[1]), Point2::new(w[2], w[3]));
        let t = ((p - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
        (p - (a + (b - a) * t)).norm()
    });
    let posts = world
        .posts
        .iter()
        .map(|&(x, y, r)| ((p - Point2::new(x, y)).norm() - r).abs());
    walls.chain(posts).fold(f64::INFINITY, f64::min)
}

/// Carving with a margin of 10 cm: the scans' noise is 5 mm.
fn carving() -> Merge {
    Merge {
        free_space_margin: 0.1,
        ..Merge::spacing(0.01)
    }
}

/// Poses across the room, facing every way.
fn tour(k: usize) -> Pose2 {
    let a = k as f64 * 0.7;
    Pose2::new(3.0 * a.cos(), 2.5 * (1.3 * a).sin(), 0.9 * a)
}

#[test]
fn carving_keeps_every_point_of_a_room_seen_from_the_right_poses() {
    let world = SyntheticWorld::room();
    let build = |merge: Merge| {
        let mut map = Reference::new(QuadTree::default());
        for k in 0..60 {
            let pose = tour(k);
            map.insert_scan(&world.scan(&pose, 0.005, k as u64 + 1), &pose, Some(merge))
                .expect("finite points");
        }
        map
    };
    let (carved, plain) = (build(carving()), build(Merge::spacing(0.01)));
    assert_eq!(carved.stale_len(), 0, "nothing seen through");
    assert_eq!(carved.live_points(), plain.live_points());
}

/// An index that cannot remove points ([`SpatialIndex::remove`]'s default): the map must
/// rebuild it to carve.
#[derive(Debug, Default)]
struct NoRemoval(BruteForce);

impl SpatialIndex for NoRemoval {
    fn insert(&mut self, p: Point2<f64>) -> Result<u32, qicp_core::IndexError> {
        self.0.insert(p)
    }
    fn clear(&mut self) {
        self.0.clear();
    }
    fn points(&self) -> &[Point2<f64>] {
        self.0.points()
    }
    fn nearest_within(&self, q: &Point2<f64>, max: f64) -> Option<qicp_core::Neighbour> {
        self.0.nearest_within(q, max)
    }
    fn within_radius(&self, q: &Point2<f64>, r: f64, out: &mut Vec<qicp_core::Neighbour>) {
        self.0.within_radius(q, r, out);
    }
    fn k_nearest(&self, q: &Point2<f64>, k: usize, out: &mut Vec<qicp_core::Neighbour>) {
        self.0.k_nearest(q, k, out);
    }
}

/// The room mapped from ten poses, then one scan inserted 20° off its true heading (a wrong
/// match), then thirty more from the right poses, all with carving.
fn room_with_a_wrong_match<I: SpatialIndex>(index: I) -> Reference<I> {
    let world = SyntheticWorld::room();
    let mut map = Reference::new(index);
    let mut insert = |scan: &Scan, pose: &Pose2| {
        map.insert_scan(scan, pose, Some(carving()))
            .expect("finite points");
    };
    for k in 0..10 {
        let pose = tour(k);
        insert(&world.scan(&pose, 0.005, k as u64 + 1), &pose);
    }
    let truth = tour(10);
    let wrong = Pose2::new(truth.x, truth.y, truth.theta + 20f64.to_radians());
    insert(&world.scan(&truth, 0.005, 11), &wrong);
    for k in 11..40 {
        let pose = tour(k);
        insert(&world.scan(&pose, 0.005, k as u64 + 1), &pose);
    }
    map
}

#[test]
fn a_wall_copied_in_by_a_wrong_match_is_carved_by_the_scans_after_it() {
    let world = SyntheticWorld::room();
    let check = |name: &str, live: Vec<Point2<f64>>, nearest: Option<qicp_core::Neighbour>| {
        let ghosts = live
            .iter()
            .filter(|p| distance_to_world(&world, p) > 0.1)
            .count();
        // Inside the room, in free space (farther than twice the margin from every surface:
        // beside a door's edge the beams around a point graze the wall), the wrong copy is
        // seen through; behind the walls it is hidden from every later scan and stays.
        let inside = live
            .iter()
            .filter(|p| p.x.abs() < 4.9 && p.y.abs() < 3.9 && distance_to_world(&world, p) > 0.2)
            .count();
        assert!(ghosts > 0, "{name}: the copy behind the walls stays");
        assert_eq!(
            inside, 0,
            "{name}: {ghosts} ghosts, {inside} inside the room"
        );
        let nearest = nearest.expect("a map").point;
        assert!(
            distance_to_world(&world, &nearest) < 0.1,
            "{name}: a carved point is still searched: {nearest}"
        );
    };
    let quad = room_with_a_wrong_match(QuadTree::default());
    let kd = room_with_a_wrong_match(KdTree::default());
    let rebuilt = room_with_a_wrong_match(NoRemoval::default());
    check(
        "quad tree",
        quad.live_points(),
        quad.index().nearest(&Point2::origin()),
    );
    check(
        "kd-tree",
        kd.live_points(),
        kd.index().nearest(&Point2::origin()),
    );
    check(
        "an index rebuilt",
        rebuilt.live_points(),
        rebuilt.index().nearest(&Point2::origin()),
    );
    assert_eq!(quad.live_points(), rebuilt.live_points(), "the same map");
    assert_eq!(kd.live_points(), rebuilt.live_points(), "the same map");
}

#[test]
fn a_rebuild_that_drops_replaced_points_is_counted_as_a_renumbering() {
    // Looks at one wall, each a little off the last, into cells capped at 16 points: full
    // cells replace their stalest points, and the index drops them in rebuilds, which give
    // the live points new ids. A look that rebuilt leaves no replaced point in the index and
    // the index as long as the live map.
    let merge = Merge {
        max_cell_points: 16,
        cell_size: 0.1,
        full_cell: FullCell::EvictStalest,
        surface_band: 0.005,
        ..Merge::spacing(0.0)
    };
    let mut map = Reference::new(QuadTree::default());
    let mut counted = 0;
    for k in 0..60 {
        let (scan, pose) = wall_scan(0.003 * (k % 7) as f64, 0.012 * (k % 5) as f64);
        map.insert_scan(&scan, &pose, Some(merge)).expect("finite");
        let now = map.renumberings();
        assert!(
            now == counted || now == counted + 1,
            "look {k}: {counted} -> {now}"
        );
        if now > counted {
            assert_eq!(map.stale_len(), 0, "look {k}");
            assert_eq!(map.index().len(), map.len(), "look {k}");
        }
        counted = now;
    }
    assert!(counted > 0, "the looks never filled the map's cells");
    map.clear();
    assert_eq!(map.renumberings(), counted + 1);
}

/// The room laid twice: scans 0-4 at their poses, scans 5-9 `drift` off (a stretch laid by
/// a drifted estimate), capped at `cap` points per 0.1 m cell (0: no cap).
fn laid_twice<I: SpatialIndex>(index: I, drift: Pose2, cap: u32) -> (Reference<I>, Vec<Pose2>) {
    let world = SyntheticWorld::room();
    let merge = Merge {
        max_cell_points: cap,
        cell_size: 0.1,
        ..Merge::spacing(0.01)
    };
    let mut map = Reference::new(index);
    let mut truth = Vec::new();
    for k in 0..10 {
        let pose = Pose2::new(-1.0 + 0.2 * k as f64, 0.1 * k as f64, 0.15 * k as f64);
        let laid = if k < 5 { pose } else { drift * pose };
        map.insert_scan(&world.scan(&pose, 0.005, k as u64 + 1), &laid, Some(merge))
            .expect("finite points");
        truth.push(pose);
    }
    (map, truth)
}

#[test]
fn a_deformed_map_moves_each_scans_points_with_the_scan_and_keeps_its_ids() {
    let drift = Pose2::new(0.4, -0.25, 2f64.to_radians());
    // Without a cap no point is stale, so none is dropped on the way.
    let (mut map, _) = laid_twice(QuadTree::default(), drift, 0);
    assert_eq!(map.stale_len(), 0);
    let before = map.index().points().to_vec();
    let info = map.info().to_vec();
    let renumberings = map.renumberings();
    // Scans 5-9 move back by the drift; scans 0-4 stay.
    let back = drift.inverse();
    map.deform(|scan| (scan >= 5).then_some(back))
        .expect("finite points");
    let after = map.index().points();
    assert_eq!(after.len(), before.len(), "no point lost");
    assert_eq!(map.renumberings(), renumberings, "ids kept");
    // Each point stayed, or moved by the drift's inverse and turned its normal with it.
    let mut moved = 0;
    for (id, (p, q)) in before.iter().zip(after).enumerate() {
        let (expected, normal) = if (p - q).norm() > 1e-12 {
            moved += 1;
            (back.transform_point(p), back.rotation() * info[id].normal)
        } else {
            (*p, info[id].normal)
        };
        assert!((q - expected).norm() < 1e-9, "point {id}");
        assert!((map.info()[id].normal - normal).norm() < 1e-9, "point {id}");
    }
    assert!(moved > 100, "the drifted scans' points moved ({moved})");
    // The index answers from the moved points: the same nearest as a linear search.
    let mut rng = SplitMix::new(11);
    for _ in 0..200 {
        let p = Point2::new(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0));
        let brute = after
            .iter()
            .map(|q| (q - p).norm_squared())
            .fold(f64::INFINITY, f64::min);
        let found = map.index().nearest_within(&p, 100.0).expect("a point");
        assert!((found.dist_sq - brute).abs() < 1e-12);
    }
}

#[test]
fn a_deformed_map_holds_one_copy_of_the_walls_and_its_cells_their_cap() {
    let drift = Pose2::new(0.4, -0.25, 2f64.to_radians());
    let world = SyntheticWorld::room();
    let off = |map: &Reference<QuadTree>| {
        map.live_points()
            .iter()
            .filter(|p| distance_to_world(&world, p) > 0.05)
            .count()
    };
    let (mut map, truth) = laid_twice(QuadTree::default(), drift, 4);
    assert!(off(&map) > 100, "the drifted copy lies off the walls");
    map.deform(|scan| (scan >= 5).then_some(drift.inverse()))
        .expect("finite points");
    assert_eq!(off(&map), 0, "every point back on a wall");
    // Moved onto the old copy, the stretch's points crowd its cells: the cap still holds.
    let crowded = cell_counts(&map.live_points(), 0.1);
    assert!(
        crowded.values().all(|&n| n <= 4),
        "{:?}",
        crowded.values().max()
    );
    // Scans laid after the deformation still fill cells only up to the cap.
    let merge = Merge {
        max_cell_points: 4,
        cell_size: 0.1,
        ..Merge::spacing(0.01)
    };
    for (k, pose) in truth.iter().enumerate() {
        map.insert_scan(&world.scan(pose, 0.005, 100 + k as u64), pose, Some(merge))
            .expect("finite points");
    }
    let counts = cell_counts(&map.live_points(), 0.1);
    assert!(
        counts.values().all(|&n| n <= 4),
        "{:?}",
        counts.values().max()
    );
}
