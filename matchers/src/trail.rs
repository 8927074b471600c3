//! Spreading a re-anchoring's correction over the stretch that drifted
//! (`[matcher.revisit] deform`).
//!
//! A re-anchoring ([`crate::revisit`]) moves the estimate back onto the old map in one step,
//! and leaves the map laid while the estimate drifted where it was laid: later visits pair
//! with either copy, and relations across the jump carry it. The drift grew while the robot
//! explored new ground, each scan matched against the points the scans just before it
//! inserted. So the trail of the records tells where it began: at the last record on old
//! ground (near a scan laid in the map at least `age_scans` insertions before, or near the
//! map's first scan, which sets its frame) before the run of records on new ground that
//! leads back to old ground. Every record counts, inserted or not: a map that takes only
//! scans with new points (q-idc's novelty gate) takes few on old ground. The correction is
//! spread from there to the re-anchoring by the path driven, nothing at the start and all
//! of it at the re-anchored record, as a pose graph with one loop and equal steps would
//! spread it. Where the robot had been back on old ground for more than `age_scans` records
//! before the re-anchoring, the drift grew there instead, against the recent points it laid
//! over the old ones, and the spread covers that run alone, from the last record whose match
//! a look-up found the old map explaining nearly whole ([`Trail::vouched`]) and pinning (a
//! match slid along a corridor is explained as well): up to there the estimate agreed with
//! the old map. The map's points move with the scan that laid them, and the trajectory with
//! them ([`Amendment`]).
//!
//! A spread is checked before it is made, as a loop closure is checked before it enters a
//! pose graph: the moved stretch must lie nearer the map laid before it, where they overlap,
//! than it did ([`moves_fit`]). A re-anchoring the old map only seemed to ask for (a stretch
//! of corridor like another) would bend a stretch that agreed with the old map off it; such
//! a correction stays a jump of the estimate, as without the spread.

use crate::revisit::Vouch;
use qicp_core::{Point2, Pose2, Reference, SpatialIndex};
use std::collections::{HashMap, VecDeque};

/// The side of the cells that tell old ground (m): a scan laid in a cell, or beside one,
/// where a scan was laid `age_scans` insertions before it is on old ground.
const GROUND_CELL: f64 = 2.0;

/// The newest vouched-for matches a trail keeps of its run on old ground (each with its
/// scan, 16 bytes a point): at one look-up in five matched scans, the last 1,000 records.
/// Where none of them is pinned, the spread covers the whole run, as without them.
const MAX_VOUCHES: usize = 200;

/// A scan that entered the map.
#[derive(Debug, Clone, Copy)]
struct Visit {
    /// The record it came with (counted from the pipeline's first).
    record: usize,
    /// Its number in the map ([`qicp_core::Reference::scans`] before it entered).
    stamp: u32,
}

/// The trail of the records and of the scans that entered the map: per record the laser's
/// path length and whether it was on old ground (9 bytes a record), and per scan its record
/// and number, with the first scan laid in each cell.
#[derive(Debug, Clone, Default)]
pub struct Trail {
    /// Insertions after which a scan's ground counts as old.
    age: usize,
    /// Per record: the laser's path length from the first record (m).
    path: Vec<f64>,
    /// Per record: whether it was on old ground.
    old_ground: Vec<bool>,
    /// The laser's position at the last record.
    last: Option<(f64, f64)>,
    visits: Vec<Visit>,
    /// Records before this one lie on a stretch already spread over ([`Trail::anchored`]):
    /// they count as old ground.
    anchored: usize,
    /// Per cell of [`GROUND_CELL`]: the number of the first insertion laid in it.
    first_in: HashMap<(i64, i64), usize>,
    /// The newest matches of the current run on old ground that a look-up found the old map
    /// explaining nearly whole, with their records ([`Trail::vouched`]).
    vouches: VecDeque<(usize, Vouch)>,
}

/// The cell of [`GROUND_CELL`] holding the laser at `laser`. Finite poses (the pipeline's)
/// and cells of 2 m fit an i64; the cast saturates.
fn cell(laser: &Pose2) -> (i64, i64) {
    (
        (laser.x / GROUND_CELL).floor() as i64,
        (laser.y / GROUND_CELL).floor() as i64,
    )
}

/// A correction of earlier poses: record `first + k` moves by `partial(k)`, applied on the
/// left (in the world), as do the points its scan laid in the map.
#[derive(Debug, Clone, PartialEq)]
pub struct Amendment {
    /// The first record moved (counted from the pipeline's first record).
    pub first: usize,
    /// The whole correction, in the world: the re-anchored laser pose times the inverse of
    /// the match's.
    pub correction: Pose2,
    /// Per record from `first` on: the share of the correction it takes, from 0 to 1.
    pub shares: Vec<f64>,
}

impl Amendment {
    /// The correction record `first + k` takes: `share` of the way from the identity to
    /// [`Amendment::correction`] (translation and angle interpolated linearly).
    #[must_use]
    pub fn partial(&self, k: usize) -> Pose2 {
        let share = self.shares.get(k).copied().unwrap_or(1.0);
        let c = &self.correction;
        // Plain products, no fused multiply-add: the Python package must give the command
        // line's poses to the bit, and a process may bind `fma` to a library of its own.
        Pose2::new(share * c.x, share * c.y, share * c.theta)
    }

    /// The correction record `record` takes, if it is one of [`Amendment::records`].
    #[must_use]
    pub fn moved(&self, record: usize) -> Option<Pose2> {
        self.records()
            .contains(&record)
            .then(|| self.partial(record - self.first))
    }

    /// The records it moves: `first..first + shares.len()`.
    #[must_use]
    pub fn records(&self) -> std::ops::Range<usize> {
        self.first..self.first + self.shares.len()
    }

    /// Applies it to a trajectory whose element `i` is record `i`'s pose (`pose` reads and
    /// writes the pose of an element); records beyond its end are left alone.
    pub fn apply<T>(&self, trajectory: &mut [T], pose: impl Fn(&mut T) -> &mut Pose2) {
        let end = self.records().end.min(trajectory.len());
        for (k, item) in trajectory.iter_mut().enumerate().take(end).skip(self.first) {
            let p = pose(item);
            *p = self.partial(k - self.first) * *p;
        }
    }
}

impl Trail {
    /// An empty trail: a scan's ground is old once `age` insertions followed it.
    #[must_use]
    pub fn new(age: usize) -> Self {
        Self {
            age: age.max(1),
            ..Self::default()
        }
    }

    /// Records processed so far: the number the next record takes.
    #[must_use]
    pub fn records(&self) -> usize {
        self.path.len()
    }

    /// The record whose scan entered the map last.
    #[must_use]
    pub fn last_scan_record(&self) -> Option<usize> {
        self.visits.last().map(|v| v.record)
    }

    /// Notes the next record's laser pose (in the world): its path, and whether it lies on
    /// old ground. The map's first record does.
    pub fn record(&mut self, laser: &Pose2) {
        let here = (laser.x, laser.y);
        let step = self
            .last
            .map_or(0.0, |(x, y)| (here.0 - x).hypot(here.1 - y));
        let before = self.path.last().copied().unwrap_or(0.0);
        self.path.push(before + step);
        self.last = Some(here);
        let old = self.on_old_ground(laser);
        self.old_ground.push(old);
        // A record on new ground ends the run the kept matches vouched for.
        if !old {
            self.vouches.clear();
        }
    }

    /// Whether a laser at `laser` (in the world) is on old ground: in a cell, or beside one,
    /// where a scan was laid `age` insertions or more ago (or the map's first scan, which
    /// sets its frame). Before any scan entered the map, everywhere is.
    #[must_use]
    pub fn on_old_ground(&self, laser: &Pose2) -> bool {
        let n = self.visits.len();
        let (cx, cy) = cell(laser);
        n == 0
            || (-1..=1).any(|dx| {
                (-1..=1).any(|dy| {
                    self.first_in
                        .get(&(cx.saturating_add(dx), cy.saturating_add(dy)))
                        .is_some_and(|&first| first == 0 || first + self.age <= n)
                })
            })
    }

    /// Since the last spread, the run of records on new ground before the newest run on old
    /// ground, and that run: `(first, back)`, records `first..back` on new ground and
    /// `back..` on old ground (`back` is [`Trail::records`] while the newest lies on new
    /// ground, and `first == back` where the trail has not left old ground).
    fn runs(&self) -> (usize, usize) {
        let old = &self.old_ground;
        let anchored = self.anchored.min(old.len());
        let mut back = old.len();
        while back > anchored && old[back - 1] {
            back -= 1;
        }
        let mut first = back;
        while first > anchored && !old[first - 1] {
            first -= 1;
        }
        (first, back)
    }

    /// The newest return to old ground since the last spread: the record it began at and
    /// the records of the run on new ground before it (how far the robot went). None while
    /// the newest record lies on new ground, or the trail has not left old ground.
    #[must_use]
    pub fn came_back(&self) -> Option<(usize, usize)> {
        let (first, back) = self.runs();
        (first < back && back < self.old_ground.len()).then_some((back, back - first))
    }

    /// Notes that the scan of the last record noted entered the map as scan `stamp`, laid
    /// from `laser` (in the world).
    pub fn inserted(&mut self, stamp: u32, laser: &Pose2) {
        let Some(record) = self.path.len().checked_sub(1) else {
            return;
        };
        self.first_in
            .entry(cell(laser))
            .or_insert(self.visits.len());
        self.visits.push(Visit { record, stamp });
    }

    /// Notes that a look-up found the old map explaining the last record's match nearly
    /// whole ([`crate::revisit::Revisit::take_vouched`]): if the old map also pins it, the
    /// estimate agreed with the old map there.
    pub fn vouched(&mut self, vouch: Vouch) {
        let Some(record) = self.path.len().checked_sub(1) else {
            return;
        };
        if self.vouches.len() == MAX_VOUCHES {
            self.vouches.pop_front();
        }
        self.vouches.push_back((record, vouch));
    }

    /// Forgets the vouched-for matches: the map's ids changed, and the old map they were
    /// scored in with them.
    pub fn unvouched(&mut self) {
        self.vouches.clear();
    }

    /// Forgets every scan (the map was cleared): no record before it is spread over again.
    pub fn cleared(&mut self) {
        self.vouches.clear();
        self.visits.clear();
        self.first_in.clear();
        self.anchored = self.path.len();
    }

    /// The amendment that spreads `correction`, found at the record about to be noted, over
    /// the stretch that drifted, or `None` when the trail shows none (no record on new
    /// ground since the last one spread over). `pinned` tells whether the old map pins a
    /// vouched-for match ([`crate::revisit::Revisit::pins`]); it is asked, newest first,
    /// only of the matches of a long run on old ground.
    #[must_use]
    pub fn amendment(
        &self,
        correction: Pose2,
        mut pinned: impl FnMut(&Vouch) -> bool,
    ) -> Option<Amendment> {
        let old = &self.old_ground;
        // Back from the newest record: the run on old ground that leads to the revisit, and
        // before it the run on new ground.
        let (mut first, back) = self.runs();
        if first == back {
            return None;
        }
        // Back on old ground for long before the re-anchoring, the robot's estimate drifted
        // there, against the recent points it laid over the old ones: the spread covers
        // that run alone, from the last record whose match the old map vouched for and pins
        // (it still agreed with the old map; the drift grew after it).
        if old.len() - back > self.age {
            first = back;
            if let Some((record, _)) = self
                .vouches
                .iter()
                .rev()
                .take_while(|(record, _)| *record >= back)
                .find(|(_, vouch)| pinned(vouch))
            {
                first = record + 1;
            }
        }
        if first >= old.len() {
            return None;
        }
        // The last record on old ground takes none of it (the map's first is on old ground).
        let from = self.path[first.saturating_sub(1)];
        let to = self.path.last().copied().unwrap_or(from);
        let shares = self.path[first..]
            .iter()
            .map(|&s| {
                if to > from {
                    ((s - from) / (to - from)).clamp(0.0, 1.0)
                } else {
                    1.0
                }
            })
            .collect();
        Some(Amendment {
            first,
            correction,
            shares,
        })
    }

    /// Notes that the stretch of the last [`Trail::amendment`] was spread over: its scans
    /// now lie on the old map, and a later correction is spread only over records after
    /// them.
    pub fn anchored(&mut self) {
        self.vouches.clear();
        self.anchored = self.path.len();
    }

    /// The correction each scan of the map takes under `amendment`, by its number.
    #[must_use]
    pub fn scan_moves(&self, amendment: &Amendment) -> HashMap<u32, Pose2> {
        self.visits
            .iter()
            .filter(|v| v.record >= amendment.first)
            .map(|v| (v.stamp, amendment.partial(v.record - amendment.first)))
            .collect()
    }
}

/// How far from a point of a stretch to be spread over the map laid before it counts as
/// overlapping it (m): the re-anchoring's window.
const OVERLAP_REACH: f64 = 1.0;
/// Points of the stretch sampled to tell whether a spread correction fits.
const OVERLAP_SAMPLES: usize = 2_000;

/// The median of `v` (0 when empty); reorders it.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Whether moving the map's scans as `moves` says (by their numbers, [`Reference::born`])
/// brings the stretch's points nearer the map laid before it where the two overlap: the median distance of a sample of them to
/// their nearest older point (within [`OVERLAP_REACH`]) must not grow. A drift that was
/// real laid the stretch's end as a copy beside the old map, which the move lays onto it;
/// a correction the old map only seemed to ask for (a stretch of corridor that looks like
/// another) pulls a stretch that agreed with it away.
pub fn moves_fit<I: SpatialIndex>(reference: &Reference<I>, moves: &HashMap<u32, Pose2>) -> bool {
    let Some(&boundary) = moves.keys().min() else {
        return true;
    };
    let born = reference.born();
    let points = reference.index().points();
    let index = reference.index();
    let stretch: Vec<usize> = (0..points.len()).filter(|&i| born[i] >= boundary).collect();
    let step = (stretch.len() / OVERLAP_SAMPLES).max(1);
    let mut around = Vec::new();
    let mut nearest_old = |p: &Point2<f64>| {
        index.within_radius(p, OVERLAP_REACH, &mut around);
        around
            .iter()
            .filter(|n| born[n.id as usize] < boundary)
            .map(|n| n.dist_sq.sqrt())
            .min_by(f64::total_cmp)
    };
    let mut before = Vec::new();
    let mut after = Vec::new();
    for &i in stretch.iter().step_by(step) {
        let p = points[i];
        let moved = moves.get(&born[i]).map_or(p, |by| by.transform_point(&p));
        let (b, a) = (nearest_old(&p), nearest_old(&moved));
        if b.is_some() || a.is_some() {
            before.push(b.unwrap_or(OVERLAP_REACH));
            after.push(a.unwrap_or(OVERLAP_REACH));
        }
    }
    before.is_empty() || median(&mut after) <= median(&mut before)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A trail of scans that entered the map at `poses`, one record each, old after `age`.
    fn trail(age: usize, poses: &[Pose2]) -> Trail {
        let mut t = Trail::new(age);
        extend(&mut t, poses);
        t
    }

    /// Notes one record and one scan at each of `poses`.
    fn extend(t: &mut Trail, poses: &[Pose2]) {
        for p in poses {
            t.record(p);
            t.inserted(t.records() as u32 - 1, p);
        }
    }

    /// Fifteen scans turning on the spot at the origin, then a 20 m square at 1 m a scan,
    /// back towards the origin down the y axis, ending at (0, `end_y`), shifted by `dy`.
    fn square_loop(end_y: i32, dy: f64) -> Vec<Pose2> {
        let mut poses: Vec<Pose2> = (0..15)
            .map(|k| Pose2::new(0.0, dy, 0.1 * k as f64))
            .collect();
        let legs = (1..=20).map(|i| (i, 0)).chain((1..=20).map(|i| (20, i)));
        let legs = legs.chain((1..=20).map(|i| (20 - i, 20)));
        let legs = legs.chain((1..=20 - end_y).map(|i| (0, 20 - i)));
        poses.extend(legs.map(|(x, y)| Pose2::new(f64::from(x), f64::from(y) + dy, 0.0)));
        poses
    }

    #[test]
    fn the_stretch_spread_over_runs_from_leaving_old_ground_to_coming_back() {
        let poses = square_loop(1, 0.0);
        let t = trail(10, &poses);
        let correction = Pose2::new(0.5, -0.2, 0.02);
        let a = t
            .amendment(correction, |_| true)
            .expect("a stretch on new ground");
        // Old ground reaches 3 m from the origin (its 2 m cell and the cells beside it): the
        // stretch begins at (4, 0), record 18, and runs on to the last record, (0, 1), which
        // takes all of it.
        assert_eq!(a.records(), 18..poses.len());
        for (k, share) in a.shares.iter().enumerate() {
            // 1 m a record from (3, 0), 76 m to (0, 1).
            let expected = (k + 1) as f64 / 76.0;
            assert!((share - expected).abs() < 1e-12, "{k}: {share}");
        }
        assert_eq!(a.partial(a.shares.len() - 1), correction);
        // Translation and angle are interpolated linearly.
        let p = a.partial(37);
        let share = a.shares[37];
        assert!((p.x - 0.5 * share).abs() < 1e-12 && (p.y + 0.2 * share).abs() < 1e-12);
        assert!((p.theta - 0.02 * share).abs() < 1e-12, "{p:?}");
        assert_eq!(a.moved(17), None);
        assert_eq!(a.moved(18 + 37), Some(p));
        // The map's scans take their records' shares.
        let moves = t.scan_moves(&a);
        assert_eq!(moves.len(), a.shares.len());
        assert_eq!(moves[&(18 + 37)], p);
        assert!(!moves.contains_key(&17));
    }

    #[test]
    fn records_on_old_ground_count_though_the_map_takes_none_of_their_scans() {
        // As a novelty gate does on a revisit: the last leg's scans do not enter the map.
        let poses = square_loop(1, 0.0);
        let mut t = Trail::new(10);
        for (k, p) in poses.iter().enumerate() {
            t.record(p);
            if p.x > 0.0 || k < 15 {
                t.inserted(k as u32, p);
            }
        }
        let a = t
            .amendment(Pose2::new(0.5, 0.0, 0.0), |_| true)
            .expect("a stretch");
        assert_eq!(a.records(), 18..poses.len());
    }

    /// The square loop back to (0, 0), then 150 records along its first leg again: a run of
    /// 150 records on old ground from record 91, (0, 3), on.
    fn long_run_on_old_ground() -> Vec<Pose2> {
        let mut poses = square_loop(0, 0.0);
        assert_eq!((poses[91].x, poses[91].y), (0.0, 3.0));
        poses.extend((0..150).map(|k| Pose2::new(0.1 * k as f64, 0.5, 0.0)));
        poses
    }

    /// A trail of `poses`, each record's scan entering the map, the matches of the records
    /// `vouched` vouched for by a look-up.
    fn vouched_trail(poses: &[Pose2], vouched: &[usize]) -> Trail {
        let mut t = Trail::new(10);
        for (k, p) in poses.iter().enumerate() {
            extend(&mut t, std::slice::from_ref(p));
            if vouched.contains(&k) {
                t.vouched(Vouch::default());
            }
        }
        t
    }

    /// The amendment of a correction of 0.5 m along x, `pinned` telling which vouched-for
    /// matches the old map pins.
    fn spread(t: &Trail, pinned: impl FnMut(&Vouch) -> bool) -> Amendment {
        t.amendment(Pose2::new(0.5, 0.0, 0.0), pinned)
            .expect("a stretch")
    }

    #[test]
    fn a_drift_found_long_after_coming_back_is_spread_over_the_run_on_old_ground() {
        // Back on old ground at record 91, then 150 records before the re-anchoring: the
        // drift grew there.
        let poses = long_run_on_old_ground();
        assert_eq!(
            spread(&trail(10, &poses), |_| true).records(),
            91..poses.len()
        );
    }

    #[test]
    fn a_drift_on_old_ground_is_spread_from_the_last_match_the_old_map_vouched_for() {
        // As above, but look-ups found the old map explaining the matches of records 150 and
        // 200 nearly whole, and pinning them: the drift grew after the later one, and the
        // records before keep their poses.
        let poses = long_run_on_old_ground();
        let t = vouched_trail(&poses, &[150, 200]);
        let a = spread(&t, |_| true);
        assert_eq!(a.records(), 201..poses.len());
        // 0.1 m a record from record 200 on.
        let expected = 1.0 / (poses.len() - 201) as f64;
        assert!((a.shares[0] - expected).abs() < 1e-12, "{}", a.shares[0]);
        // Where the old map does not pin record 200's match (a corridor), the one before it
        // that it pins starts the stretch; where it pins none, the whole run.
        let mut asked = 0;
        let a = spread(&t, |_| {
            asked += 1;
            asked == 2
        });
        assert_eq!((a.first, asked), (151, 2));
        assert_eq!(spread(&t, |_| false).records(), 91..poses.len());
    }

    #[test]
    fn a_vouched_match_before_the_run_on_old_ground_leaves_the_stretch_as_it_is() {
        // Vouched for on the first leg, before the loop: the loop's stretch is spread whole,
        // and so is a long run on old ground whose own look-ups vouched for nothing.
        let poses = square_loop(1, 0.0);
        let a = spread(&vouched_trail(&poses, &[16]), |_| true);
        assert_eq!(a.records(), 18..poses.len());
        let poses = long_run_on_old_ground();
        let a = spread(&vouched_trail(&poses, &[50]), |_| true);
        assert_eq!(a.records(), 91..poses.len());
    }

    #[test]
    fn the_run_on_old_ground_starts_where_the_loop_came_back() {
        // Back on old ground (within 3 m of the origin) from record 91, (0, 3), on.
        let poses = square_loop(0, 0.0);
        // after 73 records on new ground, (4, 0) to (0, 4).
        let t = trail(10, &poses);
        assert_eq!(t.came_back(), Some((91, 73)));
        assert!(t.on_old_ground(&Pose2::new(0.5, 0.5, 0.0)));
        assert!(!t.on_old_ground(&Pose2::new(10.0, 10.0, 0.0)));
        // On new ground it has not come back; nor has a trail that never left, or one
        // whose loop was spread over.
        assert_eq!(trail(10, &poses[..60]).came_back(), None);
        assert_eq!(trail(10, &poses[..10]).came_back(), None);
        assert_eq!(Trail::new(10).came_back(), None);
        let mut t = trail(10, &poses);
        t.anchored();
        assert_eq!(t.came_back(), None);
    }

    #[test]
    fn a_trail_that_never_left_old_ground_spreads_nothing() {
        let poses: Vec<Pose2> = (0..40)
            .map(|k| Pose2::new(0.05 * k as f64, 0.0, 0.0))
            .collect();
        assert_eq!(
            trail(10, &poses).amendment(Pose2::new(0.3, 0.0, 0.0), |_| true),
            None
        );
        assert_eq!(
            Trail::new(10).amendment(Pose2::new(0.3, 0.0, 0.0), |_| true),
            None
        );
    }

    #[test]
    fn a_stretch_spread_over_once_is_old_ground_for_the_next_correction() {
        let mut t = trail(10, &square_loop(1, 0.0));
        t.anchored();
        assert_eq!(t.amendment(Pose2::new(0.1, 0.0, 0.0), |_| true), None);
        // A second loop 30 m up the y axis, all new ground, back near its start.
        let n = t.records();
        extend(&mut t, &square_loop(1, 30.0)[15..]);
        let a = t
            .amendment(Pose2::new(0.1, 0.0, 0.0), |_| true)
            .expect("the second loop");
        assert_eq!(a.first, n);
    }

    #[test]
    fn an_amendment_moves_the_poses_of_its_records_only() {
        let a = Amendment {
            first: 2,
            correction: Pose2::new(1.0, 0.0, 0.0),
            shares: vec![0.25, 0.5, 1.0],
        };
        let mut poses = vec![Pose2::IDENTITY; 7];
        a.apply(&mut poses, |p| p);
        let xs: Vec<f64> = poses.iter().map(|p| p.x).collect();
        assert_eq!(xs, [0.0, 0.0, 0.25, 0.5, 1.0, 0.0, 0.0]);
        // A trajectory shorter than the stretch takes what it holds.
        let mut short = vec![Pose2::IDENTITY; 3];
        a.apply(&mut short, |p| p);
        assert_eq!(short[2].x, 0.25);
    }
}
