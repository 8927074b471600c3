//! Reference policies: what a [`Pipeline`](crate::Pipeline) matches each scan against, and how
//! a matched scan changes it.
//!
//! Two are built in and registered by name: [`MapPolicy`] (`reference = "map"`, paper Alg. 1:
//! a map of every relevant scan) and [`ScanPolicy`] (`reference = "scan"`: the latest relevant
//! scan). Another crate implements [`ReferencePolicy`] and registers it with
//! [`Registry::register_reference`](crate::Registry::register_reference); every algorithm and
//! index then runs against it, named `<algorithm>+<reference>` (`wsm+window`).

use crate::pipeline::Relevance;
use qicp_core::{Fallback, MatchResult, Merge, Pose2, Scan, SpatialIndex};
use std::collections::VecDeque;
use std::fmt::Debug;
use std::sync::{Arc, LazyLock};

/// A reference policy. The pipeline matches each scan against the reference, checks the match,
/// and then calls [`update`](Self::update), which decides what of the scan enters the
/// reference.
pub trait ReferencePolicy: Send + Debug {
    /// True when the reference is a map in the world frame that later scans are matched
    /// against for good: the pipeline then keeps a refused match, and one odometry
    /// contradicts, out of it (see [`crate::validation`]), and reports the policy as boosted.
    /// False for a reference that is replaced as the robot moves on (scan to scan). A
    /// constant of the policy: the registry asks it once, of a policy made with the default
    /// [`Relevance`], to tell boosted matchers from their scan-to-scan twins.
    fn is_map(&self) -> bool;

    /// Updates `reference` with the scan just matched; returns whether the scan entered it.
    fn update(&mut self, reference: &mut dyn ReferenceStore, matched: &Matched<'_>) -> bool;
}

/// The scan a pipeline just matched, for [`ReferencePolicy::update`].
#[derive(Debug, Clone, Copy)]
pub struct Matched<'a> {
    /// The scan, in the laser frame.
    pub scan: &'a Scan,
    /// Its laser pose in the world.
    pub laser: Pose2,
    /// The match (its pose relative to the reference frame); a fallback says why there is no
    /// match.
    pub result: &'a MatchResult,
    /// The matcher's own bound on a map's density (m): the default of
    /// [`Relevance::map_resolution`].
    pub map_resolution: f64,
    /// The matcher's own surface band ([`ScanMatcher::surface_band_sigmas`]): the default of
    /// [`Relevance::surface_band_sigmas`].
    ///
    /// [`ScanMatcher::surface_band_sigmas`]: qicp_core::ScanMatcher::surface_band_sigmas
    pub surface_band_sigmas: f64,
    /// The matcher's own novelty share ([`ScanMatcher::min_novelty`]): the default of
    /// [`Relevance::min_novelty`].
    ///
    /// [`ScanMatcher::min_novelty`]: qicp_core::ScanMatcher::min_novelty
    pub min_novelty: f64,
    /// The laser's range noise σ (m), held by the reference: the unit of
    /// [`Relevance::surface_band_sigmas`].
    pub range_sigma: f64,
}

/// The reference as a policy sees it: the points (in the reference frame) and the frame's pose
/// in the world.
pub trait ReferenceStore {
    /// The points held.
    fn index(&self) -> &dyn SpatialIndex;
    /// Forgets every point.
    fn clear(&mut self);
    /// Inserts the points of `scan` seen from `pose` (in the reference frame), merged as
    /// `merge` says (`None`: every point); false if a point could not be held (non-finite or
    /// beyond the index's range), in which case the scan is not inserted.
    fn insert_scan(&mut self, scan: &Scan, pose: &Pose2, merge: Option<Merge>) -> bool;
    /// Moves the reference frame to `frame` (a pose in the world). Scans are matched from the
    /// odometry prediction expressed in this frame.
    fn set_frame(&mut self, frame: Pose2);
}

/// Scan to map (paper Alg. 1, `reference = "map"`): every relevant scan enters one map in the
/// world frame, merged as [`Relevance`] bounds it (minimum spacing, cell cap, novelty, window).
#[derive(Debug, Clone, Default)]
pub struct MapPolicy {
    relevance: Relevance,
    /// Laser pose of the last scan inserted.
    last_inserted: Option<Pose2>,
    /// The scans of a windowed map ([`Relevance::window_scans`]) and their laser poses,
    /// oldest first.
    window: VecDeque<(Scan, Pose2)>,
}

impl MapPolicy {
    /// The policy with these thresholds and bounds.
    #[must_use]
    pub fn new(relevance: Relevance) -> Self {
        Self {
            relevance,
            ..Self::default()
        }
    }
}

/// Whether a scan moved far enough from the last one inserted to enter a reference.
fn is_relevant(relevance: &Relevance, last_inserted: Option<Pose2>, laser: &Pose2) -> bool {
    last_inserted.is_none_or(|last| relevance.is_relevant(&last.between(laser)))
}

/// A reference needs three points for a match.
fn enough_points(scan: &Scan) -> bool {
    scan.valid_count() >= 3
}

impl ReferencePolicy for MapPolicy {
    fn is_map(&self) -> bool {
        true
    }

    fn update(&mut self, reference: &mut dyn ReferenceStore, m: &Matched<'_>) -> bool {
        let relevance = self.relevance;
        // A relevant scan enters the map even when it could not be matched for lack of
        // correspondences: it sees territory the map does not hold yet, and its odometry pose
        // is the best estimate there is. Without it the map would stop growing and every later
        // scan would fall back too.
        let trusted = m.result.fallback.is_none()
            || matches!(
                m.result.fallback,
                Some(Fallback::TooFewCorrespondences { .. } | Fallback::EmptyReference)
            );
        if !(enough_points(m.scan)
            && is_relevant(&relevance, self.last_inserted, &m.laser)
            && trusted)
        {
            return false;
        }
        if !relevance.is_novel(reference.index(), m.scan, &m.laser, m.min_novelty) {
            return false;
        }
        // paper Alg. 1: insert all scan points of s_global into Q_t
        let merge = Some(relevance.merge(m.map_resolution, m.surface_band_sigmas, m.range_sigma));
        let inserted = reference.insert_scan(m.scan, &m.laser, merge);
        if inserted && relevance.window_scans > 0 {
            self.window.push_back((m.scan.clone(), m.laser));
            let keep = relevance.window_scans;
            if self.window.len() >= keep + keep.div_ceil(2) {
                // Rebuilt from the newest scans, merged in their order as they were.
                self.window.drain(..self.window.len() - keep);
                reference.clear();
                for (scan, pose) in &self.window {
                    // These points were finite when first inserted.
                    let _ = reference.insert_scan(scan, pose, merge);
                }
            }
        }
        if inserted {
            self.last_inserted = Some(m.laser);
        }
        inserted
    }
}

/// Scan to scan (`reference = "scan"`): the reference is the latest relevant scan, in its own
/// frame ([`Relevance`]'s thresholds 0 and 0: every scan, the classic scan-to-scan matcher).
#[derive(Debug, Clone, Default)]
pub struct ScanPolicy {
    relevance: Relevance,
    /// Laser pose of the reference scan.
    last_inserted: Option<Pose2>,
}

impl ScanPolicy {
    /// The policy with these thresholds.
    #[must_use]
    pub fn new(relevance: Relevance) -> Self {
        Self {
            relevance,
            last_inserted: None,
        }
    }
}

impl ReferencePolicy for ScanPolicy {
    fn is_map(&self) -> bool {
        false
    }

    fn update(&mut self, reference: &mut dyn ReferenceStore, m: &Matched<'_>) -> bool {
        let matched = m.result.fallback.is_none();
        let relevant = is_relevant(&self.relevance, self.last_inserted, &m.laser);
        // A scan that could not be matched against the reference replaces it: the robot has
        // left what the old one saw. Not one too sparse to be matched at all (fewer valid
        // beams than the matcher's minimum): the next scan would find nothing in it either.
        let too_sparse = matches!(m.result.fallback, Some(Fallback::TooFewPoints { .. }));
        let replaces = enough_points(m.scan) && !too_sparse && (relevant || !matched);
        if !replaces {
            return false;
        }
        reference.clear();
        reference.set_frame(m.laser);
        let inserted = reference.insert_scan(m.scan, &Pose2::IDENTITY, None);
        if inserted {
            self.last_inserted = Some(m.laser);
        }
        inserted
    }
}

type PolicyFactory = Arc<dyn Fn(&Relevance) -> Box<dyn ReferencePolicy> + Send + Sync>;

/// A reference policy as the registry knows it: which scans the matcher is matched against.
#[derive(Clone)]
pub struct ReferenceEntry {
    name: &'static str,
    summary: &'static str,
    map: bool,
    make: PolicyFactory,
}

impl ReferenceEntry {
    /// Registry name, e.g. `"map"`.
    #[must_use]
    pub fn name(&self) -> &'static str {
        self.name
    }
    /// One line for listings.
    #[must_use]
    pub fn summary(&self) -> &'static str {
        self.summary
    }
    /// Whether the policy keeps a map ([`ReferencePolicy::is_map`]): its matchers are the
    /// boosted ones.
    #[must_use]
    pub fn is_map(&self) -> bool {
        self.map
    }
    /// A policy made by `make` under `name`; see
    /// [`Registry::register_reference`](crate::Registry::register_reference).
    pub(crate) fn new(
        name: &'static str,
        summary: &'static str,
        make: impl Fn(&Relevance) -> Box<dyn ReferencePolicy> + Send + Sync + 'static,
    ) -> Self {
        Self {
            name,
            summary,
            map: make(&Relevance::default()).is_map(),
            make: Arc::new(make),
        }
    }
    /// The built-in map policy (`map`, [`MapPolicy`]).
    #[must_use]
    pub fn map() -> Self {
        MAP_ENTRY.clone()
    }
    /// The built-in scan-to-scan policy (`scan`, [`ScanPolicy`]).
    #[must_use]
    pub fn scan() -> Self {
        SCAN_ENTRY.clone()
    }
    /// A new policy with these relevance thresholds and bounds.
    #[must_use]
    pub fn policy(&self, relevance: &Relevance) -> Box<dyn ReferencePolicy> {
        (self.make)(relevance)
    }
}

impl Debug for ReferenceEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

/// Entries are equal when their names are: a registry holds one policy per name.
impl PartialEq for ReferenceEntry {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}

static MAP_ENTRY: LazyLock<ReferenceEntry> = LazyLock::new(|| ReferenceEntry {
    name: MAP,
    summary: "against a map of every relevant scan (paper Alg. 1)",
    map: true,
    make: Arc::new(|relevance| Box::new(MapPolicy::new(*relevance))),
});

static SCAN_ENTRY: LazyLock<ReferenceEntry> = LazyLock::new(|| ReferenceEntry {
    name: SCAN,
    summary: "against the latest relevant scan (scan to scan)",
    map: false,
    make: Arc::new(|relevance| Box::new(ScanPolicy::new(*relevance))),
});

/// The name of the built-in map policy ([`MapPolicy`]): the boosted matchers, `<prefix>-A`.
pub const MAP: &str = "map";
/// The name of the built-in scan-to-scan policy ([`ScanPolicy`]): the plain matchers, `A`.
pub const SCAN: &str = "scan";

/// Whether `name` is one of the built-in policies, whose composed names are the presets.
pub(crate) fn is_builtin(name: &str) -> bool {
    name == MAP || name == SCAN
}
