//! # qicp-plicp
//!
//! PL-ICP (Censi, "An ICP variant using a point-to-line metric", ICRA 2008), the algorithm of
//! Censi's CSM, as a qicp plug-in written against the public qicp crates only.
//!
//! Each scan point is paired with a reference point and measured against the line through
//! it (its surface normal, which the reference keeps per point): the error of a pair is
//! `nᵀ(R·p + t − q)`. For fixed pairs this cost is minimised exactly rather than linearised:
//! with `x = (tx, ty, cos θ, sin θ)` it is quadratic in `x` under the constraint
//! `cos² θ + sin² θ = 1`, and the constrained minimum is found through its Lagrange
//! multiplier ([`solve`], Censi's appendix). Pairs are re-formed and the gate shrinks as in
//! every qicp ICP ([`qicp_matchers::IcpParams`]).
//!
//! [`register`] adds it to a [`Registry`] as `plicp`; the registry's composition then gives
//! its boosted forms without further code: `q-plicp` against a quad-tree map, `kd-plicp`
//! against a kd-tree map.
//!
//! ```
//! let mut registry = qicp_matchers::Registry::builtin();
//! qicp_plicp::register(&mut registry);
//! let q_plicp = registry.config("q-plicp").unwrap().build().unwrap();
//! assert_eq!(q_plicp.kind(), "q-plicp");
//! ```
#![warn(missing_docs)]

mod normals;
mod solve;
mod terms;

pub use solve::{PointToLine, solve};

use solve::SymmetricSums;
#[cfg(test)]
use terms::weight;
use terms::{CachedTerms, cached_terms};

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use qicp_core::{
    CorrespondenceMetric, Fallback, MatchResult, Pair, Point2, Pose2, Query, Reference, Scan,
    ScanMatcher, SpatialIndex,
};
use qicp_matchers::icp::{Schedule, move_points, residual, trim};
use qicp_matchers::lsq::NormalEquations;
use qicp_matchers::{Acts, Algorithm, ConfigError, IcpParams, Metric, Param, Range, Registry};
use serde::{Deserialize, Serialize};

/// PL-ICP's own parameters (TOML section `[matcher.plicp]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlIcpParams {
    /// Standard deviation of a pair's point-to-line distance (m): the range noise of both
    /// points and the line's own error. It weighs the pairs against the odometry prior.
    /// Default 0.02.
    pub sigma: f64,
    /// Weight of the along-line direction relative to the normal one (0: pure point-to-line,
    /// as Censi's). A correspondent may slide along its line by about σ_slide, so this is
    /// σ²/(σ² + σ_slide²); 0.05 is σ_slide ≈ 0.09 m, WSM's sliding term. Without it a map's
    /// corridors are fixed along their length by odometry alone. A reference point without
    /// a normal (a lone return) is always measured point to point. Default 0.05.
    pub tangent_weight: f64,
    /// Adaptive outlier rejection (Censi's CSM): a pair whose point-to-line distance exceeds
    /// `outlier_mult` times the `outlier_order` quantile of all the pairs' distances is
    /// dropped for that iteration. The quantile (0 < order ≤ 1). Default 0.7.
    pub outlier_order: f64,
    /// … and the multiple (0 turns the rejection off). Default 0 (off): the pairs that fix a
    /// corridor's length are its few far ones, and on Intel the rejection at 2 turned
    /// q-plicp's 0.058 m into 2.06 m.
    pub outlier_mult: f64,
    /// Normal compatibility: a pair whose two surface normals (the reference point's and
    /// the scan point's, turned into the reference frame) differ by more than this (deg)
    /// pairs two different surfaces and is dropped; 0 keeps every pair. Default 45.
    pub max_normal_angle_deg: f64,
    /// Against a scan (`reference = "scan"`), with an odometry prior: the first gate is the
    /// narrowest of the schedule that still holds this many of the prior's translation
    /// standard deviations (as IDC's). The wide gates exist for large initial errors, and
    /// between two consecutive scans odometry says how large they can be. 0 always starts at
    /// `matcher.icp.max_dist_start`. Default 3: on Intel plicp scored 0.434 m against 0.552 m
    /// at 0, and its whole sweep's geometric mean 0.515 m against 0.587 m.
    pub gate_sigmas: f64,
    /// The same against a map ([`Reference::is_map`]). A map's older passes are off from
    /// the estimate by the drift since they were seen, which one step's odometry does not
    /// bound, so the wide gates stay. Default 0 (off): on Intel q-plicp's whole sweep had a
    /// geometric mean of 0.039 m off and 0.056 m at 3.
    pub map_gate_sigmas: f64,
}

impl Default for PlIcpParams {
    fn default() -> Self {
        Self {
            sigma: 0.02,
            tangent_weight: 0.05,
            outlier_order: 0.7,
            outlier_mult: 0.0,
            max_normal_angle_deg: 45.0,
            gate_sigmas: 3.0,
            map_gate_sigmas: 0.0,
        }
    }
}

/// PL-ICP in the registry (`algorithm = "plicp"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PlIcpAlgorithm;

impl Algorithm for PlIcpAlgorithm {
    const NAME: &'static str = "plicp";
    /// A pair's weight holds the reference point's covariance, from the laser's noise.
    const WEIGHS_BY_LASER_NOISE: bool = true;
    const SUMMARY: &'static str = "point-to-line ICP with the exact solution (Censi 2008)";
    const PARAMETERS: &'static [Param] = &[
        Param::steering(
            "sigma",
            Range::Positive,
            "standard deviation of a pair's point-to-line distance (m)",
        ),
        Param::steering(
            "tangent_weight",
            Range::Closed(0.0, 1.0),
            "weight of the along-line direction (0: pure point-to-line)",
        ),
        Param::new(
            "outlier_order",
            Range::Closed(0.05, 1.0),
            "adaptive outlier rejection: the quantile of the pairs' point-to-line distances…",
        ),
        Param::steering(
            "outlier_mult",
            Range::NonNegative,
            "… times which a pair is dropped (0: off)",
        ),
        Param::steering(
            "max_normal_angle_deg",
            Range::Closed(0.0, 180.0),
            "a pair whose two surface normals differ more (deg) is dropped (0: off)",
        ),
        Param::steering(
            "gate_sigmas",
            Range::NonNegative,
            "against a scan, with a prior, the first gate holds this many translation σ (0: max_dist_start)",
        )
        .acting_on(Acts::Scan),
        Param::steering(
            "map_gate_sigmas",
            Range::NonNegative,
            "the same against a map (0: max_dist_start)",
        )
        .acting_on(Acts::Map),
    ];
    type Params = PlIcpParams;
    type Matcher<C: Metric> = PlIcp<C>;

    /// The last gate at 0.1 m instead of 0.2 m: a point-to-line pair across a wider gate
    /// measures against a line that is not the point's own.
    fn icp_defaults() -> IcpParams {
        IcpParams {
            max_dist_end: 0.1,
            ..IcpParams::default()
        }
    }

    fn matcher<C: Metric>(icp: IcpParams, params: &PlIcpParams) -> PlIcp<C> {
        PlIcp::new(icp, *params)
    }
}

/// Adds PL-ICP to `registry` as `plicp` (and so `q-plicp`, `kd-plicp`, …).
pub fn register(registry: &mut Registry) -> &mut Registry {
    registry.register::<PlIcpAlgorithm>()
}

/// The PL-ICP matcher; `C` pairs the points (the registry uses mutual nearest neighbours).
#[derive(Debug, Clone, Default)]
pub struct PlIcp<C> {
    /// Iteration parameters.
    pub icp: IcpParams,
    /// PL-ICP's parameters.
    pub params: PlIcpParams,
    metric: C,
    moved: Vec<Point2<f64>>,
    pairs: Vec<Pair>,
    scratch: Vec<f64>,
    /// The scan's own normals, in its frame.
    normals: Vec<Vector2<f64>>,
    /// Per scan point, the pair it last formed and that pair's terms of the system: a pair
    /// is mostly formed again in the next iteration, and its terms depend on it alone.
    terms: Vec<CachedTerms>,
    /// Which call of [`ScanMatcher::match_with_prior`] this is, so the entries of `terms`
    /// from earlier calls (another reference) never match; from 1.
    call: u32,
    /// Scratch of the scan's normals.
    connected: Vec<bool>,
    /// The plain computations the fast ones must equal bit for bit (tests only).
    #[cfg(test)]
    plain: bool,
}

impl<C: CorrespondenceMetric + Default> PlIcp<C> {
    /// PL-ICP with the given parameters.
    #[must_use]
    pub fn new(icp: IcpParams, params: PlIcpParams) -> Self {
        Self {
            icp,
            params,
            ..Self::default()
        }
    }
}

impl<C: CorrespondenceMetric> PlIcp<C> {
    /// The point-to-line system of the current pairs, with the prior's blocks.
    fn system<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        prior: Option<(&Matrix3<f64>, &Pose2)>,
    ) -> PointToLine {
        #[cfg(test)]
        if self.plain {
            return self.plain_system(reference, local, prior);
        }
        let mut sums = SymmetricSums::default();
        for p in &self.pairs {
            let terms = cached_terms(
                &mut self.terms,
                self.call,
                &self.params,
                reference,
                local,
                p,
            );
            sums.add_terms(terms);
        }
        let mut system = sums.system();
        if let Some((lambda, guess)) = prior {
            system.add_prior(lambda, guess);
        }
        system
    }

    /// The system as it is plainly written: a weight and a [`PointToLine::add`] per pair.
    #[cfg(test)]
    fn plain_system<I: SpatialIndex>(
        &self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        prior: Option<(&Matrix3<f64>, &Pose2)>,
    ) -> PointToLine {
        let refs = reference.index().points();
        let mut system = PointToLine::default();
        for p in &self.pairs {
            let w = weight(&self.params, reference, p.reference);
            system.add(&local[p.scan as usize], &refs[p.reference as usize], &w);
        }
        if let Some((lambda, guess)) = prior {
            system.add_prior(lambda, guess);
        }
        system
    }

    /// Information and variance factor of the pairs at `pose`, for the covariance.
    fn information<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
    ) -> NormalEquations {
        let refs = reference.index().points();
        let (rot, t) = (pose.rotation(), pose.translation());
        let mut ne = NormalEquations::default();
        for p in &self.pairs {
            let terms = cached_terms(
                &mut self.terms,
                self.call,
                &self.params,
                reference,
                local,
                p,
            );
            let w = Matrix2::new(terms[0], terms[1], terms[1], terms[2]);
            #[cfg(test)]
            let w = if self.plain {
                weight(&self.params, reference, p.reference)
            } else {
                w
            };
            let rb = rot * local[p.scan as usize].coords;
            ne.add(&refs[p.reference as usize], &rb, &t, &w);
        }
        ne
    }
}

impl<C: CorrespondenceMetric> ScanMatcher for PlIcp<C> {
    fn name(&self) -> &'static str {
        "plicp"
    }

    /// 0.05, as IDC's and WSM's: a relevant scan enters the map only where at least 5 % of
    /// its points lie farther than `novelty_distance` (5 cm) from it. Without the gate every
    /// pass over ground already mapped thickens the map: over 12 passes of the Intel log
    /// q-plicp's map grew from 53k to 139k points (46 MB at the peak) and 905 records of
    /// pass 12 lay more than 0.5 m from pass 1's poses; with it the map holds 35k points
    /// (25 MB) and none does.
    fn min_novelty(&self) -> f64 {
        0.05
    }

    fn match_with_prior<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan: &Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
    ) -> MatchResult {
        if let Some(why) = self.icp.cannot_match(scan, reference) {
            return MatchResult::fallback(guess, why);
        }
        let local = scan.points();
        self.metric.begin_scan(local);
        // The reference is another one in every call: earlier calls' terms are keyed apart.
        if self.call == u32::MAX {
            self.terms.clear();
            self.call = 0;
        }
        self.call += 1;
        if self.terms.len() < local.len() {
            self.terms.resize(local.len(), CachedTerms::default());
        }
        self.normals.clear();
        if self.params.max_normal_angle_deg > 0.0 {
            normals::scan_normals(scan, &mut self.connected, &mut self.normals);
            #[cfg(test)]
            if self.plain {
                let info = qicp_core::scan_point_info(scan, reference.noise());
                self.normals.clear();
                self.normals.extend(info.iter().map(|i| i.normal));
            }
        }
        let prior = prior.as_ref().map(|l| (l, &guess));
        let mut pose = guess;
        let mut converged = false;
        let mut iterations = 0;
        let gate_sigmas = if reference.is_map() {
            self.params.map_gate_sigmas
        } else {
            self.params.gate_sigmas
        };
        let first = self.icp.first_level(prior.map(|(l, _)| l), gate_sigmas);
        let mut schedule = Schedule::at(first);
        let mut last_step = Vector3::zeros();
        for it in 0..self.icp.max_iterations {
            iterations = it + 1;
            self.pair(reference, local, &pose, self.icp.gate(schedule.level));
            if self.pairs.len() < self.icp.min_correspondences {
                if it == 0 {
                    let found = self.pairs.len();
                    return MatchResult::fallback(guess, Fallback::TooFewCorrespondences { found });
                }
                break;
            }
            // paper (Censi 2008) §III: the exact minimiser of the point-to-line cost.
            let Some(mut next) = solve(&self.system(reference, local, prior)) else {
                return MatchResult::fallback(guess, Fallback::Degenerate);
            };
            // Exact steps can cycle between two pairings; a step that turns back on the last
            // one is halved, so the cycle contracts onto the pose between them.
            let step = Vector3::new(
                next.x - pose.x,
                next.y - pose.y,
                qicp_core::normalize_angle(next.theta - pose.theta),
            );
            if step.dot(&last_step) < 0.0 {
                next = Pose2::new(
                    pose.x + 0.5 * step.x,
                    pose.y + 0.5 * step.y,
                    pose.theta + 0.5 * step.z,
                );
                last_step = step * 0.5;
            } else {
                last_step = step;
            }
            let settled = self.icp.small_step(&pose, &next);
            pose = next;
            let final_stage = self.icp.at_last_gate(schedule.level);
            if schedule.advance(&self.icp, settled, final_stage) {
                converged = true;
                break;
            }
        }
        self.pair(reference, local, &pose, self.icp.max_dist_end);
        if self.pairs.len() < self.icp.min_correspondences {
            let found = self.pairs.len();
            return MatchResult::fallback(guess, Fallback::TooFewCorrespondences { found });
        }
        let mut ne = self.information(reference, local, &pose);
        qicp_matchers::wsm::add_prior(&mut ne, prior.map(|(l, _)| l), &guess, &pose);
        // A final system that cannot be inverted leaves a direction open: no match to trust.
        let Some(covariance) = ne.covariance() else {
            return MatchResult::fallback(guess, Fallback::Degenerate);
        };
        MatchResult {
            pose,
            covariance,
            iterations,
            correspondences: self.pairs.len(),
            residual: residual(reference, local, &self.pairs, &pose),
            converged,
            fallback: None,
        }
    }
}

impl<C: CorrespondenceMetric> PlIcp<C> {
    /// Forms the pairs at `pose` within `gate` and trims them.
    fn pair<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        pose: &Pose2,
        gate: f64,
    ) {
        move_points(pose, local, &mut self.moved);
        let query = Query {
            local,
            points: &self.moved,
            pose: *pose,
            max_dist: gate,
        };
        self.metric.pair(reference.index(), &query, &mut self.pairs);
        trim(
            &mut self.pairs,
            self.icp.trim,
            self.icp.max_dist_end,
            &mut self.scratch,
        );
        self.reject_incompatible(reference, pose);
        self.reject_outliers(reference);
    }

    /// Drops the pairs whose normals differ by more than `max_normal_angle_deg`.
    fn reject_incompatible<I: SpatialIndex>(&mut self, reference: &Reference<I>, pose: &Pose2) {
        if self.normals.is_empty() {
            return;
        }
        let cos_max = self.params.max_normal_angle_deg.to_radians().cos();
        let rot = pose.rotation();
        let info = reference.info();
        let normals = &self.normals;
        // `retain` by hand: its per-pair closure call cost more than the test.
        let mut kept = 0;
        for i in 0..self.pairs.len() {
            let p = self.pairs[i];
            let a = info[p.reference as usize].normal;
            let b = normals[p.scan as usize];
            if a == Vector2::zeros() || b == Vector2::zeros() || a.dot(&(rot * b)) >= cos_max {
                self.pairs[kept] = p;
                kept += 1;
            }
        }
        self.pairs.truncate(kept);
    }

    /// Drops the pairs whose point-to-line distance exceeds `outlier_mult` times the
    /// `outlier_order` quantile (CSM's adaptive rejection).
    fn reject_outliers<I: SpatialIndex>(&mut self, reference: &Reference<I>) {
        let (order, mult) = (self.params.outlier_order, self.params.outlier_mult);
        if mult == 0.0 || self.pairs.len() < 4 {
            return;
        }
        let refs = reference.index().points();
        let info = reference.info();
        let moved = &self.moved;
        let distance = |p: &Pair| {
            let d = moved[p.scan as usize] - refs[p.reference as usize];
            let n = info[p.reference as usize].normal;
            if n == Vector2::zeros() {
                d.norm()
            } else {
                d.dot(&n).abs()
            }
        };
        self.scratch.clear();
        self.scratch.extend(self.pairs.iter().map(distance));
        let k =
            ((self.scratch.len() as f64 * order).ceil() as usize).clamp(1, self.scratch.len()) - 1;
        let limit = *self.scratch.select_nth_unstable_by(k, f64::total_cmp).1 * mult;
        // Within the laser's noise every pair stays, however tight the others fit.
        let limit = limit.max(self.params.sigma);
        self.pairs.retain(|p| distance(p) <= limit);
    }
}

/// Refuses a parameter set that cannot work (kept for callers of the typed API; the
/// registry checks the same ranges from [`PlIcpAlgorithm::PARAMETERS`]).
impl PlIcpParams {
    /// Checks every value against its declared range; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        qicp_matchers::params::check_section("matcher.plicp", self, PlIcpAlgorithm::PARAMETERS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qicp_core::testdata::{SplitMix, SyntheticWorld};
    use qicp_core::{Merge, MutualNearest, QuadTree};

    /// One matcher kept across every match, as a pipeline keeps it: its caches must never
    /// carry a pair's terms from one reference into the next.
    #[test]
    fn the_fast_matcher_returns_the_plain_one_s_results_bit_for_bit() {
        let params = [
            PlIcpParams::default(),
            PlIcpParams {
                outlier_mult: 2.0,
                tangent_weight: 0.0,
                ..PlIcpParams::default()
            },
            PlIcpParams {
                max_normal_angle_deg: 0.0,
                gate_sigmas: 0.0,
                map_gate_sigmas: 3.0,
                ..PlIcpParams::default()
            },
        ];
        let mut rng = SplitMix::new(3);
        let mut compared = 0;
        for (k, params) in params.iter().enumerate() {
            let icp = PlIcpAlgorithm::icp_defaults();
            let mut fast = PlIcp::<MutualNearest<QuadTree>>::new(icp, *params);
            let mut plain = PlIcp::<MutualNearest<QuadTree>>::new(icp, *params);
            plain.plain = true;
            for world in [
                SyntheticWorld::room(),
                SyntheticWorld::corridor(),
                SyntheticWorld::posts(),
            ] {
                for round in 0..12 {
                    let at = Pose2::new(
                        rng.range(-0.5, 0.5),
                        rng.range(-0.5, 0.5),
                        rng.range(-3.0, 3.0),
                    );
                    // A reference of one scan, or a map of several merged.
                    let mut reference = Reference::new(QuadTree::default());
                    let scans = if round % 2 == 0 { 1 } else { 4 };
                    for s in 0..scans {
                        let from =
                            at * Pose2::new(0.1 * s as f64, 0.05 * s as f64, 0.02 * s as f64);
                        let merge = (s > 0).then(|| Merge::spacing(0.02));
                        reference
                            .insert_scan(&world.scan(&from, 0.01, rng.next_u64()), &from, merge)
                            .expect("finite points");
                    }
                    let truth = at
                        * Pose2::new(
                            rng.range(-0.3, 0.3),
                            rng.range(-0.3, 0.3),
                            rng.range(-0.2, 0.2),
                        );
                    let scan = world.scan(&truth, 0.01, rng.next_u64());
                    let guess = truth
                        * Pose2::new(
                            rng.range(-0.2, 0.2),
                            rng.range(-0.2, 0.2),
                            rng.range(-0.1, 0.1),
                        );
                    let prior = (round % 3 == 0)
                        .then(|| Matrix3::from_diagonal(&Vector3::new(100.0, 100.0, 400.0)));
                    let a = fast.match_with_prior(&reference, &scan, guess, prior);
                    let b = plain.match_with_prior(&reference, &scan, guess, prior);
                    assert_eq!(
                        format!("{a:?}"),
                        format!("{b:?}"),
                        "params {k}, round {round}"
                    );
                    compared += usize::from(a.fallback.is_none());
                }
            }
        }
        assert!(compared > 80, "{compared} matches compared");
    }
}
