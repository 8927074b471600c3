//! Re-anchoring on a revisit. A boosted map is laid by the scans themselves: while the robot
//! explores, each scan is matched against the points the scans just before it inserted, so
//! the map drifts with the estimate. When the robot comes back to ground it mapped long ago
//! with more drift than ICP's gate pulls in, its scans still fit the recent points they
//! overlap, every check passes, and a second copy of the old walls is laid beside the first;
//! the old map is never matched again. (On the Intel log, every relation a failing sweep
//! variant gets wrong by more than 0.5 m pairs a pose of the first minutes with one of a
//! revisit.)
//!
//! Every `every`-th matched scan is therefore looked up in the old map alone, the points of
//! the scans inserted at least `age_scans` relevant scans ago: a correlative search
//! ([`crate::correlative`]) over a window around the match, in a raster of the old points
//! only. Where some pose of the window explains the scan in the old map well (a score of at
//! least 1 − `max_miss`) and by `min_gain` better than the match does, ICP is run again from
//! that pose against the whole map, without the odometry prior, and its result replaces the
//! match if the old map still explains it as well and a recent look-up found the same
//! correction (`confirmations`, `confirm_gap`). The re-anchored match is not withheld by
//! odometry's veto: it corrects drift that odometry cannot see.
//!
//! This is a local correction, not a loop closure solved over a graph: the estimate is moved
//! by the drift, and with `deform` (the default) the correction is spread over the stretch of
//! map and trajectory that drifted ([`crate::trail`]); without it the drifted stretch stays
//! where it was laid and the estimate jumps. It helps where the drift is small enough to be
//! found in the window (`window_xy`, `window_deg`) and the old map is unambiguous there. A
//! look-up that finds the old map explaining the match nearly whole, and pinning it
//! ([`Revisit::pins`]), vouches for it: the spread does not reach back past it.

use crate::ConfigError;
use crate::correlative::{CorrelativeParams, CorrelativeSearch};
use qicp_core::{Point2, Pose2, Reference, SpatialIndex};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// When and how far a match is re-anchored to the old map (TOML section `[matcher.revisit]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RevisitParams {
    /// Look for the old map at all; false never re-anchors. Default true. Acts only against
    /// a map, and only where `[matcher.validation] enabled` is true.
    pub enabled: bool,
    /// How old a map point must be to count as the old map, in relevant scans: a point is
    /// old once `age_scans` − 1 scans have entered the map after the one that brought it.
    /// The first look-up waits for `age_scans` + 1 insertions (after the start, a clear or a
    /// rebuild): one more than that, as the map's length before the oldest old scan is kept.
    /// Default 100: on the Freiburg logs 25-50 m of driving, well beyond the stretch a scan
    /// overlaps while exploring. At least 1 (a [`Revisit::new`] given 0 takes 1).
    pub age_scans: usize,
    /// Every this many matched scans one is looked up in the old map. Default 5. A cost
    /// knob: each look builds a raster of the old map around the scan.
    pub every: usize,
    /// At the re-anchored pose the old map leaves at most this share of the scan unexplained
    /// (one minus the correlative score, from 0, every point on an old point, to 1). Default
    /// 0.2.
    pub max_miss: f64,
    /// The re-anchored pose explains the scan in the old map by at least this much (of the
    /// correlative score) better than the match. Default 0.2. Above 0: at 0 the match itself
    /// could be proposed, and a re-anchoring that moves nothing would still pass the match
    /// by odometry's veto.
    pub min_gain: f64,
    /// Half-width of the translation window around the match (m). Default 1.0: the drift
    /// beyond ICP's first gate that a revisit should still pull in.
    pub window_xy: f64,
    /// Half-width of the rotation window (deg). Default 3: a heading error larger than this
    /// over a loop leaves the old map too far off for a local correction to be trusted.
    pub window_deg: f64,
    /// A re-anchoring is taken only once this many look-ups (one every `every` matched
    /// scans) have each found it, their corrections of the match agreeing within
    /// [`AGREE_XY`] and [`AGREE_DEG`], with at most `confirm_gap` look-ups between each two:
    /// a lone look-up that the old map answers elsewhere is aliasing (a stretch of corridor,
    /// a room like another), as place recognition asks for repeated detections before it
    /// closes a loop. Default 2; 1 re-anchors on the first.
    pub confirmations: usize,
    /// Look-ups that find no confirmed pose tolerated between two that confirm each other
    /// (the M-of-N confirmation of target tracking): a scan that sees only walls fitting the
    /// old map and its drifted copy alike, or too little of the old map, neither confirms a
    /// correction nor contradicts it, and neither does a proposal that ICP's refinement or
    /// the old map's score then rejects. A confirmed look-up that finds another correction
    /// starts the count again. Default 8: two agreeing look-ups at most 45 matched scans
    /// apart at `every` = 5; 0 asks for look-ups strictly in a row.
    pub confirm_gap: usize,
    /// Spread a re-anchoring's correction over the stretch that drifted ([`crate::trail`]):
    /// the map's points laid since the robot left old ground move with it, by the path
    /// driven, and so do the poses of those records
    /// ([`Odometry::take_amendment`](crate::pipeline::Odometry::take_amendment)), where the
    /// moved stretch then lies nearer the old map. Default true. False leaves the drifted
    /// stretch where it was laid, and the estimate jumps.
    pub deform: bool,
    /// Spread a loop closed by the ordinary match as well: on old ground, a match that
    /// odometry's veto would hold but the scan's points outweigh, after the veto held an
    /// earlier match of the same run on old ground, within `age_scans` records of coming
    /// back from at least as many on new ground, corrects the drift of that run, and its
    /// correction of the prediction is spread as a re-anchoring's is (with `deform`, and the
    /// same check that the moved stretch lies nearer the old map). Default true. The matches
    /// creep onto the old map there, each within the look-ups' gain of the last, so no
    /// look-up re-anchors; without this the stretch stays where it drifted. A lone odometry
    /// glitch, a correction after a shorter excursion or long after the return, is followed
    /// without a spread.
    pub deform_followed: bool,
}

/// Two look-ups' corrections agree when, applied to the same match, they differ by less
/// than this (m): two cells of the look-up's raster.
pub const AGREE_XY: f64 = 0.1;
/// … and by less than this (deg): two angle steps of the look-up's raster.
pub const AGREE_DEG: f64 = 1.0;

impl Default for RevisitParams {
    fn default() -> Self {
        Self {
            enabled: true,
            age_scans: 100,
            every: 5,
            max_miss: 0.2,
            min_gain: 0.2,
            window_xy: 1.0,
            window_deg: 3.0,
            confirmations: 2,
            confirm_gap: 8,
            deform: true,
            deform_followed: true,
        }
    }
}

/// The refined match must explain the scan in the old map within this much of the
/// correlative pose's score: ICP against the whole map may pull it back onto the recent copy.
const KEEP_SCORE: f64 = 0.05;

impl RevisitParams {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(1..=1_000_000).contains(&self.age_scans) {
            return Err(ConfigError::invalid(
                "matcher.revisit.age_scans",
                format!("{} must be in 1..=1000000", self.age_scans),
            ));
        }
        if !(1..=100).contains(&self.confirmations) {
            return Err(ConfigError::invalid(
                "matcher.revisit.confirmations",
                format!("{} must be in 1..=100", self.confirmations),
            ));
        }
        if self.confirm_gap > 1_000 {
            return Err(ConfigError::invalid(
                "matcher.revisit.confirm_gap",
                format!("{} must be in 0..=1000", self.confirm_gap),
            ));
        }
        if !(1..=1_000_000).contains(&self.every) {
            return Err(ConfigError::invalid(
                "matcher.revisit.every",
                format!("{} must be in 1..=1000000", self.every),
            ));
        }
        if !(self.max_miss.is_finite() && (0.0..=1.0).contains(&self.max_miss)) {
            return Err(ConfigError::invalid(
                "matcher.revisit.max_miss",
                format!("{} must be in [0, 1]", self.max_miss),
            ));
        }
        if !(self.min_gain.is_finite() && self.min_gain > 0.0 && self.min_gain <= 1.0) {
            return Err(ConfigError::invalid(
                "matcher.revisit.min_gain",
                format!("{} must be in (0, 1]", self.min_gain),
            ));
        }
        // The window is checked as a correlative search's, under this section's keys.
        self.search().validate().map_err(|e| match e {
            ConfigError::Invalid { key, why } => ConfigError::Invalid {
                key: key.replace("matcher.correlative", "matcher.revisit"),
                why,
            },
            other => other,
        })
    }

    /// The correlative search over this window, at the default raster.
    fn search(&self) -> CorrelativeParams {
        CorrelativeParams {
            window_xy: self.window_xy,
            window_deg: self.window_deg,
            ..CorrelativeParams::default()
        }
    }
}

/// A start in the old map for a match to be tried from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proposal {
    /// The pose of the window that explains the scan best in the old map.
    pub start: Pose2,
    /// Its correlative score in the old map.
    pub score: f64,
    /// Points with ids below this are the old map.
    below: u32,
}

/// The state of the look-ups: the map's size after each recent insertion, and a count of the
/// matched scans.
#[derive(Debug, Clone)]
pub struct Revisit {
    params: RevisitParams,
    search: CorrelativeSearch,
    /// The map's length after each of the newest `age_scans` + 1 insertions.
    sizes: VecDeque<usize>,
    matched: usize,
    /// The run of agreeing look-ups so far: the matched count of the latest, its correction
    /// (re-anchored pose ∘ match⁻¹) and how many agreed.
    run: Option<(usize, Pose2, usize)>,
    /// The match of the latest call of [`Revisit::propose`], where it looked the match up and
    /// found the old map explaining it nearly whole.
    vouched: Option<Vouch>,
}

/// A match a look-up found the old map explaining nearly whole (within `min_gain` of the
/// whole scan). Whether the old map also pins it ([`Revisit::pins`]) is asked only where a
/// spread needs to know, so the scan is kept with it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Vouch {
    /// The scan's points in its own frame.
    local: Vec<Point2<f64>>,
    /// The match.
    pose: Pose2,
    /// Points with ids below this were the old map.
    below: u32,
    /// The old map's score of the match.
    score: f64,
}

/// Look-ups with the default parameters, the search's window theirs (a derived default would
/// take the correlative search's own, 0.5 m and 25°).
impl Default for Revisit {
    fn default() -> Self {
        Self::new(RevisitParams::default())
    }
}

impl Revisit {
    /// Look-ups with the given parameters.
    #[must_use]
    pub fn new(mut params: RevisitParams) -> Self {
        // Built directly, the parameters are not validated: an age of 0 would leave no old
        // map to look up (nor an index to read its length at).
        params.age_scans = params.age_scans.max(1);
        Self {
            params,
            search: CorrelativeSearch::new(params.search()),
            sizes: VecDeque::new(),
            matched: 0,
            run: None,
            vouched: None,
        }
    }

    /// The parameters (the search's window was built from them).
    #[must_use]
    pub fn params(&self) -> &RevisitParams {
        &self.params
    }

    /// Notes that the map's points were given new ids ([`Reference::renumberings`]): the
    /// lengths held no longer divide old points from recent ones, and the map's age starts
    /// afresh.
    pub fn renumbered(&mut self) {
        self.sizes.clear();
    }

    /// Notes that a scan entered the map, which now holds `len` points. A map that holds
    /// fewer than before was rebuilt, its ids given anew: its age starts afresh (as after
    /// [`renumbered`](Self::renumbered), which tells a rebuild that did not shrink the map).
    pub fn inserted(&mut self, len: usize) {
        if self.sizes.back().is_some_and(|&last| len < last) {
            self.sizes.clear();
        }
        self.sizes.push_back(len);
        while self.sizes.len() > self.params.age_scans.saturating_add(1) {
            self.sizes.pop_front();
        }
    }

    /// For a matched scan (`local`, matched at `pose`): a start in the old map when this scan
    /// is due for a look-up and the old map explains it much better elsewhere in the window.
    pub fn propose<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
    ) -> Option<Proposal> {
        if !self.params.enabled {
            return None;
        }
        self.matched += 1;
        self.vouched = None;
        if !self.matched.is_multiple_of(self.params.every)
            || self.sizes.len() <= self.params.age_scans
        {
            return None;
        }
        // The map's length `age_scans` − 1 insertions before the newest: the points of the
        // insertions since are recent (see `age_scans`).
        let below = u32::try_from(self.sizes[1]).ok()?;
        // Where the old map explains the match nearly whole, no pose can gain `min_gain` on it
        // (scores are at most 1): the usual case, answered without drawing the raster.
        let here = self.search.score_among(reference, local, pose, below)?;
        if here + self.params.min_gain > 1.0 {
            // Only a spread reads a vouch: without `deform` the scan's points are not copied.
            if self.params.deform {
                self.vouched = Some(Vouch {
                    local: local.to_vec(),
                    pose: *pose,
                    below,
                    score: here,
                });
            }
            return None;
        }
        let min_score = (1.0 - self.params.max_miss).max(here + self.params.min_gain);
        let best = self
            .search
            .search_over(reference, local, pose, Some(below), min_score)?;
        Some(Proposal {
            start: best.pose,
            score: best.score,
            below,
        })
    }

    /// Whether the old map pins the match `vouch` holds: every pose [`AGREE_XY`] beside it,
    /// in any direction, would explain the scan at least [`KEEP_SCORE`] worse (the score's
    /// tolerance elsewhere). The least loss over the directions comes from the score's
    /// curvature, taken by central differences along x, y and the diagonal. Along a corridor
    /// the old walls explain a slid match nearly as well, so they vouch for no place along
    /// it. Asked of a map whose old points are those of the look-up (ids are kept until the
    /// map is renumbered).
    pub fn pins<I: SpatialIndex>(&mut self, reference: &Reference<I>, vouch: &Vouch) -> bool {
        let (pose, d) = (vouch.pose, AGREE_XY);
        let mut loss = |dx: f64, dy: f64| {
            let mut pair = 0.0;
            for sign in [1.0, -1.0] {
                let beside = Pose2::new(pose.x + sign * dx, pose.y + sign * dy, pose.theta);
                pair += vouch.score
                    - self
                        .search
                        .score_among(reference, &vouch.local, &beside, vouch.below)?;
            }
            // Half the summed loss of the two sides: the curvature's part, the slope's cancels.
            Some(pair / 2.0)
        };
        let (Some(lx), Some(ly), Some(ld)) = (loss(d, 0.0), loss(0.0, d), loss(d, d)) else {
            return false;
        };
        // The loss along a unit direction u at distance d is uᵀ L u, where L holds lx and ly on
        // its diagonal and, off it, the part of the diagonal step's loss the axes do not
        // explain.
        let lxy = (ld - lx - ly) / 2.0;
        let mean = (lx + ly) / 2.0;
        let least = mean - ((lx - ly) * (lx - ly) / 4.0 + lxy * lxy).sqrt();
        least >= KEEP_SCORE
    }

    /// The match of the latest [`Revisit::propose`], if it looked the match up and found the
    /// old map explaining it nearly whole (no pose of the window could gain `min_gain` on
    /// it): where the old map also pins it ([`Revisit::pins`]), drift found later grew after
    /// it. None without `deform`, where no spread reads it. Clears it.
    pub fn take_vouched(&mut self) -> Option<Vouch> {
        self.vouched.take()
    }

    /// Counts a confirmed re-anchoring of the match `matched` to `reanchored` found by this
    /// look-up, and tells whether it is to be taken: once `confirmations` look-ups, with at
    /// most `confirm_gap` look-ups between each two, have found corrections that agree (see
    /// [`RevisitParams::confirm_gap`]).
    pub fn corroborated(&mut self, matched: &Pose2, reanchored: &Pose2) -> bool {
        let now = self.matched;
        // In matched scans; saturating, as a `Revisit` built directly is not validated.
        let reach = self
            .params
            .every
            .saturating_mul(self.params.confirm_gap.saturating_add(1));
        let agrees = |(at, correction, _): &(usize, Pose2, usize)| {
            let expected = *correction * *matched;
            now.saturating_sub(*at) <= reach
                && expected.distance(reanchored) < AGREE_XY
                && qicp_core::normalize_angle(expected.theta - reanchored.theta).abs()
                    < AGREE_DEG.to_radians()
        };
        let count = match self.run {
            Some(run) if agrees(&run) => run.2 + 1,
            _ => 1,
        };
        if count >= self.params.confirmations {
            self.run = None;
            true
        } else {
            self.run = Some((now, *reanchored * matched.inverse(), count));
            false
        }
    }

    /// Whether a re-anchored match is well determined: its position standard deviation (the
    /// root of its covariance's position trace) within [`AGREE_XY`], the tolerance within
    /// which look-ups' corrections must agree. A scan of a few points (two or three trunks
    /// far off) fits the old map in more than one place, and its covariance says so; a
    /// correction that uncertain can neither be confirmed nor told from another, so it is
    /// not taken, and the look-up neither confirms nor breaks a run of look-ups. On the
    /// real logs every re-anchoring the defaults take has a σ of 1.7-8 mm, on 96 pairs or
    /// more. In the paper's sparse park with `confirmations = 1`, those at σ 0.15-0.6 m (6-8
    /// pairs) turned the drive (q-wsm 0.81 → 10.4 m ATE) and those at 36-75 mm helped.
    /// A plug-in matcher whose covariance is all zeros (none known) passes.
    #[must_use]
    pub fn well_determined(reanchored: &qicp_core::MatchResult) -> bool {
        reanchored.position_sigma() <= AGREE_XY
    }

    /// Whether a match refined from `proposal` still explains the scan in the old map as
    /// well as the proposal did.
    pub fn confirms<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        refined: &Pose2,
        proposal: &Proposal,
    ) -> bool {
        self.search
            .score_among(reference, local, refined, proposal.below)
            .is_some_and(|s| s >= proposal.score - KEEP_SCORE)
    }
}
