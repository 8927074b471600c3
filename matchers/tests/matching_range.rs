//! IDC's matching-range rule keeps each scan point's radius search between the iterations of
//! one scan. Its answers must equal the rule evaluated by brute force from scratch, over every
//! index, while the estimate wanders the way an iteration moves it (small steps, a jump now and
//! then, the window and gate shrinking).

use qicp_core::testdata::{SplitMix, laser_scans};
use qicp_core::{
    BruteForce, CorrespondenceMetric, KdTree, MatchingRange, Pair, Point2, Pose2, QuadTree, Query,
    SpatialIndex, dist_sq,
};

/// The rule by brute force: inside the window and within the reach of the point, the reference
/// point whose range from the sensor is closest to the point's, the lowest id on equal |Δr|.
/// (scan index, reference id, |Δr|).
fn brute_range_rule(
    map: &[Point2<f64>],
    points: &[Point2<f64>],
    pose: &Pose2,
    window: f64,
    max_dist: f64,
) -> Vec<(u32, u32, f64)> {
    let o = Point2::new(pose.x, pose.y);
    let mut out = Vec::new();
    for (k, p) in points.iter().enumerate() {
        let d = p - o;
        let r = d.norm();
        if r == 0.0 {
            continue;
        }
        let reach = max_dist.min(r * window.min(1.0) + 0.1);
        let best = map
            .iter()
            .zip(0u32..)
            .filter(|(m, _)| dist_sq(m, p) <= reach * reach)
            .filter(|(m, _)| {
                // The bearing of m is within ±window of the point's: cos ≥ cos(window).
                let e = *m - o;
                e.dot(&(d / r)) >= e.norm() * window.min(std::f64::consts::PI).cos()
            })
            .map(|(m, id)| (((m - o).norm() - r).abs(), id))
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        if let Some((dr, id)) = best {
            out.push((k as u32, id, dr));
        }
    }
    out
}

fn check<I: SpatialIndex + Default>() {
    let map_points = laser_scans(20_000, 5);
    let mut map = I::default();
    for p in &map_points {
        map.insert(*p).expect("finite point");
    }
    let mut rng = SplitMix::new(42);
    let mut rule = MatchingRange::default();
    let mut pairs: Vec<Pair> = Vec::new();
    let mut checked = 0;
    for scan in 0..6 {
        // A scan from a sensor pose inside the map's extent…
        let truth = Pose2::new(
            rng.range(-17.0, 17.0),
            rng.range(-5.5, 5.5),
            rng.range(-3.0, 3.0),
        );
        // … seeing map points within 8 m, with a few centimetres of noise.
        let seen: Vec<&Point2<f64>> = map_points
            .iter()
            .filter(|m| dist_sq(m, &Point2::new(truth.x, truth.y)) < 64.0)
            .collect();
        let local: Vec<Point2<f64>> = (0..150)
            .map(|_| {
                let m = seen[(rng.next_u64() % seen.len() as u64) as usize];
                let noisy = Point2::new(m.x + rng.range(-0.03, 0.03), m.y + rng.range(-0.03, 0.03));
                truth.inverse_transform_point(&noisy)
            })
            .collect();
        rule.begin_scan(&local);
        let mut pose = truth;
        for it in 0..25 {
            // Mostly small steps, now and then a jump beyond the searches' slack.
            let step = if it % 7 == 6 { 0.3 } else { 0.01 };
            pose = pose
                * Pose2::new(
                    rng.range(-step, step),
                    rng.range(-step, step),
                    rng.range(-step, step) * 0.5,
                );
            let window = (15.0 - 0.5 * it as f64).max(1.0).to_radians();
            let max_dist = if it < 8 {
                1.0
            } else if it < 16 {
                0.5
            } else {
                0.2
            };
            let moved: Vec<Point2<f64>> = local.iter().map(|p| pose.transform_point(p)).collect();
            rule.window = window;
            let query = Query {
                local: &local,
                points: &moved,
                pose,
                max_dist,
            };
            rule.pair(&map, &query, &mut pairs);
            let want = brute_range_rule(&map_points, &moved, &pose, window, max_dist);
            assert_eq!(
                pairs.iter().map(|p| p.scan).collect::<Vec<_>>(),
                want.iter().map(|w| w.0).collect::<Vec<_>>(),
                "scan {scan}, iteration {it}: different points paired"
            );
            let o = Point2::new(pose.x, pose.y);
            for (p, w) in pairs.iter().zip(&want) {
                let q = moved[p.scan as usize];
                let c = map.points()[p.reference as usize];
                assert_eq!(p.dist_sq, dist_sq(&c, &q));
                let dr = ((c - o).norm() - (q - o).norm()).abs();
                assert!(
                    (dr - w.2).abs() <= 1e-12,
                    "scan {scan}, iteration {it}, point {}: |Δr| {dr} against {}",
                    p.scan,
                    w.2
                );
                assert_eq!(
                    p.reference, w.1,
                    "scan {scan}, iteration {it}, point {}: paired with another point",
                    p.scan
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 5_000, "only {checked} pairs compared");
}

#[test]
fn cached_searches_equal_brute_force_quadtree() {
    check::<QuadTree>();
}

#[test]
fn cached_searches_equal_brute_force_kdtree() {
    check::<KdTree>();
}

#[test]
fn cached_searches_equal_brute_force_brute_force() {
    check::<BruteForce>();
}

/// A cache filled from one reference is not used for another, even without `begin_scan`.
#[test]
fn a_new_reference_drops_the_cache() {
    let mut rule = MatchingRange::new(10f64.to_radians());
    let local = vec![Point2::new(3.0, 0.0), Point2::new(0.0, 3.0)];
    let pose = Pose2::IDENTITY;
    let query = Query {
        local: &local,
        points: &local,
        pose,
        max_dist: 1.0,
    };
    let mut a = BruteForce::default();
    a.insert(Point2::new(3.1, 0.0)).unwrap();
    a.insert(Point2::new(0.0, 3.1)).unwrap();
    let mut pairs = Vec::new();
    rule.pair(&a, &query, &mut pairs);
    assert_eq!(pairs.len(), 2);
    let mut b = BruteForce::default();
    b.insert(Point2::new(5.0, 5.0)).unwrap();
    b.insert(Point2::new(3.05, 0.0)).unwrap();
    rule.pair(&b, &query, &mut pairs);
    assert_eq!(pairs.len(), 1);
    assert_eq!(pairs[0].reference, 1);
}

/// A sensor pose that is not finite pairs no point, whatever the reference holds: the rule's
/// one-branch filter must treat a NaN range as failing, as the separate tests did.
#[test]
fn a_pose_that_is_not_finite_pairs_nothing() {
    let mut rule = MatchingRange::new(10f64.to_radians());
    let local = vec![Point2::new(3.0, 0.0), Point2::new(0.0, 3.0)];
    let mut reference = QuadTree::default();
    reference.insert(Point2::new(3.1, 0.0)).unwrap();
    reference.insert(Point2::new(0.0, 3.1)).unwrap();
    let mut pairs = Vec::new();
    for pose in [
        Pose2::new(f64::NAN, 0.0, 0.0),
        Pose2::new(0.0, f64::INFINITY, 0.0),
    ] {
        let query = Query {
            local: &local,
            points: &local,
            pose,
            max_dist: 1.0,
        };
        rule.begin_scan(&local);
        rule.pair(&reference, &query, &mut pairs);
        assert!(pairs.is_empty(), "{pose:?} paired {pairs:?}");
    }
}

/// Logged ranges are quantized, so several reference points can differ from a scan point's
/// range by exactly the same amount. The rule then takes the lowest id whatever order the index
/// finds them in, so the quad tree, the kd-tree and brute force pair alike.
fn ties_go_to_the_lowest_id<I: SpatialIndex + Default>() {
    // Points at exactly 65/8 m from the origin (integer solutions of x² + y² = 65², scaled by
    // 1/8 so every square and the root are exact), 6-16° apart.
    let ring: Vec<Point2<f64>> = [
        (16.0, 63.0),
        (25.0, 60.0),
        (33.0, 56.0),
        (39.0, 52.0),
        (52.0, 39.0),
        (56.0, 33.0),
        (60.0, 25.0),
        (63.0, 16.0),
    ]
    .iter()
    .map(|&(x, y)| Point2::new(x / 8.0, y / 8.0))
    .collect();
    let mut rng = SplitMix::new(7);
    let mut ties = 0;
    for _ in 0..20 {
        // Each round inserts the ring in another order among other points, so ids and the
        // indexes' search orders are shuffled against each other.
        let mut map_points: Vec<Point2<f64>> = laser_scans(2_000, 3)
            .into_iter()
            .map(|p| Point2::new(p.x + 40.0, p.y))
            .collect();
        for p in &ring {
            let at = (rng.next_u64() % (map_points.len() as u64 + 1)) as usize;
            map_points.insert(at, *p);
        }
        let mut map = I::default();
        for p in &map_points {
            map.insert(*p).expect("a finite point");
        }
        let pose = Pose2::IDENTITY;
        let local: Vec<Point2<f64>> = (0..30)
            .map(|_| {
                let bearing = rng.range(20f64.to_radians(), 70f64.to_radians());
                let r = 65.0 / 8.0 + rng.range(-0.2, 0.2);
                Point2::new(r * bearing.cos(), r * bearing.sin())
            })
            .collect();
        let window = 25f64.to_radians();
        let mut rule = MatchingRange::new(window);
        rule.begin_scan(&local);
        let query = Query {
            local: &local,
            points: &local,
            pose,
            max_dist: 2.0,
        };
        let mut pairs = Vec::new();
        rule.pair(&map, &query, &mut pairs);
        let want = brute_range_rule(&map_points, &local, &pose, window, 2.0);
        let got: Vec<(u32, u32)> = pairs.iter().map(|p| (p.scan, p.reference)).collect();
        let expected: Vec<(u32, u32)> = want.iter().map(|w| (w.0, w.1)).collect();
        assert_eq!(got, expected);
        // The test means something only if scan points had several equal candidates: ring
        // points (all at the same range) inside the reach and the window.
        ties += local
            .iter()
            .filter(|p| {
                let u = p.coords / p.coords.norm();
                ring.iter()
                    .filter(|m| {
                        dist_sq(m, p) <= 4.0 && m.coords.dot(&u) >= m.coords.norm() * window.cos()
                    })
                    .count()
                    >= 2
            })
            .count();
    }
    assert!(
        ties > 300,
        "only {ties} of 600 scan points had tied candidates"
    );
}

#[test]
fn ties_go_to_the_lowest_id_quadtree() {
    ties_go_to_the_lowest_id::<QuadTree>();
}

#[test]
fn ties_go_to_the_lowest_id_kdtree() {
    ties_go_to_the_lowest_id::<KdTree>();
}
