//! Laser odometry pipelines: a matcher plus a reference policy. Scan-to-scan (incremental) keeps
//! the previous scan; boosted (paper Alg. 1) keeps a map of every relevant scan.

use crate::ConfigError;
use crate::calibration::OdometryCalibration;
use crate::correlative::{CorrelativeParams, CorrelativeSearch};
use crate::icp::non_negative;
use crate::policy::{MapPolicy, Matched, ReferencePolicy, ReferenceStore, ScanPolicy};
use crate::revisit::{Revisit, RevisitParams};
use crate::trail::{Amendment, Trail, moves_fit};
use crate::validation::{
    Check, FieldOfView, Fit, Placed, ValidationParams, Validator, is_poor, odometry_chi2,
    replaces_without_level, rescues_refused,
};
use qicp_core::{
    Fallback, FullCell, LaserNoise, MatchResult, Matrix3, Merge, Point2, Pose2, PriorSource,
    Record, Reference, ScanMatcher, SpatialIndex,
};
use serde::{Deserialize, Serialize};

/// Alg. 1's relevance thresholds (TOML section `[matcher.relevance]`): which scans enter
/// the reference. Boosted pipelines add relevant scans to the map; incremental ones replace
/// their single reference scan with the latest relevant scan (0 and 0: every scan, the
/// classic scan-to-scan matcher).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Relevance {
    /// A scan is relevant when it moved more than this in x or y since the last relevant scan
    /// (τmax, m). Default 0.25.
    pub tau_max: f64,
    /// … or turned more than this (ρmax, deg). Default 5.
    pub rho_max_deg: f64,
    /// Boosted maps skip a new point closer than this to one they hold (m): the bound on the
    /// map's density, so that memory and per-scan time grow with the area explored, not with
    /// time. 0 inserts every point, as Alg. 1 reads (693k points on the Intel log).
    /// Default (`None`): the matcher's own [`ScanMatcher::map_resolution`], in typed and
    /// TOML-built pipelines alike: for WSM the laser's range noise `matcher.laser.sigma_range`
    /// (0.01), below which a new point adds no geometry; 0.02 for IDC, whose range rule's
    /// radius queries grow with the map's density (40 ms/scan on a corridor map without it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_resolution: Option<f64>,
    /// A new point within this many laser range-noise σ (`matcher.laser.sigma_range`) of the
    /// surface through its nearest map point, when that point was held before the scan, is
    /// not inserted ([`Merge::surface_band`]): the map holds that surface already, so a wall
    /// seen again thickens far less on each visit (points farther off still enter: the map's
    /// growth slows, it does not stop). Unlike the cell cap it never stops a second copy of a
    /// wall that lies off the first by more than the noise. 0 inserts such points, as Alg. 1
    /// reads.
    /// Default (`None`): the matcher's own [`ScanMatcher::surface_band_sigmas`], 1 (1 cm for
    /// the default laser; the Intel map holds 109,785 points instead of 159,906 for q-wsm),
    /// and 0 for IDC, whose matching-range rule needs every sample (see the README).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_band_sigmas: Option<f64>,
    /// A relevant scan enters a boosted map only when at least this share of its points lies
    /// farther than `novelty_distance` from every map point: a place the map already holds
    /// adds nothing on a revisit, so the map grows with the area explored, not with the
    /// number of visits (keyframe selection by overlap). 0 inserts every relevant scan, as
    /// Alg. 1 reads. Default (`None`): the matcher's own [`ScanMatcher::min_novelty`], 0.05
    /// for IDC (whose range rule slows with the map's density; on Intel it also scores
    /// better with it, and its sweep holds), for WSM (its Intel sweep holds with it, and its
    /// map over 12 passes of Intel grows by 10 % instead of 170 %) and for PL-ICP (its map
    /// over those passes holds 35k points instead of 139k).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_novelty: Option<f64>,
    /// How far (m) a scan point must lie from the map to count as new. Default 0.05, five
    /// times the range noise of the Intel laser: a point seen before and matched lies well
    /// within it.
    pub novelty_distance: f64,
    /// Side of the square cells of the map's cell cap (m). Default 0.1.
    pub cell_size: f64,
    /// A boosted map holds at most this many points in a cell of `cell_size` (0: no cap, as
    /// Alg. 1 reads), so its memory grows with the area explored, whatever the time spent
    /// there. What a full cell does with a new point is `full_cell`.
    /// Default (`None`): the count two surfaces crossing a cell diagonally put into it at the
    /// map's spacing, ⌈2√2 · `cell_size` / `map_resolution`⌉ ([`two_surfaces_cap`]): 29 for
    /// WSM's 1 cm, 15 for IDC's and PL-ICP's 2 cm; none where the map keeps every point
    /// (`map_resolution = 0`). The spacing, the surface band and the novelty gate keep most
    /// cells below it (on Intel it changes the boosted maps by about 1 %), so it binds where
    /// they do not: clutter the novelty gate lets in, a map laid over itself. It is a bound
    /// on memory per area, not a mechanism of accuracy (docs/robustness.md, "A cell cap on
    /// by default", has its sweeps). The points full cells replace leave the index in
    /// rebuilds, each of which restarts the map's age for re-anchoring's look-ups
    /// (`[matcher.revisit] age_scans`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_cell_points: Option<u32>,
    /// What a full cell does with a new point: `"evict_stalest"` (default) replaces the
    /// cell's point that scans have confirmed least recently; `"skip"` keeps its first points
    /// (a full cell then keeps the first copy of its wall, right or wrong: with it, at 20, the
    /// robustness sweep on Intel found twice as many fragile variants; see the README).
    pub full_cell: FullCell,
    /// A boosted map holds only the most recent relevant scans: at least this many and at
    /// most half as many again (it is rebuilt from the newest `window_scans` when it reaches
    /// 1.5 × that), so memory and per-scan time stay bounded on a drive of any length, at the
    /// price of the places left behind: a loop longer than the window is matched against
    /// its own recent scans, not against its start. Each rebuild starts the map's age afresh
    /// for re-anchoring's look-ups (`[matcher.revisit] age_scans`), so a window of at most
    /// twice `age_scans` scans never looks up its old map after its first rebuild. 0 keeps
    /// every relevant scan, as Alg. 1 reads. Default 0.
    pub window_scans: usize,
    /// Free-space carving ([`Merge::free_space_margin`], m): a map point that merged scans
    /// see through (both beams around its bearing return from beyond it by more than this)
    /// more often than they land on it, and at least twice, leaves the map. 0 (off) keeps
    /// every point, as Alg. 1 reads. Default 0.
    pub free_space_margin: f64,
}

/// Smallest and largest cell of the cell cap (m): cells finer than a millimetre would cap
/// nothing a laser resolves, and the cell coordinates of points within ±2³¹ m must fit.
const MIN_CELL_SIZE: f64 = 1e-3;
/// See [`MIN_CELL_SIZE`].
const MAX_CELL_SIZE: f64 = 1e3;
/// Largest map window (scans): far beyond any log's relevant scans (Intel has 4,000), small
/// enough that the window's arithmetic cannot overflow.
const MAX_WINDOW_SCANS: usize = 1_000_000;

/// Two odometry readings this close (m, and rad) are the same reading: a wheel that did not
/// turn. A stall repeats its reading exactly in a log as written, but readings recomposed
/// from increments (the sweep's perturbed odometry, a transform chain) keep rounding noise
/// of about 1e-13 m where the wheels stood. A CARMEN log writes micrometres, and a robot
/// that moves at all moves farther than this in one record.
const SAME_READING: f64 = 1e-8;

/// Whether `a` and `b` are one odometry reading up to rounding ([`SAME_READING`]).
fn same_reading(a: &Pose2, b: &Pose2) -> bool {
    (a.x - b.x).abs() <= SAME_READING
        && (a.y - b.y).abs() <= SAME_READING
        && qicp_core::normalize_angle(a.theta - b.theta).abs() <= SAME_READING
}

/// The default cell cap ([`Relevance::max_cell_points`]): the points two surfaces sampled at
/// `resolution` (m) put into a square cell of side `cell_size` when both cross it along its
/// diagonal, ⌈2√2 · `cell_size` / `resolution`⌉. 0 (no cap) where the map keeps every point
/// (`resolution` 0, as Alg. 1 reads).
#[must_use]
pub fn two_surfaces_cap(cell_size: f64, resolution: f64) -> u32 {
    if !(resolution > 0.0 && resolution.is_finite() && cell_size.is_finite()) {
        return 0;
    }
    // Saturating: a cap beyond u32 caps nothing anyway.
    (2.0 * std::f64::consts::SQRT_2 * cell_size / resolution)
        .ceil()
        .clamp(1.0, f64::from(u32::MAX)) as u32
}

impl Default for Relevance {
    fn default() -> Self {
        Self {
            tau_max: 0.25,
            rho_max_deg: 5.0,
            map_resolution: None,
            surface_band_sigmas: None,
            min_novelty: None,
            novelty_distance: 0.05,
            cell_size: 0.1,
            max_cell_points: None,
            full_cell: FullCell::EvictStalest,
            window_scans: 0,
            free_space_margin: 0.0,
        }
    }
}

impl Relevance {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        non_negative("matcher.relevance.tau_max", self.tau_max)?;
        non_negative("matcher.relevance.rho_max_deg", self.rho_max_deg)?;
        non_negative(
            "matcher.relevance.map_resolution",
            self.map_resolution.unwrap_or(0.0),
        )?;
        non_negative(
            "matcher.relevance.surface_band_sigmas",
            self.surface_band_sigmas.unwrap_or(0.0),
        )?;
        if let Some(share) = self.min_novelty
            && !(0.0..=1.0).contains(&share)
        {
            return Err(ConfigError::invalid(
                "matcher.relevance.min_novelty",
                format!("{share} must lie in [0, 1]"),
            ));
        }
        non_negative("matcher.relevance.novelty_distance", self.novelty_distance)?;
        non_negative(
            "matcher.relevance.free_space_margin",
            self.free_space_margin,
        )?;
        if !(self.cell_size.is_finite()
            && (MIN_CELL_SIZE..=MAX_CELL_SIZE).contains(&self.cell_size))
        {
            return Err(ConfigError::invalid(
                "matcher.relevance.cell_size",
                format!(
                    "{} must lie in [{MIN_CELL_SIZE}, {MAX_CELL_SIZE}]",
                    self.cell_size
                ),
            ));
        }
        if self.window_scans > MAX_WINDOW_SCANS {
            return Err(ConfigError::invalid(
                "matcher.relevance.window_scans",
                format!("{} must be at most {MAX_WINDOW_SCANS}", self.window_scans),
            ));
        }
        Ok(())
    }

    /// How a relevant scan is merged into a map whose matcher's own density bound is
    /// `matcher_resolution` and surface band `matcher_band_sigmas` (used where
    /// `map_resolution` and `surface_band_sigmas` are not set), for a laser whose range noise
    /// is `range_sigma` (m).
    #[must_use]
    pub fn merge(
        &self,
        matcher_resolution: f64,
        matcher_band_sigmas: f64,
        range_sigma: f64,
    ) -> Merge {
        let resolution = self.map_resolution.unwrap_or(matcher_resolution);
        Merge {
            resolution,
            cell_size: self.cell_size,
            max_cell_points: self.cell_cap(resolution),
            full_cell: self.full_cell,
            surface_band: self.surface_band_sigmas.unwrap_or(matcher_band_sigmas) * range_sigma,
            free_space_margin: self.free_space_margin,
        }
    }

    /// The cell cap of a map at `resolution` (m): `max_cell_points` where set, else its
    /// default ([`two_surfaces_cap`]).
    #[must_use]
    pub fn cell_cap(&self, resolution: f64) -> u32 {
        self.max_cell_points
            .unwrap_or_else(|| two_surfaces_cap(self.cell_size, resolution))
    }

    /// Whether a scan at `pose` shows enough the `map` does not hold yet (see
    /// [`Relevance::min_novelty`]; `matcher_min_novelty` where it is not set).
    #[must_use]
    pub fn is_novel<I: SpatialIndex + ?Sized>(
        &self,
        map: &I,
        scan: &qicp_core::Scan,
        pose: &Pose2,
        matcher_min_novelty: f64,
    ) -> bool {
        let points = scan.points();
        let min_novelty = self.min_novelty.unwrap_or(matcher_min_novelty);
        if min_novelty <= 0.0 || map.is_empty() || points.is_empty() {
            return true;
        }
        let reach = self.novelty_distance * self.novelty_distance;
        let novel = points
            .iter()
            .filter(|p| {
                map.nearest_within(&pose.transform_point(p), reach)
                    .is_none()
            })
            .count();
        novel as f64 >= min_novelty * points.len() as f64
    }

    /// paper Alg. 1: relevant if τ̂x > τmax or τ̂y > τmax or ρ̂ > ρmax.
    #[must_use]
    pub fn is_relevant(&self, motion: &Pose2) -> bool {
        motion.x.abs() > self.tau_max
            || motion.y.abs() > self.tau_max
            || motion.theta.abs() > self.rho_max_deg.to_radians()
    }
}

/// How far odometry is trusted (TOML section `[matcher.motion]`): the standard deviations
/// of an odometry motion of length d (m) turning by φ (rad). Matchers that weigh their pairs
/// (WSM) use it as a prior, so a scan that constrains only some directions (one tree in view,
/// a featureless corridor) keeps odometry's estimate in the others.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionModel {
    /// Use the prior at all. Default true.
    pub enabled: bool,
    /// σ of x and y: `sigma_xy_min + sigma_xy_per_m·d` (m). Default 0.05.
    pub sigma_xy_min: f64,
    /// Default 0.2 (m per m).
    pub sigma_xy_per_m: f64,
    /// σ of θ: `sigma_theta_min_deg + sigma_theta_per_m_deg·d + sigma_theta_per_rad·|φ|` (deg).
    /// Default 1.
    pub sigma_theta_min_deg: f64,
    /// Default 2 (deg per m).
    pub sigma_theta_per_m_deg: f64,
    /// Default 0.2 (rad per rad).
    pub sigma_theta_per_rad: f64,
    /// Distance driven (m) over which odometry's translation scale and rotational bias per
    /// metre are fitted to the accepted matches, and applied to every prediction
    /// ([`crate::calibration`]): a wheel that slips a few per cent otherwise biases every
    /// match the scan constrains little. Against a map only: scan to scan, each pair's own
    /// bias (a corridor's length measured short) would be learnt and fed back (on Intel idc
    /// 0.18 → 0.32 m, wsm 0.46 → 0.80 m). 0 (the default) predicts with odometry as it reads;
    /// 20 is a horizon that worked on Intel, whose odometry is biased (see the README's
    /// robustness section: it helps there and hurts q-wsm in the simulated park, whose slip
    /// is not a fixed bias).
    pub calibration_m: f64,
    /// Where odometry repeated one reading over several records (to within rounding: the
    /// readings of a perturbed or transformed copy of a log keep noise of 1e-13 m where the
    /// wheels stood) while the matches saw the robot move (they disagreed with it beyond its
    /// uncertainty), the first new reading is applied to the pose of the repeat's first
    /// record, not to the previous one: a reading that stalled and then caught up holds the
    /// whole motion since the stall began, and the matches during the stall have followed
    /// part of it already. A reading that jumped ahead first and then stalled (a log played
    /// backwards) holds only its own record's motion and is applied to the previous pose;
    /// the motion the matches followed over the stall tells the two apart. false applies
    /// every step to the previous pose. Default true. (The MIT CSAIL log stalls three times
    /// for four records and then jumps by up to 0.94 m and 85.5°; see the README.)
    pub stall_restart: bool,
    /// Where odometry repeats one reading while the matches saw the robot move (as for
    /// `stall_restart`), the repeated reading holds no motion: the stall's further records
    /// are predicted at the laser's last velocity (its motion over the last record whose
    /// match passed the check against a running level, or stood where odometry that moves
    /// weighed it and did not contradict it, as KISS-ICP predicts at constant velocity with
    /// no odometry; none before then or with validation off, where the last pose stands)
    /// and matched without odometry's prior, so that odometry's veto does not hold them to
    /// a robot standing still. A log with no odometry at all (every reading the same) is one
    /// such stall from its second record on. false predicts a stall's records where the
    /// repeated reading says, with its prior. Default true.
    pub stall_velocity: bool,
    /// With `stall_velocity`, in a log without odometry (every reading so far the first one),
    /// against a map, the prediction at the last checked velocity is weighed as a prior (by
    /// the matchers that take one: WSM weighs it against its pairs, IDC fuses it and sizes its
    /// first gate and window by it), with this many times the standard deviations this model
    /// gives the same motion by odometry: a constant velocity predicts less surely than wheels
    /// measure. Unlike odometry's prior it vetoes nothing; it keeps the prediction where the
    /// scan pins nothing, as along a corridor, where a match would otherwise slide and write a
    /// shifted copy of its walls into the map. Where a log's odometry stalls for a few records
    /// (a burst of jittered records with one reading, as Intel's) the velocity is no such
    /// prediction, and no prior is weighed (with one, 12 passes of Intel lost their map in
    /// passes 11 and 12). Scan to scan a slid match costs only its own step, and no prior is
    /// weighed (with one, on Intel without odometry, idc scored 0.877 m against 0.740 m).
    /// 0: no prior (the prediction only starts the match). Default 2. (On Intel with every
    /// odometry reading zeroed, the q-wsm sweep had 33 of 60 variants above 0.05 m without it,
    /// 6 at 2 and 6 at 5; see the README.)
    pub stall_prior_sigmas: f64,
    /// Along the direction of translation the scan constrains least, where the surfaces that
    /// face it tell less than the prior does (along a featureless corridor whose walls run
    /// past the laser's reach), the match keeps the prior's estimate, and its covariance the
    /// prior's (solution remapping, Zhang, Kaess and Singh 2016; [`crate::degeneracy`]). A
    /// match with a surface facing that direction is left as it is. Odometry's prior only,
    /// in a log whose odometry has moved: a stall's constant-velocity prediction is no
    /// measurement of how far the robot went, and held where it speeds up or stops it
    /// carries the old speed on (on Intel without odometry and with returns beyond 10 m
    /// dropped, q-wsm 0.373 → 1.38 m). Default true;
    /// false weighs every match against its prior inside the matcher alone, as before.
    pub hold_unobserved: bool,
}

impl Default for MotionModel {
    fn default() -> Self {
        Self {
            enabled: true,
            sigma_xy_min: 0.05,
            sigma_xy_per_m: 0.2,
            sigma_theta_min_deg: 1.0,
            sigma_theta_per_m_deg: 2.0,
            sigma_theta_per_rad: 0.2,
            calibration_m: 0.0,
            stall_restart: true,
            stall_velocity: true,
            stall_prior_sigmas: 2.0,
            hold_unobserved: true,
        }
    }
}

impl MotionModel {
    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        crate::icp::positive("matcher.motion.sigma_xy_min", self.sigma_xy_min)?;
        non_negative("matcher.motion.sigma_xy_per_m", self.sigma_xy_per_m)?;
        crate::icp::positive(
            "matcher.motion.sigma_theta_min_deg",
            self.sigma_theta_min_deg,
        )?;
        non_negative(
            "matcher.motion.sigma_theta_per_m_deg",
            self.sigma_theta_per_m_deg,
        )?;
        non_negative(
            "matcher.motion.sigma_theta_per_rad",
            self.sigma_theta_per_rad,
        )?;
        non_negative("matcher.motion.calibration_m", self.calibration_m)?;
        non_negative("matcher.motion.stall_prior_sigmas", self.stall_prior_sigmas)
    }

    /// Information matrix of an odometry motion, or `None` when disabled.
    #[must_use]
    pub fn information(&self, motion: &Pose2) -> Option<Matrix3<f64>> {
        if !self.enabled {
            return None;
        }
        let d = motion.x.hypot(motion.y);
        let sxy = self.sigma_xy_min + self.sigma_xy_per_m * d;
        let sth = (self.sigma_theta_min_deg + self.sigma_theta_per_m_deg * d).to_radians()
            + self.sigma_theta_per_rad * motion.theta.abs();
        Some(Matrix3::from_diagonal(&nalgebra::Vector3::new(
            1.0 / (sxy * sxy),
            1.0 / (sxy * sxy),
            1.0 / (sth * sth),
        )))
    }

    /// Information matrix of a stall's prediction at `velocity`
    /// ([`MotionModel::stall_prior_sigmas`]), or `None` when the prior or this one is off.
    #[must_use]
    pub fn stall_information(&self, velocity: &Pose2) -> Option<Matrix3<f64>> {
        let k = self.stall_prior_sigmas;
        if k <= 0.0 {
            return None;
        }
        self.information(velocity).map(|lambda| lambda / (k * k))
    }
}

/// What a pipeline says about one record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Robot pose in the world (the frame of the first record's odometry).
    pub pose: Pose2,
    /// The matcher's result (its pose is relative to the reference frame).
    pub result: MatchResult,
    /// Whether the scan entered the reference.
    pub inserted: bool,
    /// What the check before insertion said ([`crate::validation`]).
    pub check: Check,
}

/// A laser-odometry pipeline: feed records in time order, get robot poses.
/// Object-safe: the TOML registry hands these out as `Box<dyn Odometry>`.
pub trait Odometry: Send + std::fmt::Debug {
    /// The registry name, e.g. `"q-wsm"`.
    fn kind(&self) -> &str;
    /// Matches one record and updates the reference.
    fn process(&mut self, record: &Record) -> Estimate;
    /// Points held in the reference (the whole map for boosted pipelines): those the matcher
    /// pairs with, and any a full cell replaced or free-space carving removed that the map
    /// has not dropped yet ([`Reference::stale_len`]).
    fn reference_points(&self) -> &[Point2<f64>];
    /// The live points of the reference: [`Odometry::reference_points`] without those a full
    /// cell replaced ([`qicp_core::FullCell::EvictStalest`]) or carving removed
    /// ([`Relevance::free_space_margin`]). The map as it stands.
    fn live_points(&self) -> Vec<Point2<f64>> {
        self.reference_points().to_vec()
    }
    /// How many live points the reference holds: the length of [`Odometry::live_points`],
    /// without gathering them. The map's size as `qicp match` reports it (`map_points`).
    fn live_len(&self) -> usize {
        self.live_points().len()
    }
    /// A correction of earlier records' poses that the last [`Odometry::process`] made, once
    /// ([`RevisitParams::deform`]): a trajectory kept by the caller should take it. None by
    /// default.
    fn take_amendment(&mut self) -> Option<Amendment> {
        None
    }
    /// Whether [`Odometry::take_amendment`] can ever give one: a caller that keeps no
    /// trajectory otherwise keeps one only then. False by default.
    fn amends(&self) -> bool {
        false
    }
}

/// The built-in reference policies, for [`Pipeline::new`] (any [`ReferencePolicy`] will do).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Policy {
    /// Scan-to-scan: the reference is the latest relevant scan ([`ScanPolicy`]).
    Incremental(Relevance),
    /// Scan-to-map (paper Alg. 1): the reference is the map of all relevant scans
    /// ([`MapPolicy`]).
    Boosted(Relevance),
}

impl From<Policy> for Box<dyn ReferencePolicy> {
    fn from(policy: Policy) -> Self {
        match policy {
            Policy::Incremental(relevance) => Box::new(ScanPolicy::new(relevance)),
            Policy::Boosted(relevance) => Box::new(MapPolicy::new(relevance)),
        }
    }
}

/// The pipeline's reference as its policy sees it.
struct Store<'a, I> {
    reference: &'a mut Reference<I>,
    frame: &'a mut Pose2,
}

impl<I: SpatialIndex> ReferenceStore for Store<'_, I> {
    fn index(&self) -> &dyn SpatialIndex {
        self.reference.index()
    }
    fn clear(&mut self) {
        self.reference.clear();
    }
    fn insert_scan(&mut self, scan: &qicp_core::Scan, pose: &Pose2, merge: Option<Merge>) -> bool {
        self.reference.insert_scan(scan, pose, merge).is_ok()
    }
    fn set_frame(&mut self, frame: Pose2) {
        *self.frame = frame;
    }
}

/// Records that read one odometry value, from the first: a robot standing still, or odometry
/// that stopped updating while the robot moved (the MIT CSAIL log repeats a reading four
/// times, three times over, while the robot drives 0.5-0.9 m and turns up to 85°, and then
/// jumps by all of it at once).
#[derive(Debug, Clone, Copy)]
struct OdometryRun {
    /// Laser pose estimated at the run's first record.
    start: Pose2,
    /// Whether a match since then disagreed with odometry beyond its uncertainty
    /// ([`Validator::disagrees`]): the scans saw the robot move where odometry read none.
    contradicted: bool,
    /// Whether a match of the run, its first record's included, was refused: the motion the
    /// matches followed over the run is then not to be weighed against a new reading
    /// ([`Pipeline::restart_base`]).
    refused: bool,
}

impl OdometryRun {
    /// Extends `run` by a record whose reading repeats the previous one (`!fresh`), or starts a
    /// new run at it (`laser`). A record re-anchored by `correction` (the corrected laser pose
    /// times the inverse of the match's, in the world) moves the run's start with it: a
    /// restart after the stall then takes the reading's motion from where the stall began, in
    /// the corrected frame, neither losing the correction nor counting the stall's motion
    /// twice.
    fn follow(
        run: &mut Option<Self>,
        fresh: bool,
        (contradicted, refused): (bool, bool),
        laser: Pose2,
        correction: Option<Pose2>,
    ) {
        match run {
            Some(run) if !fresh => {
                if let Some(c) = correction {
                    run.start = c * run.start;
                }
                run.contradicted |= contradicted;
                run.refused |= refused;
            }
            _ => {
                *run = Some(Self {
                    start: laser,
                    contradicted: false,
                    refused,
                });
            }
        }
    }
}

/// Whether an accepted match's motion from the previous pose is the robot's own, for the
/// odometry calibration to learn: not refused, not withheld, and not re-anchored (a
/// re-anchored pose holds the drift it corrects, which is no motion of the wheels).
fn shows_wheel_motion(check: &Check) -> bool {
    !(check.refused || check.withheld || check.reanchored)
}

/// A matcher `M` with a reference held in index `I`.
#[derive(Debug)]
pub struct Pipeline<M, I> {
    kind: String,
    matcher: M,
    reference: Reference<I>,
    policy: Box<dyn ReferencePolicy>,
    motion: MotionModel,
    /// Pose of the reference frame in the world, as the policy sets it: the identity for a
    /// map, the reference scan's laser pose scan to scan.
    reference_frame: Pose2,
    /// What the last scan that entered the reference saw ([`ValidationParams::skip_unseen`]).
    view: Option<FieldOfView>,
    /// Odometry and estimated laser pose of the previous record.
    last: Option<(Pose2, Pose2)>,
    /// The laser's motion over the last record whose match passed the check, as matched (a
    /// re-anchoring's correction left out): the prediction where odometry stalled
    /// ([`MotionModel::stall_velocity`]). The identity until a match has passed.
    velocity: Pose2,
    /// The run of records that read the previous record's odometry (see [`OdometryRun`]).
    run: Option<OdometryRun>,
    /// The check before insertion, and its search.
    validator: Validator,
    /// The look-ups in the old map that re-anchor a match on a revisit.
    revisit: Revisit,
    /// The reference's [`renumberings`](Reference::renumberings) the look-ups know of.
    renumberings: u64,
    /// The records and the scans of the map, for spreading a re-anchoring's correction.
    trail: Trail,
    /// The latest spread correction not yet taken ([`Odometry::take_amendment`]).
    amendment: Option<Amendment>,
    /// The record (as the trail counts them) whose match odometry's veto last held at the
    /// prediction: a later match of the same run on old ground that the scan lets outweigh
    /// the veto closes a loop ([`RevisitParams::deform_followed`]).
    held: Option<usize>,
    search: CorrelativeSearch,
    /// Odometry's scale and drift, fitted to the accepted matches.
    calibration: OdometryCalibration,
    /// The first record's odometry reading, and whether a later one has differed from it:
    /// until one does, the log has no odometry ([`MotionModel::stall_prior_sigmas`]).
    first_reading: Option<Pose2>,
    odometry_moved: bool,
}

impl<M: ScanMatcher, I: SpatialIndex> Pipeline<M, I> {
    /// A pipeline named `kind` (for reports), with the defaults of the TOML registry: the
    /// odometry prior of [`MotionModel::default`], the checks of
    /// [`ValidationParams::default`] and [`CorrelativeParams::default`], the re-anchoring of
    /// [`RevisitParams::default`], and the matcher's own
    /// map resolution and surface band where `policy` leaves them unset. `noise` is the laser's
    /// (`[matcher.laser]` in TOML), held by the reference for every matcher. `Pipeline::new(..)` with default
    /// parameters and `Registry::config(name)?.build()` give the same poses.
    pub fn new(
        kind: impl Into<String>,
        matcher: M,
        index: I,
        policy: impl Into<Box<dyn ReferencePolicy>>,
        noise: LaserNoise,
    ) -> Self {
        Self {
            kind: kind.into(),
            matcher,
            reference: Reference::with_noise(index, noise),
            policy: policy.into(),
            motion: MotionModel::default(),
            reference_frame: Pose2::IDENTITY,
            view: None,
            last: None,
            velocity: Pose2::IDENTITY,
            run: None,
            validator: Validator::new(ValidationParams::default()),
            search: CorrelativeSearch::new(CorrelativeParams::default()),
            revisit: Revisit::new(RevisitParams::default()),
            renumberings: 0,
            trail: Trail::new(RevisitParams::default().age_scans),
            amendment: None,
            held: None,
            first_reading: None,
            odometry_moved: false,
            calibration: OdometryCalibration::default(),
        }
        .with_motion_model(MotionModel::default())
    }

    /// Checks matches as `validation` says, searching with `correlative` where they look wrong
    /// (and, with its `start_without_odometry`, starting ICP from it where a log has no
    /// odometry).
    #[must_use]
    pub fn with_validation(
        mut self,
        validation: ValidationParams,
        correlative: CorrelativeParams,
    ) -> Self {
        self.validator = Validator::new(validation);
        self.search = CorrelativeSearch::new(correlative);
        self
    }

    /// Re-anchors matches to the old map on a revisit as `revisit` says ([`crate::revisit`]).
    #[must_use]
    pub fn with_revisit(mut self, revisit: RevisitParams) -> Self {
        self.revisit = Revisit::new(revisit);
        self.trail = Trail::new(revisit.age_scans);
        self
    }

    /// Uses `motion` as the prior of every match.
    #[must_use]
    pub fn with_motion_model(mut self, motion: MotionModel) -> Self {
        self.motion = motion;
        // Against a map only: scan to scan the calibration stays off (see `calibration_m`).
        let horizon = if self.policy.is_map() {
            motion.calibration_m
        } else {
            0.0
        };
        self.calibration = OdometryCalibration::new(horizon);
        self
    }

    /// The reference (map or previous scan).
    pub fn reference(&self) -> &Reference<I> {
        &self.reference
    }

    /// Matches `scan` from `guess` and checks the match before it may enter the reference: a
    /// suspect match is searched again from the best pose of a correlative search around the
    /// prediction, and one that stays poor is refused (see [`crate::validation`]). The flag
    /// says whether the match passed the check against a running level (none before the
    /// check has seen enough matches to set one).
    /// `by_odometry`: the prior is odometry's, which alone may hold the directions the scan
    /// does not fix ([`MotionModel::hold_unobserved`]); otherwise it is a prediction
    /// ([`PriorSource`]).
    fn match_checked(
        &mut self,
        scan: &qicp_core::Scan,
        guess: Pose2,
        prior: Option<Matrix3<f64>>,
        (correlative_start, by_odometry): (bool, bool),
    ) -> (MatchResult, Check, bool) {
        // The hold keeps the prediction along what the scan does not fix, whatever start the
        // match came from: a re-match from the search's best pose along a featureless
        // corridor starts wherever the search's scores tied.
        let held = prior
            .filter(|_| by_odometry && self.motion.hold_unobserved)
            .map(|lambda| (lambda, guess));
        let source = if by_odometry {
            PriorSource::Odometry
        } else {
            PriorSource::Prediction
        };
        let local = scan.points();
        // Without odometry, ICP starts from the search's best pose around the prediction
        // ([`CorrelativeParams::start_without_odometry`]), and from the prediction only where
        // that match finds too few pairs.
        let started = (correlative_start && self.validator.params.enabled)
            .then(|| self.search.search(&self.reference, local, &guess))
            .flatten()
            .map(|start| self.match_from(scan, start.pose, (prior, source), held))
            .filter(|(m, ..)| m.fallback.is_none());
        let (mut result, mut was_held, placed) = match started {
            Some(m) => m,
            None => self.match_from(scan, guess, (prior, source), held),
        };
        if !self.validator.params.enabled {
            let check = Check {
                held: was_held,
                ..Check::UNCHECKED
            };
            return (result, check, false);
        }
        let level = self.validator.threshold();
        let mut fit = match result.fallback {
            None => self.fit(local, &result, placed.as_ref()),
            // Nothing within the gate: odometry may be far off, or the scan sees new ground.
            Some(Fallback::TooFewCorrespondences { found }) => Fit {
                share: 0.0,
                residual: f64::NAN,
                pairs: found as f64,
            },
            Some(_) => return (result, Check::UNCHECKED, false),
        };
        let mut check = Check::UNCHECKED;
        // After a run of refusals no level judges a match: every one is searched until
        // matches set a new level.
        let unleveled = self.validator.restarting();
        let search_all = unleveled && self.validator.params.search_after_refusals;
        if self.validator.params.search && (search_all || is_poor(fit, level)) {
            check.searched = true;
            if let Some(start) = self.search.search(&self.reference, local, &guess) {
                let (again, again_held, again_placed) =
                    self.match_from(scan, start.pose, (prior, source), held);
                if again.fallback.is_none() {
                    let f = self.fit(local, &again, again_placed.as_ref());
                    // Only a match that passes the check replaces the first: one poor
                    // match is not traded for another (an aliased corridor, a lone scan).
                    // Except a first match the check refuses, for one that only its
                    // residual makes suspect: that one would stand. With no level, the
                    // re-match must explain clearly more, and odometry must let it pass where
                    // it lets the first.
                    let replaces = if search_all {
                        let vetoed = |pose: &Pose2| {
                            prior.filter(|_| by_odometry).is_some_and(|lambda| {
                                self.validator.disagrees(&lambda, &guess, pose)
                            })
                        };
                        replaces_without_level(
                            &self.validator.params,
                            (fit, &result.pose),
                            (f, &again.pose),
                            vetoed,
                        )
                    } else {
                        !is_poor(f, level) || rescues_refused(fit, f, level)
                    };
                    if f.share > fit.share && replaces {
                        result = again;
                        fit = f;
                        check.recovered = true;
                        was_held = again_held;
                    }
                }
            }
        }
        let passed = result.fallback.is_none() && level.is_some() && !is_poor(fit, level);
        if result.fallback.is_none() {
            self.validator.record(fit);
            check.inlier_share = fit.share;
            check.refused = self.validator.refuse(fit, level);
            // A refused match is weighed against the prediction: where the prediction
            // explains the scan at least as well, the match went astray, and the next
            // prediction must not start from it. After a run of refusals has cleared the
            // level (a scene change, or a lost pose), a match has no level to judge it until
            // new matches set one; the prediction's share stands in for the running median,
            // and the match went astray where it falls more than `max_share_drop` below it.
            let astray = |predicted: f64| {
                if check.refused {
                    predicted >= fit.share
                } else {
                    self.validator.params.falls_below(fit.share, predicted)
                }
            };
            if (check.refused || unleveled) && astray(self.share(local, &guess, None)) {
                result = MatchResult::fallback(guess, Fallback::Refused);
            }
        }
        check.held = was_held && result.fallback.is_none();
        (result, check, passed)
    }

    /// The matcher's match of `scan` from `start` under `prior` (centred there, from
    /// `source`), holding the prediction in the direction the scan does not fix where `held`
    /// gives odometry's prior and the prediction ([`MotionModel::hold_unobserved`]), and
    /// whether it held. The scan placed at the match, paired with the reference within the
    /// check's reach, comes with it where the hold judged the match and left its pose as it
    /// was: the check reads the same look-ups.
    fn match_from(
        &mut self,
        scan: &qicp_core::Scan,
        start: Pose2,
        (prior, source): (Option<Matrix3<f64>>, PriorSource),
        held: Option<(Matrix3<f64>, Pose2)>,
    ) -> (MatchResult, bool, Option<Placed>) {
        let mut m = self
            .matcher
            .match_with_prior_from(&self.reference, scan, start, prior, source);
        let (Some((lambda, predicted)), None) = (held, m.fallback) else {
            return (m, false, None);
        };
        let placed = Placed::new(
            &self.reference,
            scan.points(),
            &m.pose,
            self.validator.reach(),
        );
        let weak = crate::degeneracy::weak_direction(
            &self.reference,
            &placed,
            self.validator.params.inlier_distance,
        );
        match weak {
            Some(weak)
                if crate::degeneracy::hold_unobserved(&mut m, &predicted, &lambda, &weak) =>
            {
                (m, true, None)
            }
            _ => (m, false, Some(placed)),
        }
    }

    /// Where the first new reading after a stall is applied from ([`MotionModel::stall_restart`]):
    /// the pose where the stall began, if the reading caught up with the whole motion since,
    /// or the previous pose (`laser`), if it holds only its own record's motion, as where the
    /// reading jumped ahead first and then stalled (the MIT CSAIL log played backwards reads
    /// each catch-up before its stall). The matches tell them apart: caught up, the reading's
    /// `step` exceeds the motion they followed over the stall by one record's motion; jumped
    /// ahead, it is one record's motion. The nearer of the two under the motion model's
    /// information for the step; the stall's start where they tie, where the model gives no
    /// information, or where a match of the run was refused (the motion followed is then no
    /// measure: a refused first match that stands may lie on an alias of the scene).
    fn restart_base(&self, run: &OdometryRun, laser: Pose2, step: &Pose2) -> Pose2 {
        let Some(lambda) = self.motion.information(step).filter(|_| !run.refused) else {
            return run.start;
        };
        // A motion's χ² from none at all.
        let chi2 = |d: Pose2| odometry_chi2(&lambda, &Pose2::IDENTITY, &d);
        let followed = run.start.between(&laser);
        if chi2(followed.between(step)) <= chi2(*step) {
            run.start
        } else {
            laser
        }
    }

    /// The share of the scan `local` at `pose` the reference explains, of the points it could
    /// have seen ([`ValidationParams::skip_unseen`]); from `placed`'s look-ups where it was
    /// placed at `pose`.
    fn share(&self, local: &[Point2<f64>], pose: &Pose2, placed: Option<&Placed>) -> f64 {
        let view = self.view.filter(|_| self.validator.params.skip_unseen);
        match placed.filter(|p| p.pose == *pose) {
            Some(placed) => self
                .validator
                .placed_share(&self.reference, placed, view.as_ref()),
            None => self
                .validator
                .seen_share(&self.reference, local, pose, view.as_ref()),
        }
    }

    /// What the check weighs of a match of the scan `local`: the share of it the reference
    /// explains, the residual and the pairs; from `placed`'s look-ups where it holds the
    /// match's ([`Pipeline::share`]).
    fn fit(&self, local: &[Point2<f64>], r: &MatchResult, placed: Option<&Placed>) -> Fit {
        Fit {
            share: self.share(local, &r.pose, placed),
            residual: r.residual,
            pairs: r.correspondences as f64,
        }
    }

    /// Looks the matched scan up in the old map ([`crate::revisit`]) and re-anchors the match
    /// there when the old map explains it much better nearby: true when it did.
    fn reanchor(&mut self, scan: &qicp_core::Scan, result: &mut MatchResult) -> bool {
        let local = scan.points();
        let Some(proposal) = self.revisit.propose(&self.reference, local, &result.pose) else {
            return false;
        };
        let again = self
            .matcher
            .match_with_prior(&self.reference, scan, proposal.start, None);
        if again.fallback.is_some()
            || !self
                .revisit
                .confirms(&self.reference, local, &again.pose, &proposal)
        {
            return false;
        }
        // The re-anchored match passes the check every match passes, as a search's recovery
        // must: one that holds far fewer pairs than recent matches, or leaves a larger
        // residual, fits the old map on a part of the scan only, where a stretch of it looks
        // alike (aliasing). And it must be pinned to within the tolerance the look-ups'
        // corrections are compared with: a few trunks fit the old map in many places.
        if is_poor(self.fit(local, &again, None), self.validator.threshold())
            || !Revisit::well_determined(&again)
        {
            return false;
        }
        if !self.revisit.corroborated(&result.pose, &again.pose) {
            return false;
        }
        *result = again;
        true
    }

    /// Whether a re-anchoring is spread over the stretch that drifted: against a map, with
    /// the checks, re-anchoring and `deform` on. Only then is the trail kept.
    fn spreads(&self) -> bool {
        let revisit = self.revisit.params();
        self.policy.is_map() && self.validator.params.enabled && revisit.enabled && revisit.deform
    }

    /// Spreads a re-anchoring's `correction` (in the world) over the stretch of map and
    /// trajectory that drifted, where the moved stretch fits the old map better
    /// ([`crate::trail`]); otherwise the correction stays a jump.
    fn deform(&mut self, correction: Pose2) {
        let (revisit, reference) = (&mut self.revisit, &self.reference);
        let Some(amendment) = self
            .trail
            .amendment(correction, |vouch| revisit.pins(reference, vouch))
        else {
            return;
        };
        let moves = self.trail.scan_moves(&amendment);
        if !moves_fit(&self.reference, &moves) {
            return;
        }
        if self
            .reference
            .deform(|stamp| moves.get(&stamp).copied())
            .is_err()
        {
            // A point moved out of the index's range: the map is empty and starts afresh.
            self.trail.cleared();
            self.view = None;
            return;
        }
        // The last scan in the map saw from where it now lies (one laid before the stretch
        // did not move).
        if let Some(view) = &mut self.view
            && let Some(by) = self
                .trail
                .last_scan_record()
                .and_then(|last| amendment.moved(last))
        {
            *view = view.moved(&by);
        }
        self.trail.anchored();
        self.amendment = Some(amendment);
    }

    /// A match followed against odometry's veto (`matched`, in the reference frame, against
    /// the prediction `guess`) on old ground, after the veto held an earlier match of the
    /// same run on old ground at its prediction, closes a loop: the scans have pulled towards
    /// the old map against odometry at least twice, the second time by enough points to
    /// outweigh it. Its correction of the prediction is the drift of the stretch since the
    /// robot left old ground, and is spread over it as a re-anchoring's is
    /// ([`RevisitParams::deform_followed`]). A lone odometry glitch (one reading off, the
    /// match right) is followed without a spread: no veto held a match before it. So is a
    /// correction after an excursion shorter than the map's age (`age_scans` records: a
    /// few records whose stamps stand out of order, a look through a door), which holds no
    /// loop's drift, and one more than `age_scans` records after the robot came back: the
    /// loop closed then, and a drift on old ground is the re-anchoring's to find.
    fn close_followed(&mut self, matched: &Pose2, guess: &Pose2) {
        let params = self.revisit.params();
        if !(self.spreads() && params.deform_followed) {
            return;
        }
        let followed = self.reference_frame * *matched;
        // Back from an excursion of `age_scans` records or more, within as many records, and
        // the veto held a match since.
        let closes = self.trail.came_back().is_some_and(|(back, excursion)| {
            excursion >= params.age_scans
                && self.trail.records() - back <= params.age_scans
                && self.held.is_some_and(|held| held >= back)
        });
        if closes && self.trail.on_old_ground(&followed) {
            self.deform(followed * (self.reference_frame * *guess).inverse());
        }
    }

    fn update_reference(&mut self, record: &Record, laser: &Pose2, result: &MatchResult) -> bool {
        let matched = Matched {
            scan: &record.scan,
            laser: *laser,
            result,
            map_resolution: self.matcher.map_resolution(self.reference.noise()),
            surface_band_sigmas: self.matcher.surface_band_sigmas(),
            min_novelty: self.matcher.min_novelty(),
            range_sigma: self.reference.noise().sigma_range,
        };
        let mut store = Store {
            reference: &mut self.reference,
            frame: &mut self.reference_frame,
        };
        self.policy.update(&mut store, &matched)
    }
}

impl<M, I> Odometry for Pipeline<M, I>
where
    M: ScanMatcher + Send + std::fmt::Debug,
    I: SpatialIndex + Send + std::fmt::Debug,
{
    fn kind(&self) -> &str {
        &self.kind
    }

    fn process(&mut self, record: &Record) -> Estimate {
        let offset = record.laser_offset;
        // The odometry motion since the previous record, as a motion of the laser.
        // Corrected by the calibration fitted so far: the prediction and the prior's centre.
        let fresh = self
            .last
            .is_none_or(|(odom, _)| !same_reading(&record.odometry, &odom));
        let first_reading = *self.first_reading.get_or_insert(record.odometry);
        self.odometry_moved |= !same_reading(&record.odometry, &first_reading);
        // A reading repeated while the matches saw the robot move holds no motion: the record
        // is predicted at the last checked velocity, without odometry's prior.
        let stalled =
            !fresh && self.motion.stall_velocity && self.run.is_some_and(|run| run.contradicted);
        // The pose the step is taken from: the previous record's, except where odometry
        // stalled and the scans saw the robot move on meanwhile. Then the first new reading
        // holds the whole motion since the stall began, which the matches have followed in
        // part already: taken from the previous pose it would be counted twice.
        let (predicted, step, raw, base) = match self.last {
            None => (
                record.odometry * offset,
                Pose2::IDENTITY,
                Pose2::IDENTITY,
                None,
            ),
            Some((_, laser)) if stalled => {
                (laser * self.velocity, self.velocity, Pose2::IDENTITY, None)
            }
            Some((odom, laser)) => {
                let raw = offset.inverse() * odom.between(&record.odometry) * offset;
                let step = self.calibration.correct(&raw);
                let base = match self.run {
                    Some(run) if fresh && run.contradicted && self.motion.stall_restart => {
                        self.restart_base(&run, laser, &step)
                    }
                    _ => laser,
                };
                (base * step, step, raw, Some(base))
            }
        };
        let guess = self.reference_frame.between(&predicted);
        // The prior's x-y block is isotropic, so it holds in the reference frame unrotated.
        let prior = if stalled {
            None
        } else {
            self.motion.information(&step)
        };
        let boosted = self.policy.is_map();
        // Against a map, in a log without odometry, the prediction at the last checked
        // velocity is weighed as a prior of its own, looser than odometry's, that vetoes
        // nothing: a scan that pins only some directions (a corridor) keeps the
        // constant-velocity prediction in the others, rather than slide and write a shifted
        // copy of its walls into the map.
        let without_odometry = stalled && boosted && !self.odometry_moved;
        let weighed = if stalled {
            without_odometry
                .then(|| self.motion.stall_information(&self.velocity))
                .flatten()
        } else {
            prior
        };
        let correlative_start = without_odometry && self.search.params.start_without_odometry;
        // Odometry's prior alone holds a direction, and only in a log whose odometry has
        // moved: in one without odometry the repeated reading is no measurement either.
        let by_odometry = !stalled && self.odometry_moved;
        let (mut result, mut check, passed) = self.match_checked(
            &record.scan,
            guess,
            weighed,
            (correlative_start, by_odometry),
        );
        // On a revisit the match may be re-anchored to the old map: a correction of drift,
        // which odometry's veto must not take back.
        // The match's laser pose in the world, before any re-anchoring.
        let matched = self.reference_frame * result.pose;
        check.reanchored = boosted
            && self.validator.params.enabled
            && result.fallback.is_none()
            && self.reanchor(&record.scan, &mut result);
        let vouched = self.revisit.take_vouched();
        if check.reanchored && self.spreads() {
            self.deform((self.reference_frame * result.pose) * matched.inverse());
        }
        // A refused match stays out of a map, and so does one that odometry contradicts
        // until a match agrees again. A scan-to-scan reference is replaced all the same: there
        // is no map to protect, and an older reference overlaps less.
        let contradicted = !check.reanchored
            && result.fallback.is_none()
            && prior.is_some_and(|lambda| self.validator.disagrees(&lambda, &guess, &result.pose));
        check.withheld = boosted && contradicted;
        // Odometry says the match moved where the robot did not; unless the scan explains
        // the match by enough points more than the prediction to outweigh odometry,
        // odometry's pose stands, as after a refusal.
        if check.withheld
            && let Some(lambda) = prior
        {
            let local = record.scan.points();
            let gained =
                || (check.inlier_share - self.share(local, &guess, None)) * local.len() as f64;
            if self
                .validator
                .outweighs_odometry(gained, &lambda, &guess, &result.pose)
            {
                self.close_followed(&result.pose, &guess);
            } else {
                result = MatchResult::fallback(guess, Fallback::Refused);
                self.held = Some(self.trail.records());
            }
        }
        let laser = self.reference_frame * result.pose;
        if self.spreads() {
            self.trail.record(&laser);
            // The old map explained this match nearly whole, and the match stands.
            if let Some(vouch) = vouched
                && result.fallback.is_none()
            {
                self.trail.vouched(vouch);
            }
        }
        let protect = boosted && (check.refused || check.withheld);
        let inserted = !protect && self.update_reference(record, &laser, &result);
        if inserted {
            self.view = Some(FieldOfView::of(
                &record.scan,
                self.reference_frame.between(&laser),
            ));
        }
        if boosted && self.reference.renumberings() != self.renumberings {
            self.renumberings = self.reference.renumberings();
            self.revisit.renumbered();
            self.trail.unvouched();
        }
        if inserted && boosted {
            self.revisit.inserted(self.reference.index().len());
        }
        if inserted && self.spreads() {
            let scans = self.reference.scans();
            if scans == 1 {
                self.trail.cleared();
            }
            let stamp = u32::try_from(scans - 1).unwrap_or(u32::MAX);
            self.trail.inserted(stamp, &laser);
        }
        if let Some(before) = base
            && result.fallback.is_none()
            && shows_wheel_motion(&check)
        {
            self.calibration.learn(&raw, &before.between(&laser));
        }
        // In the world: the corrected laser pose times the inverse of the match's.
        let correction = check.reanchored.then(|| laser * matched.inverse());
        OdometryRun::follow(
            &mut self.run,
            fresh,
            (contradicted, check.refused),
            laser,
            correction,
        );
        // The motion as matched, where the match stands and something vouches for it: it
        // passed the check, or odometry that moves weighed it and did not contradict it (a
        // fast turn's matches keep too few pairs for the level, and a stall right after must
        // not be predicted at the motion of some earlier turn). A re-anchoring's correction is
        // drift, not velocity. Elsewhere the last such motion stays: a poor match's motion
        // would carry its error into the next prediction.
        let vouched_by_wheels =
            self.validator.params.enabled && by_odometry && !check.refused && !contradicted;
        if let Some((_, previous)) = self.last
            && (passed || vouched_by_wheels)
            && result.fallback.is_none()
            && !check.withheld
        {
            self.velocity = previous.between(if check.reanchored { &matched } else { &laser });
        }
        self.last = Some((record.odometry, laser));
        Estimate {
            pose: laser * offset.inverse(),
            result,
            inserted,
            check,
        }
    }

    fn reference_points(&self) -> &[Point2<f64>] {
        self.reference.index().points()
    }

    fn live_points(&self) -> Vec<Point2<f64>> {
        self.reference.live_points()
    }

    fn live_len(&self) -> usize {
        self.reference.len() - self.reference.stale_len()
    }

    fn take_amendment(&mut self) -> Option<Amendment> {
        self.amendment.take()
    }

    fn amends(&self) -> bool {
        self.spreads()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reanchoring_is_not_learnt_as_wheel_motion() {
        assert!(shows_wheel_motion(&Check::UNCHECKED));
        for flag in 0..3 {
            let mut check = Check::UNCHECKED;
            match flag {
                0 => check.refused = true,
                1 => check.withheld = true,
                _ => check.reanchored = true,
            }
            assert!(!shows_wheel_motion(&check), "{check:?}");
        }
    }

    #[test]
    fn a_reanchoring_during_a_stall_moves_the_stall_start_with_it() {
        let start = Pose2::new(1.0, 0.0, 0.0);
        let mut run = None;
        OdometryRun::follow(&mut run, true, (false, false), start, None);
        // The reading repeats and a match contradicts it: the stall's run holds on.
        OdometryRun::follow(
            &mut run,
            false,
            (true, false),
            Pose2::new(1.3, 0.0, 0.0),
            None,
        );
        assert!(run.is_some_and(|r| r.contradicted && r.start == start));
        // A re-anchoring with the reading still repeated: the match at (1.6, 0) is moved to
        // (1.9, 0.2) turned by 0.05 rad, and the stall's start moves by the same correction.
        let (matched, corrected) = (Pose2::new(1.6, 0.0, 0.0), Pose2::new(1.9, 0.2, 0.05));
        let correction = corrected * matched.inverse();
        OdometryRun::follow(&mut run, false, (false, false), corrected, Some(correction));
        let moved = run.map(|r| r.start).expect("a run");
        // The stall's start keeps its place relative to the match: 0.6 m behind it.
        let behind = moved.between(&corrected);
        assert!(
            (behind.x - 0.6).abs() < 1e-12 && behind.y.abs() < 1e-12,
            "{behind:?}"
        );
        assert!(run.is_some_and(|r| r.contradicted));
        // A fresh reading starts a new run.
        OdometryRun::follow(
            &mut run,
            true,
            (false, false),
            Pose2::new(2.5, 0.2, 0.05),
            None,
        );
        assert!(run.is_some_and(|r| !r.contradicted && r.start.x == 2.5));
    }
}
