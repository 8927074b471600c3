//! Checking a match before it enters the reference. Paper Alg. 1 inserts every relevant scan
//! into a map that is never forgotten, so one wrong match (odometry out by decimetres, a
//! symmetric room, a local minimum) would be copied into the map and every later scan
//! matched against the turned copy. CSM reports `valid` rather than trusting every result;
//! here a match is judged by the share of its points the reference explains, against the
//! running level of recent scans (a share that is low everywhere in a cluttered park is
//! normal there, and a drop against the level is what marks a wrong match):
//!
//! 1. a match whose share falls more than `max_share_drop` below the running median share
//!    (as a fraction of it) is suspect, and so is one whose residual exceeds
//!    `max_residual_ratio` times the running median residual, or one left with more than
//!    `max_pair_drop` fewer pairs than the running median of recent matches';
//! 2. a suspect match is searched again: a correlative search over a window around the
//!    prediction ([`crate::correlative`]) gives ICP a new start, and the new match replaces
//!    the first only if it explains more of the scan and passes the check itself;
//! 3. a match still below the level does not enter the map (a residual alone does not keep it
//!    out); where the prediction explains
//!    the scan at least as well, the prediction is reported instead (a
//!    [`Fallback::Refused`](qicp_core::Fallback::Refused)), so the next prediction does not
//!    start from a match that went astray;
//! 4. a match odometry contradicts beyond its uncertainty (`max_odometry_chi2`) does not enter
//!    the map either, and falls back to the prediction unless the points it explains beyond
//!    the prediction outweigh odometry's disagreement (`veto_falls_back`, `point_evidence`).
//!
//! The share counts only the points the reference could have seen (`skip_unseen`): new ground,
//! away from every map point and outside the last inserted scan's field of view, is no sign of
//! a wrong match.

use crate::ConfigError;
use crate::icp::positive;
use qicp_core::{Matrix3, Neighbour, Point2, Pose2, Reference, Scan, SpatialIndex, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// How matches are checked (TOML section `[matcher.validation]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidationParams {
    /// Check matches at all; false runs the paper's plain Alg. 1 (every relevant scan enters
    /// the map, no search). Default true.
    pub enabled: bool,
    /// A scan point is explained when the reference surface lies within this distance of it
    /// (m). Default 0.1: several times a laser's range noise, well below a wrong match's
    /// offsets.
    pub inlier_distance: f64,
    /// A match is suspect, and a search runs, when its share of explained points falls more
    /// than this fraction below the running median share of recent scans. Default 0.25.
    pub max_share_drop: f64,
    /// A match is also suspect when its residual correlation distance exceeds this many times
    /// the running median residual: a match turned by a few degrees in clutter can keep most
    /// points near some surface, but not near the ones they belong to. Suspect, not refused:
    /// a search's re-match above it still replaces a first match the check refuses
    /// ([`rescues_refused`]). Default 2.
    pub max_residual_ratio: f64,
    /// A match is also suspect when it is left with more than this fraction fewer pairs
    /// than the running median of recent matches (0: off): too few inliers. A scan
    /// matched a turn short of a fast turn can keep most of its points within
    /// `inlier_distance` of some surface while half its pairs fail the metric's test (on the
    /// MIT CSAIL log, 108 pairs against a level of about 220, with 0.80 of its points
    /// explained). Default 0.3.
    pub max_pair_drop: f64,
    /// Checked scans in the running median, 5 to 10,000 (a [`Validator::new`] given another
    /// value takes the nearest of these). Default 25.
    pub history: usize,
    /// Run the correlative search on suspect matches. Default true.
    pub search: bool,
    /// After this many refusals in a row the running level starts afresh: a run of poor
    /// matches is a change of scene (new ground, a crowd), not one wrong match, and the map
    /// must grow into it. Until enough matches set the new level, the share the prediction
    /// explains stands in for it: a match more than `max_share_drop` below that falls back to
    /// the prediction and stays out of the map. Default 3.
    pub max_refusals: usize,
    /// While a run of refusals has cleared the level (`max_refusals`) and too few matches have
    /// set a new one, every match is searched, not only a poor one: a robot turning fast into
    /// ground its map has not seen leaves ICP in a local minimum short of the turn, and with
    /// no level to judge it that match would enter the map. The search's re-match replaces it
    /// where the match falls more than `max_share_drop` below the re-match's share (which
    /// stands in for the level, as the prediction's does for the fall-back) and where
    /// odometry's χ² test (`max_odometry_chi2`) would not reject the re-match unless it
    /// rejects the first as well ([`replaces_without_level`]). false searches only poor
    /// matches, as before a restart. Default true. (On the MIT CSAIL log with every second
    /// record, a match of q-wsm's after such a run explained 0.42 of its scan and entered the
    /// map 15° off the turn, 18.6° off to the end; its re-match explains 0.90.)
    pub search_after_refusals: bool,
    /// A match whose pose differs from the odometry prediction by more than this squared
    /// Mahalanobis distance, under the motion model's covariance (`[matcher.motion]`), is
    /// reported but withheld from the map until a match agrees with odometry again (0: off).
    /// Default 16.3, the 99.9 % quantile of χ² with three degrees of freedom: a corridor
    /// slide of decimetres, or a turn of many degrees odometry never made, would otherwise be
    /// written into the map as a second copy of every wall. A match that snaps back onto the
    /// map after drift is withheld too, once: the next scan, predicted from it, agrees.
    /// The same test tells a stalled odometry reading (`[matcher.motion] stall_restart`), scan
    /// to scan too.
    pub max_odometry_chi2: f64,
    /// A match odometry's veto withholds falls back to the prediction (a
    /// [`Fallback::Refused`](qicp_core::Fallback::Refused)) unless the scan tells the two
    /// apart by enough points to outweigh odometry (`point_evidence`): odometry says the match
    /// moved where the robot did not (a slide along a corridor, a turn on a few points), so
    /// the next prediction starts from odometry's pose, as after a refusal. Where the match
    /// explains the scan by many points more (a recovery from odometry gone wrong) it is
    /// followed. false follows every withheld match. Default true.
    pub veto_falls_back: bool,
    /// How much one scan point counts against odometry when a withheld match is weighed
    /// against the prediction (`veto_falls_back`): the log-likelihood ratio of a point the
    /// match explains and the prediction does not. The match is followed only where the
    /// points it explains beyond the prediction, times this, reach half the χ² of its
    /// disagreement with odometry: a turn of 30° that odometry never made is not taken on
    /// one point more of a five-point scan. Default 5, the ratio of a point explained with
    /// probability 0.99 at the right pose and 0.3 at a wrong one (ln(0.99·0.7 / (0.3·0.01))
    /// ≈ 5.4); the points of a scan are not independent, so this is generous to the scan.
    pub point_evidence: f64,
    /// A scan point the reference could not have seen counts in neither part of the share:
    /// one farther than twice `inlier_distance` from every reference point and outside the
    /// field of view of the last scan that entered the reference (at a bearing from its
    /// laser that none of its beams took; [`FieldOfView`]). New ground beside a robot backing
    /// along a corridor, or behind one that has turned, then does not lower the share of a
    /// right match; a wrong match still moves points off the surfaces the map holds within
    /// that view. false counts every point of the scan. Default true. (On Intel played
    /// backwards, counting every point, a level 17.5 % below the median refused such scans
    /// along a corridor, and the search slid their poses back onto the walls the map held:
    /// q-idc 0.30 m against 0.021 m; see the README.)
    pub skip_unseen: bool,
}

impl Default for ValidationParams {
    fn default() -> Self {
        Self {
            enabled: true,
            inlier_distance: 0.1,
            max_share_drop: 0.25,
            max_residual_ratio: 2.0,
            max_pair_drop: 0.3,
            history: 25,
            search: true,
            max_refusals: 3,
            search_after_refusals: true,
            max_odometry_chi2: 16.3,
            veto_falls_back: true,
            point_evidence: 5.0,
            skip_unseen: true,
        }
    }
}

/// The running median needs this many scans before it judges any.
const MIN_HISTORY: usize = 5;
/// The longest history `validate` allows.
const MAX_HISTORY: usize = 10_000;

impl ValidationParams {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("matcher.validation.inlier_distance", self.inlier_distance)?;
        if !(self.max_share_drop.is_finite() && (0.0..=1.0).contains(&self.max_share_drop)) {
            return Err(ConfigError::invalid(
                "matcher.validation.max_share_drop",
                format!("{} must be in [0, 1]", self.max_share_drop),
            ));
        }
        if !(self.max_pair_drop.is_finite() && (0.0..=1.0).contains(&self.max_pair_drop)) {
            return Err(ConfigError::invalid(
                "matcher.validation.max_pair_drop",
                format!("{} must be in [0, 1]", self.max_pair_drop),
            ));
        }
        if !(self.max_residual_ratio.is_finite() && self.max_residual_ratio >= 1.0) {
            return Err(ConfigError::invalid(
                "matcher.validation.max_residual_ratio",
                format!("{} must be finite and ≥ 1", self.max_residual_ratio),
            ));
        }
        if !(MIN_HISTORY..=MAX_HISTORY).contains(&self.history) {
            return Err(ConfigError::invalid(
                "matcher.validation.history",
                format!("{} must be in {MIN_HISTORY}..={MAX_HISTORY}", self.history),
            ));
        }
        crate::icp::non_negative(
            "matcher.validation.max_odometry_chi2",
            self.max_odometry_chi2,
        )?;
        positive("matcher.validation.point_evidence", self.point_evidence)?;
        if self.max_refusals == 0 {
            return Err(ConfigError::invalid(
                "matcher.validation.max_refusals",
                "must be at least 1",
            ));
        }
        Ok(())
    }

    /// True when `share` falls more than `max_share_drop` below `standing_in`, the share that
    /// stands in for the level where none judges a match (the prediction's, after a run of
    /// refusals; a search's re-match's).
    #[must_use]
    pub fn falls_below(&self, share: f64, standing_in: f64) -> bool {
        (1.0 - self.max_share_drop) * standing_in > share
    }
}

/// The squared Mahalanobis distance of `matched` from `predicted` under the prior information
/// `lambda` (both poses in the reference frame).
pub(crate) fn odometry_chi2(lambda: &Matrix3<f64>, predicted: &Pose2, matched: &Pose2) -> f64 {
    let d = Vector3::new(
        matched.x - predicted.x,
        matched.y - predicted.y,
        qicp_core::normalize_angle(matched.theta - predicted.theta),
    );
    d.dot(&(lambda * d))
}

/// True when `fit` explains a smaller share than the `level` of [`Validator::threshold`],
/// leaves a larger residual or holds fewer pairs; never while the history is too short to tell
/// (`None`).
#[must_use]
pub fn is_poor(fit: Fit, level: Option<Level>) -> bool {
    level.is_some_and(|l| {
        fit.share < l.min_share || fit.residual > l.max_residual || fit.pairs < l.min_pairs
    })
}

/// True when a search's re-match `again` replaces a first match `first` that `level` refuses
/// (its share below the level's) although `again` is poor: `again` holds the level's share
/// and pairs, and only its residual is above the level. A residual above the level makes a
/// match suspect, never refused ([`Validator::refuse`]): `again` would stand where `first`
/// falls. (On the MIT CSAIL log odometry caught up after a stall 16° beyond the turn the
/// scans saw; q-wsm's match from there explained 0.19 of the scan, the search's re-match
/// 0.99 with 229 pairs against a level of 171, but a residual of about twice the running
/// median, as a fast turn's skewed scan leaves, and the record kept the prediction.)
#[must_use]
pub fn rescues_refused(first: Fit, again: Fit, level: Option<Level>) -> bool {
    level.is_some_and(|l| {
        first.share < l.min_share && again.share >= l.min_share && again.pairs >= l.min_pairs
    })
}

/// True when a search's re-match `again` replaces a first match `first` while a run of
/// refusals has left no level to judge them ([`ValidationParams::search_after_refusals`]):
/// the first falls more than `max_share_drop` below the re-match's share, and odometry's χ²
/// test does not reject the re-match where it lets the first pass (`disagrees`: whether the
/// test rejects a match, given its pose). A re-match that explains more of a scan in foliage
/// by turning against odometry is no recovery (on the clinic log, re-matches explaining
/// 0.15-0.21 more of their scans, turned up to 19° where odometry turned 0.1°).
#[must_use]
pub fn replaces_without_level(
    params: &ValidationParams,
    (first, first_pose): (Fit, &Pose2),
    (again, again_pose): (Fit, &Pose2),
    disagrees: impl Fn(&Pose2) -> bool,
) -> bool {
    params.falls_below(first.share, again.share)
        && (!disagrees(again_pose) || disagrees(first_pose))
}

/// What the check said of one match.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Check {
    /// Share of the scan's points the reference explains at the estimate; NaN when the
    /// match was not checked.
    pub inlier_share: f64,
    /// The match looked wrong and the correlative search ran.
    pub searched: bool,
    /// The search's start led to a better match, which replaced the first.
    pub recovered: bool,
    /// The match stayed below the running level: it does not enter a map (a scan-to-scan
    /// reference is replaced all the same), and where the prediction explains the scan at
    /// least as well, the prediction stands.
    pub refused: bool,
    /// The match disagreed with odometry beyond the motion model's uncertainty
    /// ([`ValidationParams::max_odometry_chi2`]): its pose is reported, but it does not
    /// enter a map.
    pub withheld: bool,
    /// The match was re-anchored to the old map on a revisit ([`crate::revisit`]).
    pub reanchored: bool,
    /// The match kept odometry's estimate along the direction the scan does not fix
    /// ([`crate::MotionModel::hold_unobserved`]).
    pub held: bool,
}

impl Check {
    /// A match that was not checked.
    pub const UNCHECKED: Check = Check {
        inlier_share: f64::NAN,
        searched: false,
        recovered: false,
        refused: false,
        withheld: false,
        reanchored: false,
        held: false,
    };
}

/// The running level of explained shares, and the judge of each new one.
#[derive(Debug, Clone, Default)]
pub struct Validator {
    /// The parameters.
    pub params: ValidationParams,
    recent: VecDeque<Fit>,
    sorted: Vec<f64>,
    refusals: usize,
    /// The history was cleared by a run of refusals, not by a new drive.
    restarted: bool,
}

/// A scan placed at a pose, each point paired with the reference's nearest point within a
/// reach: the look-ups the check's share ([`Validator::placed_share`]) and the hold's weak
/// direction ([`crate::degeneracy::weak_direction`]) both read, made once per match.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    /// The pose the scan was placed at.
    pub pose: Pose2,
    /// How far (m) the look-ups reached.
    pub reach: f64,
    /// Each point in the reference frame, with the reference's nearest point within `reach`.
    pub points: Vec<(Point2<f64>, Option<Neighbour>)>,
}

impl Placed {
    /// Places `local` (laser frame) at `pose` and looks up each point's nearest reference
    /// point within `reach`.
    #[must_use]
    pub fn new<I: SpatialIndex>(
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
        reach: f64,
    ) -> Self {
        let points = local.iter().map(|q| pose.transform_point(q));
        Self::look_up(reference, points, *pose, reach)
    }

    /// The points (reference frame) of a scan placed at `pose`, each with its nearest
    /// reference point within `reach`.
    fn look_up<I: SpatialIndex>(
        reference: &Reference<I>,
        points: impl Iterator<Item = Point2<f64>>,
        pose: Pose2,
        reach: f64,
    ) -> Self {
        let index = reference.index();
        let points = points
            .map(|p| (p, index.nearest_within(&p, reach * reach)))
            .collect();
        Self {
            pose,
            reach,
            points,
        }
    }
}

/// The field of view of the last scan that entered a reference: its laser pose in the
/// reference frame and the bearings its beams spanned (half a beam step beyond the first and
/// the last).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldOfView {
    /// The inverse of the laser's pose: from the reference frame into the laser's.
    to_laser: Pose2,
    /// The bearing halfway between the first beam and the last (rad).
    middle: f64,
    /// Half the span (rad); π or more sees all round.
    half_span: f64,
}

impl FieldOfView {
    /// What `scan` saw from `laser` (its pose in the reference frame).
    #[must_use]
    pub fn of(scan: &Scan, laser: Pose2) -> Self {
        let g = &scan.geometry;
        let first = g.angle_min;
        let last = g.angle(scan.beams().saturating_sub(1));
        Self {
            to_laser: laser.inverse(),
            middle: 0.5 * (first + last),
            half_span: 0.5 * (last - first).abs() + 0.5 * g.angle_increment.abs(),
        }
    }

    /// The same view from a laser moved by `by` (on the left, in the reference frame).
    #[must_use]
    pub fn moved(&self, by: &Pose2) -> Self {
        Self {
            to_laser: self.to_laser * by.inverse(),
            ..*self
        }
    }

    /// True where `p` (reference frame) lies at a bearing from the laser that the scan's
    /// beams spanned; every range counts.
    #[must_use]
    pub fn contains(&self, p: &Point2<f64>) -> bool {
        let local = self.to_laser.transform_point(p);
        let bearing = local.y.atan2(local.x);
        qicp_core::normalize_angle(bearing - self.middle).abs() <= self.half_span
    }
}

/// How well a match fits its reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Share of the scan's points the reference explains.
    pub share: f64,
    /// The match's residual correlation distance (m).
    pub residual: f64,
    /// The pairs of the match's last iteration.
    pub pairs: f64,
}

/// The running level a match is judged against: a fit with a smaller share, or a larger
/// residual, is poor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Level {
    /// `(1 − max_share_drop)` × the median share of recent scans.
    pub min_share: f64,
    /// `max_residual_ratio` × the median residual of recent scans (m).
    pub max_residual: f64,
    /// `(1 − max_pair_drop)` × the median pair count of recent scans (0 when the test is
    /// off).
    pub min_pairs: f64,
}

impl Validator {
    /// A validator with no history.
    #[must_use]
    pub fn new(mut params: ValidationParams) -> Self {
        // Built directly, the parameters are not validated: the history is kept within the
        // range `validate` allows, so it stays bounded and long enough to set a level.
        params.history = params.history.clamp(MIN_HISTORY, MAX_HISTORY);
        Self {
            params,
            recent: VecDeque::with_capacity(params.history),
            sorted: Vec::with_capacity(params.history),
            refusals: 0,
            restarted: false,
        }
    }

    /// True when `matched` differs from the odometry prediction `predicted` by more than
    /// [`ValidationParams::max_odometry_chi2`] under the prior information `lambda` (both
    /// poses in the reference frame, whose x-y information is isotropic); never when the
    /// checks or this test are off.
    #[must_use]
    pub fn disagrees(&self, lambda: &Matrix3<f64>, predicted: &Pose2, matched: &Pose2) -> bool {
        if !self.params.enabled || self.params.max_odometry_chi2 <= 0.0 {
            return false;
        }
        odometry_chi2(lambda, predicted, matched) > self.params.max_odometry_chi2
    }

    /// True when a match that odometry's veto withheld is to be followed rather than the
    /// prediction ([`ValidationParams::veto_falls_back`]): when the scan points it explains
    /// beyond the prediction (`gained`, which may be negative), each worth
    /// [`ValidationParams::point_evidence`], outweigh half the χ² of its disagreement with
    /// odometry under the prior information `lambda`. Always true when the fall-back is off;
    /// `gained` is counted only when it is on.
    #[must_use]
    pub fn outweighs_odometry(
        &self,
        gained: impl FnOnce() -> f64,
        lambda: &Matrix3<f64>,
        predicted: &Pose2,
        matched: &Pose2,
    ) -> bool {
        if !self.params.veto_falls_back {
            return true;
        }
        let gained = gained();
        gained > 0.0
            && gained * self.params.point_evidence
                >= 0.5 * odometry_chi2(lambda, predicted, matched)
    }

    /// Share of `local` (scan points, laser frame) within `inlier_distance` of the reference
    /// surface when the scan sits at `pose`.
    #[must_use]
    pub fn inlier_share<I: SpatialIndex>(
        &self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
    ) -> f64 {
        self.seen_share(reference, local, pose, None)
    }

    /// As [`Validator::inlier_share`], over the points the reference could have seen: a point
    /// farther than twice `inlier_distance` from every reference point and outside `view`
    /// does not count ([`ValidationParams::skip_unseen`]). Every point counts without a view,
    /// and where none could have been seen.
    #[must_use]
    pub fn seen_share<I: SpatialIndex>(
        &self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
        view: Option<&FieldOfView>,
    ) -> f64 {
        let placed = Placed::new(reference, local, pose, self.reach());
        self.placed_share(reference, &placed, view)
    }

    /// How far from a point the check looks for the reference: twice `inlier_distance`.
    #[must_use]
    pub fn reach(&self) -> f64 {
        2.0 * self.params.inlier_distance
    }

    /// [`Validator::seen_share`] of a scan already placed and paired with the reference, the
    /// look-ups made once for the check and the hold. A placement made within less than
    /// [`Validator::reach`] is looked up again.
    #[must_use]
    pub fn placed_share<I: SpatialIndex>(
        &self,
        reference: &Reference<I>,
        placed: &Placed,
        view: Option<&FieldOfView>,
    ) -> f64 {
        let reach = self.reach();
        if placed.reach < reach {
            let points = placed.points.iter().map(|(p, _)| *p);
            let again = Placed::look_up(reference, points, placed.pose, reach);
            return self.placed_share(reference, &again, view);
        }
        let d = self.params.inlier_distance;
        let (mut explained, mut seen) = (0usize, 0usize);
        for (p, nearest) in &placed.points {
            let surface = nearest
                .filter(|n| n.dist_sq <= reach * reach)
                .map(|n| (reference.surface_foot(n.id, p) - p).norm_squared());
            // With no reference point within the reach a point is unexplained; outside the
            // view it was also unseen.
            if surface.is_none() && view.is_some_and(|v| !v.contains(p)) {
                continue;
            }
            seen += 1;
            explained += usize::from(surface.is_some_and(|e_sq| e_sq.sqrt() <= d));
        }
        // Where no point could have been seen (or the scan is empty), none is explained: the
        // share is 0, as counted over every point.
        if seen == 0 {
            return 0.0;
        }
        explained as f64 / seen as f64
    }

    /// The level below which a match is poor; `None` while the history is too short to tell.
    #[must_use]
    pub fn threshold(&mut self) -> Option<Level> {
        if self.recent.len() < MIN_HISTORY {
            return None;
        }
        let share = self.median(|f| f.share);
        let residual = self.median(|f| f.residual);
        let pairs = self.median(|f| f.pairs);
        let drop = self.params.max_pair_drop;
        Some(Level {
            min_share: (1.0 - self.params.max_share_drop) * share,
            max_residual: self.params.max_residual_ratio * residual,
            min_pairs: if drop > 0.0 {
                (1.0 - drop) * pairs
            } else {
                0.0
            },
        })
    }

    fn median(&mut self, of: impl Fn(&Fit) -> f64) -> f64 {
        self.sorted.clear();
        self.sorted.extend(self.recent.iter().map(of));
        let mid = self.sorted.len() / 2;
        *self.sorted.select_nth_unstable_by(mid, f64::total_cmp).1
    }

    /// Adds a checked share to the running level. Every checked scan counts, refused or not:
    /// a robot entering a new room sees less of the map for a while, and the level follows.
    pub fn record(&mut self, fit: Fit) {
        if !(fit.share.is_finite() && fit.residual.is_finite()) {
            return;
        }
        if self.recent.len() == self.params.history {
            self.recent.pop_front();
        }
        self.recent.push_back(fit);
    }

    /// Judges a recorded share against the level it was checked with: true when it is
    /// refused. The `max_refusals`-th refusal in a row clears the history, so the scene the
    /// robot has entered sets the next level.
    pub fn refuse(&mut self, fit: Fit, level: Option<Level>) -> bool {
        // A residual above the level makes a match suspect, not refused: people walking by, a
        // door left open raise the residual of right matches too.
        let refused = level.is_some_and(|l| fit.share < l.min_share);
        self.refusals = if refused { self.refusals + 1 } else { 0 };
        if self.refusals >= self.params.max_refusals {
            self.clear();
            self.restarted = true;
        }
        refused
    }

    /// Forgets the history (a new drive, a new scene).
    pub fn clear(&mut self) {
        self.recent.clear();
        self.refusals = 0;
        self.restarted = false;
    }

    /// True while a run of refusals has cleared the level and too few matches have been
    /// checked since to set a new one.
    #[must_use]
    pub fn restarting(&self) -> bool {
        self.restarted && self.recent.len() < MIN_HISTORY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(share: f64, residual: f64) -> Fit {
        Fit {
            share,
            residual,
            pairs: 100.0,
        }
    }

    #[test]
    fn a_refused_match_is_rescued_only_by_one_whose_only_fault_is_its_residual() {
        let level = Some(Level {
            min_share: 0.75,
            max_residual: 0.02,
            min_pairs: 80.0,
        });
        let refused = fit(0.2, 0.01);
        let loose = fit(0.99, 0.03);
        assert!(is_poor(loose, level));
        assert!(rescues_refused(refused, loose, level));
        // A first match that stands is not traded for a poor one.
        assert!(!rescues_refused(fit(0.8, 0.03), loose, level));
        // Too small a share, or too few pairs, is no rescue.
        assert!(!rescues_refused(refused, fit(0.7, 0.01), level));
        let few = Fit {
            pairs: 60.0,
            ..loose
        };
        assert!(!rescues_refused(refused, few, level));
        // Without a level nothing is refused, and nothing rescued.
        assert!(!rescues_refused(refused, loose, None));
    }

    #[test]
    fn a_validator_built_with_no_history_keeps_a_bounded_one_that_sets_a_level() {
        // Built directly, the parameters are not validated: a history of 0 once let the fits
        // pile up without bound, and one below five never set a level.
        for (history, kept) in [
            (0, MIN_HISTORY),
            (2, MIN_HISTORY),
            (usize::MAX, MAX_HISTORY),
        ] {
            let mut v = Validator::new(ValidationParams {
                history,
                ..ValidationParams::default()
            });
            for _ in 0..MAX_HISTORY + 10 {
                v.record(fit(0.9, 0.01));
            }
            assert_eq!(v.recent.len(), kept, "history {history}");
            assert!(v.threshold().is_some(), "history {history}");
        }
    }

    #[test]
    fn the_level_follows_the_median_of_recent_fits() {
        let mut v = Validator::new(ValidationParams {
            history: 5,
            ..ValidationParams::default()
        });
        for s in [0.9, 0.8, 0.9, 0.85] {
            v.record(fit(s, 0.01));
            assert_eq!(v.threshold(), None, "too few scans to judge");
        }
        v.record(fit(0.1, 0.03));
        let level = v.threshold().unwrap();
        assert!((level.min_share - 0.75 * 0.85).abs() < 1e-12);
        assert!((level.max_residual - 2.0 * 0.01).abs() < 1e-12);
        for _ in 0..5 {
            v.record(fit(0.3, 0.02));
        }
        let level = v.threshold().unwrap();
        assert!(
            (level.min_share - 0.75 * 0.3).abs() < 1e-12,
            "the old level is forgotten"
        );
        assert!((level.max_residual - 0.04).abs() < 1e-12);
        assert!(!is_poor(fit(0.3, 0.04), Some(level)));
        assert!(is_poor(fit(0.2, 0.01), Some(level)), "too small a share");
        assert!(is_poor(fit(0.9, 0.05), Some(level)), "too large a residual");
        assert!(!is_poor(fit(0.0, 1.0), None), "no level, no judgement");
    }

    /// Too few inliers: a match a turn short in a fast turn keeps 0.80 of its points near some
    /// surface (no drop past the share's level) but only half its usual pairs. The pair test
    /// makes it suspect (so it is searched); it does not refuse it, and at 0 it is off.
    #[test]
    fn a_match_left_with_half_its_usual_pairs_is_suspect_though_its_share_holds() {
        let mut v = Validator::new(ValidationParams::default());
        for n in [220.0, 230.0, 210.0, 225.0, 215.0, 240.0] {
            v.record(Fit {
                share: 0.98,
                residual: 0.012,
                pairs: n,
            });
        }
        let level = v.threshold().expect("a level");
        // The running median of six is its upper middle value, 225.
        assert!((level.min_pairs - 0.7 * 225.0).abs() < 1e-9, "{level:?}");
        let short = Fit {
            share: 0.80,
            residual: 0.020,
            pairs: 108.0,
        };
        assert!(short.share >= level.min_share, "the share alone passes");
        assert!(is_poor(short, Some(level)), "too few pairs");
        assert!(!v.refuse(short, Some(level)), "suspect, not refused");
        let mut off = Validator::new(ValidationParams {
            max_pair_drop: 0.0,
            ..ValidationParams::default()
        });
        for _ in 0..6 {
            off.record(Fit {
                share: 0.98,
                residual: 0.012,
                pairs: 220.0,
            });
        }
        assert!(!is_poor(short, off.threshold()), "the test switched off");
    }

    #[test]
    fn a_run_of_refusals_starts_a_new_level() {
        let mut v = Validator::new(ValidationParams::default());
        for _ in 0..10 {
            v.record(fit(0.95, 0.01));
        }
        let t = v.threshold();
        let (good, bad) = (fit(0.9, 0.01), fit(0.5, 0.01));
        assert!(!v.refuse(good, t));
        assert!(v.refuse(bad, t));
        assert!(!v.refuse(good, t), "an accepted match ends the run");
        assert!(v.refuse(bad, t) && v.refuse(bad, t));
        assert!(
            v.threshold().is_some(),
            "two refusals in a row keep the level"
        );
        assert!(v.refuse(bad, t));
        assert_eq!(v.threshold(), None, "the third starts afresh");
    }

    #[test]
    fn a_withheld_match_is_followed_only_on_points_that_outweigh_odometry() {
        // σ 1° in heading, 5 cm in x and y.
        let lambda =
            Matrix3::from_diagonal(&Vector3::new(400.0, 400.0, 1.0f64.to_radians().powi(-2)));
        let v = Validator::new(ValidationParams::default());
        let predicted = Pose2::IDENTITY;
        let turned = |deg: f64| Pose2::new(0.0, 0.0, deg.to_radians());
        // 33° off (χ² ≈ 1089): one point more is not enough, 200 are.
        assert!(!v.outweighs_odometry(|| 1.0, &lambda, &predicted, &turned(33.0)));
        assert!(v.outweighs_odometry(|| 200.0, &lambda, &predicted, &turned(33.0)));
        // 5° off (χ² 25): three points more (3 × 5 ≥ 12.5) are.
        assert!(v.outweighs_odometry(|| 3.0, &lambda, &predicted, &turned(5.0)));
        assert!(!v.outweighs_odometry(|| 2.0, &lambda, &predicted, &turned(5.0)));
        // None gained, or fewer: odometry's pose stands, however slight the disagreement.
        assert!(!v.outweighs_odometry(|| 0.0, &lambda, &predicted, &turned(4.1)));
        assert!(!v.outweighs_odometry(|| -3.0, &lambda, &predicted, &turned(4.1)));
        // With the fall-back off every withheld match is followed.
        let follow = Validator::new(ValidationParams {
            veto_falls_back: false,
            ..ValidationParams::default()
        });
        assert!(follow.outweighs_odometry(|| -3.0, &lambda, &predicted, &turned(33.0)));
        // … without counting the points.
        assert!(follow.outweighs_odometry(
            || unreachable!("counted with the fall-back off"),
            &lambda,
            &predicted,
            &turned(33.0)
        ));
    }

    #[test]
    fn a_re_match_without_a_level_replaces_only_a_clearly_worse_match_odometry_lets_pass() {
        let params = ValidationParams::default();
        let (first, near, turned) = (
            Pose2::IDENTITY,
            Pose2::new(0.05, 0.0, 0.0),
            Pose2::new(0.0, 0.0, 15f64.to_radians()),
        );
        // Odometry's veto withholds what is turned more than 10°.
        let vetoed = |p: &Pose2| p.theta.abs() > 10f64.to_radians();
        let replaces = |first_share: f64, again_share: f64, again: &Pose2, first: &Pose2| {
            replaces_without_level(
                &params,
                (fit(first_share, 0.02), first),
                (fit(again_share, 0.02), again),
                vetoed,
            )
        };
        // 0.3 is more than 25 % below 0.5, not below 0.38.
        assert!(replaces(0.3, 0.5, &near, &first));
        assert!(!replaces(0.3, 0.38, &near, &first));
        // A re-match the veto withholds does not replace one it lets pass …
        assert!(!replaces(0.3, 0.9, &turned, &first));
        // … but may replace one it withholds too, or replace a withheld one.
        assert!(replaces(0.3, 0.9, &turned, &turned));
        assert!(replaces(0.3, 0.9, &first, &turned));
    }
}
