//! Weighted Scan Matching (Pfister, Kriechbaum, Roumeliotis, Burdick 2002).

use crate::ConfigError;
use crate::icp::{IcpParams, move_points, residual, trim};
use crate::lsq::{NormalEquations, apply_step};
use crate::params::{Acts, Param, Range, check_section};
use crate::registry::{Algorithm, Metric};
use qicp_core::{
    ClosestPoint, CorrespondenceMetric, Fallback, LaserNoise, MatchResult, Matrix2, Matrix3, Pair,
    Point2, PointInfo, Pose2, Query, Reference, Scan, ScanMatcher, SpatialIndex, Vector2,
    scan_point_info,
};
use serde::{Deserialize, Serialize};

/// WSM's own parameters (TOML section `[matcher.wsm]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WsmParams {
    /// Scale of the sampling part of the correspondence error, uniform over the sample spacing
    /// s of the reference surface: variance (s²/12)·scale along the surface. Default 1.
    pub correspondence_scale: f64,
    /// The sliding part of the correspondence error (m): how far along a straight surface the
    /// true correspondent may lie because the pose is not yet exact. Adds its square to the
    /// variance along the surface where the reference point lies on a line; where it does not
    /// (a tree trunk, a corner, a lone point; see [`PointInfo::linearity`]) the slide is at
    /// most one sample spacing, which in a dense map is far less. Default 0.1.
    pub sigma_slide: f64,
    /// Share of the along-surface variance also assigned across the surface. Default 0.01.
    pub normal_fraction: f64,
    /// Against a map ([`Reference::is_map`]): a pair whose two points both lie on straight
    /// surfaces ([`PointInfo::linearity`] 1) with normals more than this apart (deg, the scan
    /// point's turned into the map) is dropped. A map holds both faces of a thin wall, seen
    /// from either side, and a point of one face pairs with the other within the gate; one
    /// scan, seen from one place, never holds both. Corners and clutter, whose normals are
    /// guesses, keep their pairs: at a corridor's door jambs they fix its length. 0: off.
    /// Default 90 (faces that look opposite ways).
    pub face_angle_deg: f64,
    /// Against a map ([`Reference::is_map`]), a stage whose gate is still wider than
    /// `matcher.icp.max_dist_end` ends once a step moves the scan's points by less than this
    /// fraction of the gate (root mean square): the next, narrower gate pairs them afresh.
    /// Scan to scan, where every match's error stays in the trajectory, every stage runs
    /// until the `matcher.icp` tolerances (or its iteration budget), as it does at 0.
    /// Default 0 (off), a speed knob: at 0.1 (with `settle_translation` 0.0005 and
    /// `settle_rotation_deg` 0.03) q-wsm ran 7.3 iterations a scan on Intel instead of 14.2
    /// (−20 % instructions) with its sweeps within their bounds, but a start far off (a
    /// record out of order without odometry, the constant-velocity prediction pointing the
    /// wrong way) converges in steps below a tenth of the wide gate and was left 0.3 m off
    /// where the full stage pulled it in (`tests/rosbag_cli.rs`'s bag without odometry,
    /// record 310; docs/robustness.md, last section).
    pub stage_tolerance: f64,
    /// Against a map, the last stage also settles when a step moves less than this (m)…
    /// Below it the steps are the jitter of pairs switching between the overlapping samples
    /// of a map, as IDC's
    /// ([`IdcParams::settle_translation`](crate::IdcParams::settle_translation)). Where the
    /// scan barely fixes a direction (a corridor), steps along it stay small while the
    /// estimate still slides: at 1 mm the matches of `matchers/tests/degeneracy.rs`'s
    /// 721-beam corridor stopped up to 10 mm short along its axis, at 0.5 mm 3.9 mm. Default
    /// 0 (with `settle_rotation_deg` 0: the `matcher.icp` tolerances alone); alone at 0.0005
    /// it saves little (13.4 iterations a scan on Intel against 14.2).
    pub settle_translation: f64,
    /// … and turns less than this (deg). Default 0.
    pub settle_rotation_deg: f64,
}

impl Default for WsmParams {
    fn default() -> Self {
        Self {
            correspondence_scale: 1.0,
            sigma_slide: 0.1,
            normal_fraction: 0.01,
            face_angle_deg: 90.0,
            stage_tolerance: 0.0,
            settle_translation: 0.0,
            settle_rotation_deg: 0.0,
        }
    }
}

/// WSM in the registry (`algorithm = "wsm"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct WsmAlgorithm;

impl Algorithm for WsmAlgorithm {
    const NAME: &'static str = "wsm";
    const SUMMARY: &'static str = "Weighted Scan Matching (Pfister et al. 2002)";
    const PARAMETERS: &'static [Param] = &[
        Param::new(
            "correspondence_scale",
            Range::Positive,
            "scale of the sampling part of the correspondence error",
        ),
        Param::steering(
            "sigma_slide",
            Range::NonNegative,
            "how far along a straight surface the true correspondent may lie (m)",
        ),
        Param::new(
            "normal_fraction",
            Range::Closed(0.0, 1.0),
            "share of the along-surface variance also assigned across it",
        ),
        Param::steering(
            "face_angle_deg",
            Range::Closed(0.0, 180.0),
            "against a map, a pair of two straight surfaces whose normals differ more (deg) is dropped (0: off)",
        )
        .acting_on(Acts::Map),
        Param::new(
            "stage_tolerance",
            Range::Closed(0.0, 1.0),
            "against a map, a wide stage ends when a step moves the points less than this fraction of the gate (0: off)",
        ),
        Param::new(
            "settle_translation",
            Range::NonNegative,
            "against a map, the last stage settles below this step (m)",
        ),
        Param::new(
            "settle_rotation_deg",
            Range::NonNegative,
            "… and below this turn (deg)",
        ),
    ];
    type Params = WsmParams;
    type Matcher<C: Metric> = Wsm<C>;

    fn matcher<C: Metric>(icp: IcpParams, params: &WsmParams) -> Wsm<C> {
        Wsm::new(icp, *params)
    }

    /// WSM weighs every pair by the laser's noise, so `[matcher.laser]` steers it.
    const WEIGHS_BY_LASER_NOISE: bool = true;
}

impl WsmParams {
    /// Checks every value against its declared range; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_section("matcher.wsm", self, WsmAlgorithm::PARAMETERS)
    }

    /// True when, against a map (`map`), the step from `pose` to `next` ends its stage early:
    /// at a wider gate than the last (`final_stage` false) when it moves the scan's points
    /// `local` by less than `stage_tolerance` × `gate` (root mean square); at the last when
    /// it moves less than `settle_translation` and turns less than `settle_rotation_deg`.
    /// Never scan to scan.
    #[must_use]
    pub fn settles(
        &self,
        pose: &Pose2,
        next: &Pose2,
        local: &[Point2<f64>],
        gate: f64,
        (final_stage, map): (bool, bool),
    ) -> bool {
        if !map {
            return false;
        }
        if final_stage {
            // Off (the default): no work per iteration.
            if self.settle_translation <= 0.0 {
                return false;
            }
            let turned = qicp_core::normalize_angle(pose.theta - next.theta).abs();
            return pose.distance(next) < self.settle_translation
                && turned < self.settle_rotation_deg.to_radians();
        }
        self.stage_tolerance > 0.0
            && !local.is_empty()
            && rms_motion(pose, next, local) < self.stage_tolerance * gate
    }

    /// Covariance of the correspondence error at a reference point (Pfister et al. Sec. IV):
    /// the scan point lands anywhere between two samples of the surface, so the error spreads
    /// along the surface with the sample spacing.
    #[must_use]
    pub fn correspondence_covariance(&self, at: &PointInfo) -> Matrix2<f64> {
        // Along a straight surface the correspondent may slide by σslide; on a curved one (a
        // trunk, a corner, a lone point) by no more than about one sample spacing.
        let slide = self.sigma_slide * self.sigma_slide;
        let l = at.linearity;
        let v = at.spacing * at.spacing / 12.0 * self.correspondence_scale
            + l * slide
            + (1.0 - l) * slide.min(at.spacing * at.spacing);
        if at.normal == Vector2::zeros() {
            return Matrix2::identity() * v;
        }
        let n = at.normal;
        let t = Vector2::new(-n.y, n.x);
        t * t.transpose() * v + n * n.transpose() * (v * self.normal_fraction)
    }
}

/// How far moving from `a` to `b` moves the points `local` (root mean square, m).
fn rms_motion(a: &Pose2, b: &Pose2, local: &[Point2<f64>]) -> f64 {
    let turn = b.rotation() - a.rotation();
    let shift = b.translation() - a.translation();
    let sum: f64 = local
        .iter()
        .map(|p| (turn * p.coords + shift).norm_squared())
        .sum();
    (sum / local.len() as f64).sqrt()
}

/// Adds the guess as a Gaussian prior: cost (guess − pose)ᵀ Λ (guess − pose).
pub fn add_prior(
    ne: &mut NormalEquations,
    prior: Option<&Matrix3<f64>>,
    guess: &Pose2,
    pose: &Pose2,
) {
    let Some(lambda) = prior else { return };
    let r = qicp_core::Vector3::new(
        guess.x - pose.x,
        guess.y - pose.y,
        qicp_core::normalize_angle(guess.theta - pose.theta),
    );
    ne.h += lambda;
    ne.g += lambda * r;
    ne.chi2 += r.dot(&(lambda * r));
    ne.dof += 3;
}

/// WSM: every pair is weighted by the inverse of its combined covariance (measurement noise of
/// both points plus correspondence error) and the weighted least squares is solved by
/// Gauss–Newton; the inverse information matrix is the pose covariance.
///
/// `C` pairs the points: [`ClosestPoint`] scan-to-scan, the paper's
/// [`MutualNearest`](qicp_core::MutualNearest) against a map (Q-WSM).
#[derive(Debug, Clone, Default)]
pub struct Wsm<C = ClosestPoint> {
    /// Iteration parameters.
    pub icp: IcpParams,
    /// WSM's parameters.
    pub params: WsmParams,
    metric: C,
    moved: Vec<Point2<f64>>,
    pairs: Vec<Pair>,
    scratch: Vec<f64>,
}

impl<C: CorrespondenceMetric + Default> Wsm<C> {
    /// WSM with the given parameters.
    #[must_use]
    pub fn new(icp: IcpParams, params: WsmParams) -> Self {
        Self {
            icp,
            params,
            ..Self::default()
        }
    }
}

impl<C: CorrespondenceMetric> Wsm<C> {
    /// Drops the pairs that join opposite faces of a thin wall
    /// ([`WsmParams::face_angle_deg`]); only against a map.
    fn drop_opposed_faces<I: SpatialIndex>(
        &mut self,
        reference: &Reference<I>,
        scan_info: &[PointInfo],
        pose: &Pose2,
    ) {
        let angle = self.params.face_angle_deg;
        if angle <= 0.0 || !reference.is_map() {
            return;
        }
        let cos_max = angle.to_radians().cos();
        let rot = pose.rotation();
        let info = reference.info();
        self.pairs.retain(|p| {
            let a = &info[p.reference as usize];
            let b = &scan_info[p.scan as usize];
            // Linearity 1 is a line within twice the range noise: its normal is no guess. A
            // point with no neighbour has linearity 0 (and a zero normal).
            a.linearity < 1.0 || b.linearity < 1.0 || a.normal.dot(&(rot * b.normal)) >= cos_max
        });
    }

    /// Pfister et al. Eq. (8)–(15): the weighted normal equations of the current pairs.
    fn normal_equations<I: SpatialIndex>(
        &self,
        reference: &Reference<I>,
        local: &[Point2<f64>],
        scan_info: &[PointInfo],
        pose: &Pose2,
    ) -> NormalEquations {
        let refs = reference.index().points();
        let info = reference.info();
        let rot = pose.rotation();
        let t = pose.translation();
        let mut ne = NormalEquations::default();
        for p in &self.pairs {
            let a = &info[p.reference as usize];
            let b = &scan_info[p.scan as usize];
            // P = C_a + R C_b Rᵀ + C_corr
            let cov = a.covariance
                + rot * b.covariance * rot.transpose()
                + self.params.correspondence_covariance(a);
            let Some(w) = cov.try_inverse() else { continue };
            ne.add(
                &refs[p.reference as usize],
                &(rot * local[p.scan as usize].coords),
                &t,
                &w,
            );
        }
        ne
    }
}

impl<C: CorrespondenceMetric> ScanMatcher for Wsm<C> {
    fn name(&self) -> &'static str {
        "wsm"
    }

    /// The laser's range noise, below which a new point adds no geometry.
    fn map_resolution(&self, noise: &LaserNoise) -> f64 {
        noise.sigma_range
    }

    /// 0.05, as IDC's: a relevant scan enters the map only where at least 5 % of its points
    /// lie farther than `novelty_distance` (5 cm) from it. Without the gate every pass over
    /// ground already mapped thickens the map: over 12 passes of the Intel log q-wsm's map
    /// grew from 103k to 278k points (peak memory 68 MB, pass 12 a median 0.024 m from
    /// pass 1's poses); with it from 54k to 59k (29 MB, 0.009 m), and its Intel sweep stays
    /// within its bounds (see the README's robustness section).
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
        let scan_info = scan_point_info(scan, reference.noise());
        self.metric.begin_scan(local);
        let mut pose = guess;
        let mut converged = false;
        let mut iterations = 0;
        let mut schedule = self.icp.schedule();
        for it in 0..self.icp.max_iterations {
            iterations = it + 1;
            let gate = self.icp.gate(schedule.level);
            move_points(&pose, local, &mut self.moved);
            let query = Query {
                local,
                points: &self.moved,
                pose,
                max_dist: gate,
            };
            self.metric.pair(reference.index(), &query, &mut self.pairs);
            trim(
                &mut self.pairs,
                self.icp.trim,
                self.icp.max_dist_end,
                &mut self.scratch,
            );
            self.drop_opposed_faces(reference, &scan_info, &pose);
            if self.pairs.len() < self.icp.min_correspondences {
                if it == 0 {
                    return MatchResult::fallback(
                        guess,
                        Fallback::TooFewCorrespondences {
                            found: self.pairs.len(),
                        },
                    );
                }
                break;
            }
            let mut ne = self.normal_equations(reference, local, &scan_info, &pose);
            add_prior(&mut ne, prior.as_ref(), &guess, &pose);
            let Some(step) = ne.solve() else {
                return MatchResult::fallback(guess, Fallback::Degenerate);
            };
            let next = apply_step(&pose, &step);
            let final_stage = self.icp.at_last_gate(schedule.level);
            let settled = self.icp.small_step(&pose, &next)
                || self.params.settles(
                    &pose,
                    &next,
                    local,
                    gate,
                    (final_stage, reference.is_map()),
                );
            pose = next;
            if schedule.advance(&self.icp, settled, final_stage) {
                converged = true;
                break;
            }
        }
        // Final pairs and information at the estimate: covariance = H⁻¹.
        move_points(&pose, local, &mut self.moved);
        let query = Query {
            local,
            points: &self.moved,
            pose,
            max_dist: self.icp.max_dist_end,
        };
        self.metric.pair(reference.index(), &query, &mut self.pairs);
        self.drop_opposed_faces(reference, &scan_info, &pose);
        if self.pairs.len() < self.icp.min_correspondences {
            // The estimate lost its support on the way (pairs fell out of the shrinking
            // gate): it and its near-singular covariance would be noise.
            return MatchResult::fallback(
                guess,
                Fallback::TooFewCorrespondences {
                    found: self.pairs.len(),
                },
            );
        }
        // The sliding term stays: without it a featureless corridor would claim to fix the
        // pose along its axis to the sample spacing (tests/wsm_covariance.rs).
        let mut ne = self.normal_equations(reference, local, &scan_info, &pose);
        add_prior(&mut ne, prior.as_ref(), &guess, &pose);
        // Pfister et al.: covariance = H⁻¹, scaled by the a-posteriori variance factor.
        // A final system that cannot be inverted leaves a direction open: no match to trust
        // (its placeholder covariance would pass for a real, very uncertain one).
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rms_motion_is_the_points_root_mean_square_displacement() {
        let ring: Vec<Point2<f64>> = (0..8)
            .map(|k| {
                let a = f64::from(k) * std::f64::consts::FRAC_PI_4;
                Point2::new(2.0 * a.cos(), 2.0 * a.sin())
            })
            .collect();
        let at = Pose2::new(1.0, -2.0, 0.7);
        // A shift moves every point by its length, a turn about the laser by the chord.
        let shifted = Pose2::new(1.03, -1.96, 0.7);
        assert!((rms_motion(&at, &shifted, &ring) - 0.05).abs() < 1e-12);
        let turned = Pose2::new(1.0, -2.0, 0.75);
        let chord = 2.0 * 2.0 * (0.025f64).sin();
        assert!((rms_motion(&at, &turned, &ring) - chord).abs() < 1e-12);
        // Against each point moved one by one.
        let both = Pose2::new(0.9, -2.1, 0.6);
        let brute = (ring
            .iter()
            .map(|p| (both.transform_point(p) - at.transform_point(p)).norm_squared())
            .sum::<f64>()
            / 8.0)
            .sqrt();
        assert!((rms_motion(&at, &both, &ring) - brute).abs() < 1e-12);
    }
}
