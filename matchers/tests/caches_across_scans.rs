//! The correspondence rules keep their searches from one scan to the next while the map stays
//! the same ([`SpatialIndex::revision`]): most scans leave a boosted map as it was. Whatever
//! the map does in between (grows, loses points, is rebuilt to the same length around the same
//! first point), a rule that kept its searches must pair exactly as a fresh one does; and one
//! searching an index that does not count its revisions must keep nothing between scans.

use qicp_core::testdata::{SplitMix, laser_scans};
use qicp_core::{
    BruteForce, CorrespondenceMetric, KdTree, MatchingRange, MutualNearest, Neighbour, Pair,
    Point2, PointId, Pose2, QuadTree, Query, SpatialIndex, dist_sq,
};

/// An index that forwards to `I`, counts the searches made in it, and reports `I`'s
/// revisions only when `counted`: by default it does not count them (the trait's default),
/// as a plug-in may not.
#[derive(Debug, Default)]
struct Probed<I> {
    index: I,
    counted: bool,
    searches: std::cell::Cell<usize>,
}

impl<I: SpatialIndex> SpatialIndex for Probed<I> {
    fn insert(&mut self, p: Point2<f64>) -> Result<PointId, qicp_core::IndexError> {
        self.index.insert(p)
    }
    fn clear(&mut self) {
        self.index.clear();
    }
    fn points(&self) -> &[Point2<f64>] {
        self.index.points()
    }
    fn nearest_within(&self, q: &Point2<f64>, max_dist_sq: f64) -> Option<Neighbour> {
        self.searches.set(self.searches.get() + 1);
        self.index.nearest_within(q, max_dist_sq)
    }
    fn within_radius(&self, q: &Point2<f64>, radius: f64, out: &mut Vec<Neighbour>) {
        self.searches.set(self.searches.get() + 1);
        self.index.within_radius(q, radius, out);
    }
    fn k_nearest(&self, q: &Point2<f64>, k: usize, out: &mut Vec<Neighbour>) {
        self.searches.set(self.searches.get() + 1);
        self.index.k_nearest(q, k, out);
    }
    fn remove(&mut self, id: PointId) -> Option<bool> {
        self.index.remove(id)
    }
    fn revision(&self) -> Option<u64> {
        self.index.revision().filter(|_| self.counted)
    }
}

/// How the map changes before a scan.
#[derive(Debug, Clone, Copy)]
enum Change {
    None,
    /// New points around the robot.
    Grows,
    /// Every third point within 6 m of the robot taken out (the length stays).
    LosesPoints,
    /// Cleared and refilled with as many points, the first where it was and every other one
    /// moved by 4 cm (the length and the first point stay).
    Rebuilt,
}

/// The pairs of both rules along a slow drive through a map that changes as `changes` says,
/// each compared with a fresh rule's (no kept search) at every iteration. Returns how many
/// pairs were compared.
fn drive<I: SpatialIndex + Default>(changes: &[Change]) -> usize {
    let mut points = laser_scans(20_000, 31);
    let mut map = I::default();
    for p in &points {
        map.insert(*p).expect("a finite point");
    }
    let mut rng = SplitMix::new(8);
    let mut mutual = MutualNearest::<QuadTree>::default();
    let mut range = MatchingRange::default();
    let (mut got, mut want): (Vec<Pair>, Vec<Pair>) = (Vec::new(), Vec::new());
    let mut compared = 0;
    let mut robot = Pose2::new(-10.0, 0.0, 0.2);
    for (scan, change) in changes.iter().enumerate() {
        let o = Point2::new(robot.x, robot.y);
        match change {
            Change::None => {}
            Change::Grows => {
                for _ in 0..500 {
                    let p = Point2::new(o.x + rng.range(-6.0, 6.0), o.y + rng.range(-6.0, 6.0));
                    map.insert(p).expect("a finite point");
                    points.push(p);
                }
            }
            Change::LosesPoints => {
                let near: Vec<usize> = (0..points.len())
                    .filter(|&i| dist_sq(&points[i], &o) < 36.0)
                    .step_by(3)
                    .collect();
                for i in near {
                    assert_eq!(map.remove(i as PointId), Some(true), "removal of {i}");
                }
            }
            Change::Rebuilt => {
                map.clear();
                for (i, p) in points.iter_mut().enumerate() {
                    if i > 0 {
                        *p = Point2::new(p.x + 0.04, p.y - 0.03);
                    }
                    map.insert(*p).expect("a finite point");
                }
            }
        }
        // 150 returns of the map within 8 m, with centimetres of noise, in the scan's frame.
        let seen: Vec<Point2<f64>> = map
            .points()
            .iter()
            .filter(|m| dist_sq(m, &o) < 64.0)
            .copied()
            .collect();
        let local: Vec<Point2<f64>> = (0..150)
            .map(|_| {
                let m = seen[(rng.next_u64() % seen.len() as u64) as usize];
                let noisy = Point2::new(m.x + rng.range(-0.02, 0.02), m.y + rng.range(-0.02, 0.02));
                robot.inverse_transform_point(&noisy)
            })
            .collect();
        mutual.begin_scan(&local);
        range.begin_scan(&local);
        let mut pose = robot;
        for it in 0..6 {
            let step = 0.005;
            pose = pose
                * Pose2::new(
                    rng.range(-step, step),
                    rng.range(-step, step),
                    rng.range(-step, step),
                );
            let moved: Vec<Point2<f64>> = local.iter().map(|p| pose * *p).collect();
            let query = Query {
                local: &local,
                points: &moved,
                pose,
                max_dist: [0.5, 0.3, 0.2][it / 2],
            };
            let mut fresh = MutualNearest::<QuadTree>::default();
            fresh.begin_scan(&local);
            mutual.pair(&map, &query, &mut got);
            fresh.pair(&map, &query, &mut want);
            // Equidistant points may be told apart differently; the distances may not.
            let key = |p: &Pair| (p.scan, p.dist_sq);
            assert_eq!(
                got.iter().map(key).collect::<Vec<_>>(),
                want.iter().map(key).collect::<Vec<_>>(),
                "mutual nearest, scan {scan} after {change:?}, iteration {it}"
            );
            compared += got.len();
            let window = (8.0 - it as f64).to_radians();
            range.window = window;
            let mut fresh = MatchingRange::new(window);
            fresh.begin_scan(&local);
            range.pair(&map, &query, &mut got);
            fresh.pair(&map, &query, &mut want);
            assert_eq!(
                got, want,
                "matching range, scan {scan} after {change:?}, iteration {it}"
            );
            compared += got.len();
        }
        // The next scan a few centimetres on: most searches it kept still cover it.
        robot = robot * Pose2::new(0.03, 0.0, 0.002);
    }
    compared
}

const CHANGES: [Change; 10] = [
    Change::None,
    Change::None,
    Change::LosesPoints,
    Change::None,
    Change::Rebuilt,
    Change::None,
    Change::Grows,
    Change::None,
    Change::LosesPoints,
    Change::Rebuilt,
];

#[test]
fn searches_kept_from_scan_to_scan_follow_every_change_of_a_quadtree_map() {
    assert!(drive::<QuadTree>(&CHANGES) > 10_000);
}

#[test]
fn searches_kept_from_scan_to_scan_follow_every_change_of_a_kdtree_map() {
    assert!(drive::<KdTree>(&CHANGES) > 10_000);
}

#[test]
fn searches_kept_from_scan_to_scan_follow_every_change_of_a_brute_force_map() {
    assert!(drive::<BruteForce>(&CHANGES) > 10_000);
}

/// Without revisions a rebuilt map of the same length around the same first point looks the
/// same to the rules: they must search it afresh each scan.
#[test]
fn an_index_that_does_not_count_its_revisions_keeps_nothing_between_scans() {
    assert!(drive::<Probed<QuadTree>>(&CHANGES) > 10_000);
}

/// Two indexes changed alike take different revisions: a rule that kept its searches of one
/// never takes the other for it.
#[test]
fn two_indexes_never_share_a_revision_after_a_change() {
    fn check<I: SpatialIndex + Default>() {
        let (mut a, mut b) = (I::default(), I::default());
        a.insert(Point2::new(1.0, 2.0)).unwrap();
        b.insert(Point2::new(1.0, 2.0)).unwrap();
        assert_ne!(a.revision(), b.revision());
        a.clear();
        b.clear();
        assert_ne!(a.revision(), b.revision());
    }
    check::<QuadTree>();
    check::<KdTree>();
    check::<BruteForce>();
}

/// The searches a scan makes in an unchanged map right after another scan from a pose a
/// millimetre away, as a share of the first scan's: both rules, one iteration each.
fn searches_again(counted: bool) -> (f64, f64) {
    let mut map = Probed::<QuadTree> {
        counted,
        ..Probed::default()
    };
    for p in laser_scans(20_000, 41) {
        map.insert(p).expect("a finite point");
    }
    let robot = Pose2::new(-10.0, 0.0, 0.2);
    let o = Point2::new(robot.x, robot.y);
    let local: Vec<Point2<f64>> = map
        .points()
        .iter()
        .filter(|m| dist_sq(m, &o) < 64.0)
        .step_by(7)
        .take(150)
        .map(|m| robot.inverse_transform_point(m))
        .collect();
    let mut mutual = MutualNearest::<QuadTree>::default();
    let mut range = MatchingRange::new(3f64.to_radians());
    let mut pairs = Vec::new();
    let mut counts = [[0usize; 2]; 2];
    for (scan, pose) in [robot, robot * Pose2::new(0.001, 0.0, 0.0)]
        .iter()
        .enumerate()
    {
        let moved: Vec<Point2<f64>> = local.iter().map(|p| pose.transform_point(p)).collect();
        let query = Query {
            local: &local,
            points: &moved,
            pose: *pose,
            max_dist: 0.3,
        };
        mutual.begin_scan(&local);
        map.searches.set(0);
        mutual.pair(&map, &query, &mut pairs);
        counts[0][scan] = map.searches.get();
        range.begin_scan(&local);
        map.searches.set(0);
        range.pair(&map, &query, &mut pairs);
        counts[1][scan] = map.searches.get();
    }
    let share = |c: [usize; 2]| c[1] as f64 / c[0].max(1) as f64;
    (share(counts[0]), share(counts[1]))
}

/// The point of keeping: a scan in a map its predecessor left unchanged answers most of its
/// searches from what the predecessor found; without revisions it searches everything again.
#[test]
fn a_scan_in_an_unchanged_map_reuses_its_predecessors_searches() {
    let (mutual, range) = searches_again(true);
    assert!(
        mutual < 0.2 && range < 0.2,
        "searched again: {mutual:.2}, {range:.2}"
    );
    let (mutual, range) = searches_again(false);
    assert!(
        mutual > 0.9 && range > 0.9,
        "searched again: {mutual:.2}, {range:.2}"
    );
}
