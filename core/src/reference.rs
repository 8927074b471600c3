//! What a scan is matched against: a spatial index of reference points plus what matchers need
//! to know about each point (its surface normal, the sampling spacing around it and its
//! measurement covariance).
//!
//! Incremental matching keeps one scan here; boosted matching keeps every relevant scan (paper
//! Alg. 1). Either way the matcher sees the same type.

use crate::index::{IndexError, Neighbour, PointId, SpatialIndex};
use crate::{BeamStatus, Pose2, Scan};
use nalgebra::{Matrix2, Point2, Vector2};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Range and bearing noise of a laser (Pfister et al. 2002, Sec. III).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LaserNoise {
    /// Standard deviation of a range reading, along the beam (m). Default 0.01.
    pub sigma_range: f64,
    /// Standard deviation of a beam's bearing, across the beam (rad). Default 0.001.
    pub sigma_bearing: f64,
}

impl Default for LaserNoise {
    fn default() -> Self {
        Self {
            sigma_range: 0.01,
            sigma_bearing: 0.001,
        }
    }
}

impl LaserNoise {
    /// Covariance of a point at `range` along bearing `angle`, in the laser frame:
    /// σr² along the beam, (r·σφ)² across it.
    #[must_use]
    pub fn point_covariance(&self, range: f64, angle: f64) -> Matrix2<f64> {
        let (s, c) = angle.sin_cos();
        let along = self.sigma_range * self.sigma_range;
        let across = (range * self.sigma_bearing).powi(2);
        let u = Vector2::new(c, s);
        let v = Vector2::new(-s, c);
        u * u.transpose() * along + v * v.transpose() * across
    }
}

/// What a matcher knows about one reference point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointInfo {
    /// Unit surface normal in the reference frame, facing the sensor that saw it; zero when the
    /// point had no close neighbour to estimate it from.
    pub normal: Vector2<f64>,
    /// Distance between neighbouring samples of the surface around the point (m). It shrinks as
    /// more scans of the same surface enter a map: the density gain of the paper's Fig. 2.
    pub spacing: f64,
    /// Measurement covariance in the reference frame (m²).
    pub covariance: Matrix2<f64>,
    /// How well the point's neighbours fit a straight line, from 0 (no neighbours, too few to
    /// tell, or a curved surface such as a distant tree trunk) to 1 (a line within twice the
    /// range noise). A point on a straight surface may correspond to any point along it; a
    /// point on a trunk or a corner may not.
    pub linearity: f64,
    /// Standard deviation of the normal's direction (rad): the fitted line's, σ / √λ, σ the
    /// points' spread across it (never below the range noise) and λ their scatter along it.
    /// A window of samples a few millimetres apart turns its normal at random by tens of
    /// degrees; one spanning metres holds it to a fraction of one. π/2 (no direction known)
    /// for a point without a normal.
    pub normal_sigma: f64,
}

/// Two neighbouring beams' points lie on one surface when they are closer than this…
pub const NEIGHBOUR_GAP: f64 = 0.3;
/// … or than this fraction of the range (a wall seen at a grazing angle is sampled sparsely).
pub const NEIGHBOUR_GAP_PER_METRE: f64 = 0.15;

/// Beams on either side of a point used to fit its surface.
const HALF_WINDOW: usize = 2;

/// `connected[k]` (into `out`): point k and point k + 1 of `scan` lie on one surface, by
/// [`NEIGHBOUR_GAP`] and [`NEIGHBOUR_GAP_PER_METRE`].
pub fn surface_connections(scan: &Scan, out: &mut Vec<bool>) {
    let pts = scan.points();
    let beams = scan.beam_of_point();
    out.clear();
    out.extend((0..pts.len().saturating_sub(1)).map(|k| {
        let beams_apart = beams[k].abs_diff(beams[k + 1]);
        let limit = NEIGHBOUR_GAP.max(NEIGHBOUR_GAP_PER_METRE * scan.point_range(k));
        beams_apart <= 2 && (pts[k] - pts[k + 1]).norm() <= limit * beams_apart as f64
    }));
}

/// The surface fitted through point `k` of `pts`: the window of its connected neighbours
/// within ±2 beams, and the principal-axis line through them.
struct SurfaceFit<'a> {
    window: &'a [Point2<f64>],
    /// Unit normal facing the sensor (at the laser origin).
    normal: Vector2<f64>,
    /// Scatter about the window's mean.
    scatter: (f64, f64, f64),
}

/// The fit at point `k` (`connected` from [`surface_connections`]); `None` for a point with no
/// connected neighbour.
fn surface_fit<'a>(pts: &'a [Point2<f64>], connected: &[bool], k: usize) -> Option<SurfaceFit<'a>> {
    let mut lo = k;
    while lo > 0 && k - lo < HALF_WINDOW && connected[lo - 1] {
        lo -= 1;
    }
    let mut hi = k;
    while hi + 1 < pts.len() && hi - k < HALF_WINDOW && connected[hi] {
        hi += 1;
    }
    if hi == lo {
        return None;
    }
    let window = &pts[lo..=hi];
    let n = window.len() as f64;
    let mean = window.iter().fold(Vector2::zeros(), |m, p| m + p.coords) / n;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in window {
        let d = p.coords - mean;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    // Direction of the principal axis of the 2×2 scatter matrix.
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let mut normal = Vector2::new(-angle.sin(), angle.cos());
    // Face the sensor (at the laser origin).
    if normal.dot(&pts[k].coords) > 0.0 {
        normal = -normal;
    }
    Some(SurfaceFit {
        window,
        normal,
        scatter: (sxx, sxy, syy),
    })
}

/// The unit surface normal of point `k` of `pts` ([`PointInfo::normal`]: facing the sensor,
/// zero for a point with no connected neighbour); `connected` from [`surface_connections`].
/// For a matcher that needs the scan's normals and not the rest of [`scan_point_info`].
#[must_use]
pub fn surface_normal(pts: &[Point2<f64>], connected: &[bool], k: usize) -> Vector2<f64> {
    surface_fit(pts, connected, k).map_or_else(Vector2::zeros, |f| f.normal)
}

/// Per-point normals and spacings of one scan, in the laser frame: a line fitted (principal
/// axis) through the point and its connected neighbours within ±2 beams.
#[must_use]
pub fn scan_point_info(scan: &Scan, noise: &LaserNoise) -> Vec<PointInfo> {
    let pts = scan.points();
    let step = scan.geometry.angle_increment.abs().max(1e-6);
    let mut connected = Vec::new();
    surface_connections(scan, &mut connected);
    (0..pts.len())
        .map(|k| {
            let range = scan.point_range(k);
            let covariance = noise.point_covariance(range, scan.point_angle(k));
            let Some(fit) = surface_fit(pts, &connected, k) else {
                return PointInfo {
                    normal: Vector2::zeros(),
                    spacing: (range * step).max(1e-4),
                    covariance,
                    linearity: 0.0,
                    normal_sigma: std::f64::consts::FRAC_PI_2,
                };
            };
            let window = fit.window;
            let n = window.len() as f64;
            let (sxx, sxy, syy) = fit.scatter;
            let spacing = (window[window.len() - 1] - window[0]).norm() / (n - 1.0);
            let (linearity, normal_sigma) =
                line_quality(sxx, sxy, syy, window.len(), noise.sigma_range);
            PointInfo {
                normal: fit.normal,
                spacing: spacing.max(1e-4),
                covariance,
                linearity,
                normal_sigma,
            }
        })
        .collect()
}

/// How well `n` points with scatter matrix `[[sxx, sxy], [sxy, syy]]` (about their mean) fit
/// a line, from one eigen-decomposition and one spread across it, σ̂ = sqrt(λmin / (n − 2)):
/// - linearity ([`PointInfo::linearity`]): 1 when σ̂ is within twice the range noise σ (real
///   walls are a little rough), falling to 0 at 4σ; two points always fit a line and prove
///   nothing: 0;
/// - the normal's deviation ([`PointInfo::normal_sigma`]): σ̂, never below σ (σ alone for two
///   points), over the root of the scatter along the line, λmax (a regression slope's
///   deviation), at most π/2.
fn line_quality(sxx: f64, sxy: f64, syy: f64, n: usize, sigma: f64) -> (f64, f64) {
    let (lambda_min, lambda_max) = principal_scatter(sxx, sxy, syy);
    let spread = (n > 2).then(|| (lambda_min / (n - 2) as f64).sqrt());
    let linearity = match spread {
        Some(spread) if sigma > 0.0 => (2.0 - 0.5 * spread / sigma).clamp(0.0, 1.0),
        _ => 0.0,
    };
    let deviation = spread.map_or(sigma, |spread| spread.max(sigma)) / lambda_max.sqrt();
    let normal_sigma = if deviation.is_finite() {
        deviation.min(std::f64::consts::FRAC_PI_2)
    } else {
        std::f64::consts::FRAC_PI_2
    };
    (linearity, normal_sigma)
}

/// The scatter matrix's eigenvalues (across the principal axis, along it), never negative.
fn principal_scatter(sxx: f64, sxy: f64, syy: f64) -> (f64, f64) {
    let half_trace = 0.5 * (sxx + syy);
    let root = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
    ((half_trace - root).max(0.0), (half_trace + root).max(0.0))
}

/// How a scan is merged into a map (see [`Reference::insert_scan`]): the two density bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Merge {
    /// A new point closer than this to one held is not inserted (m); 0 keeps every point.
    pub resolution: f64,
    /// The cell cap, if any: the map is divided into square cells of this side (m)…
    pub cell_size: f64,
    /// … and a cell holds at most this many points (0: no cap), so the map grows with the
    /// area explored, not with time. What a full cell does with a new point is
    /// [`Merge::full_cell`].
    pub max_cell_points: u32,
    /// What a full cell does with a new point that the spacing and the surface band admit.
    pub full_cell: FullCell,
    /// A new point within this distance (m) of the surface through its nearest map point, when
    /// that point was held before the scan (the map's polyline through its samples,
    /// [`Reference::surface_foot`]), is not inserted:
    /// the map holds that surface already. A wall seen again stays one sample thick instead
    /// of thickening, visit after visit, into a band as wide as the laser's noise; a point
    /// off the surface (another wall, a corner, a gap wider than the samples' spacing) still
    /// enters. 0 (or a value that is not finite and positive) inserts such points.
    pub surface_band: f64,
    /// Free-space carving: a map point that a merged scan sees through (both beams around its
    /// bearing return from beyond it by more than this, m) counts one miss; a point whose
    /// bearing beams return within this of its range counts one look (its insertion is the
    /// first). A point missed at least twice and more often than looked at leaves the map's
    /// searches at once, as an occupancy grid frees a cell its beams cross: a wall copied in
    /// by a bad match, a person who walked by. Only points within 10 m of the laser are
    /// looked at, and only between two valid beams. 0 (or a value that is not finite and
    /// positive) carves nothing.
    pub free_space_margin: f64,
}

/// What a full cell of the cell cap ([`Merge::max_cell_points`]) does with a new point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FullCell {
    /// The new point replaces the cell's point confirmed least recently: the one whose
    /// surface no scan has landed on (within the spacing or the surface band) for longest,
    /// such as a copy of a wall from a match that was off, or a chair since moved. Points
    /// every revisit confirms stay; a point inserted or confirmed by the same scan is never
    /// replaced (the new point is then skipped). The map keeps the places it sees, as they
    /// look now. Replaced points leave the index lazily, in one rebuild once they make up an
    /// eighth of it ([`Reference::stale_len`]), as ikd-Tree (FAST-LIO2) removes points.
    #[default]
    EvictStalest,
    /// The new point is skipped: a full cell keeps its first points, right or wrong.
    Skip,
}

impl Merge {
    /// Only the minimum spacing: no cell cap, no surface band.
    #[must_use]
    pub fn spacing(resolution: f64) -> Self {
        Self {
            resolution,
            cell_size: 0.0,
            max_cell_points: 0,
            full_cell: FullCell::EvictStalest,
            surface_band: 0.0,
            free_space_margin: 0.0,
        }
    }

    /// The cell holding `p` when the cell cap is on. Points are finite and within
    /// ±2³¹ m ([`crate::index::check_point`]) and configs hold cells to at least a
    /// millimetre, so the cell coordinates fit an `i64`; a narrower cell given through this
    /// API saturates the cast (cells far out alias) rather than panicking.
    fn cell(&self, p: &Point2<f64>) -> Option<(i64, i64)> {
        (self.max_cell_points > 0 && self.cell_size > 0.0).then(|| cell_of(p, self.cell_size))
    }
}

/// The square cell of side `side` holding `p` ([`Merge::cell`]).
fn cell_of(p: &Point2<f64>, side: f64) -> (i64, i64) {
    ((p.x / side).floor() as i64, (p.y / side).floor() as i64)
}

/// A spatial index of reference points with a [`PointInfo`] per point.
#[derive(Debug, Clone, Default)]
pub struct Reference<I> {
    index: I,
    info: Vec<PointInfo>,
    scans: usize,
    /// True once a scan was merged into it ([`Reference::is_map`]).
    merged: bool,
    /// Per point: the number of the scan that inserted it or last landed on its surface
    /// ([`FullCell::EvictStalest`]).
    confirmed: Vec<u32>,
    /// Per point: the number of the scan that inserted it ([`Reference::deform`]).
    born: Vec<u32>,
    /// The side of the cell cap's cells (m), once a merge used them…
    cell_size: f64,
    /// … and the cap.
    cell_cap: u32,
    /// Per point: false once a full cell replaced it; it leaves the index at the next rebuild.
    live: Vec<bool>,
    /// Points replaced and still in the index.
    stale: usize,
    /// Per point: the scans that looked at it and the scans that saw through it
    /// ([`Merge::free_space_margin`]).
    looks: Vec<(u16, u16)>,
    /// Scratch of the carving's radius search.
    around: Vec<Neighbour>,
    /// Times the points were given new ids ([`Reference::renumberings`]).
    renumberings: u64,
    /// The noise of the laser whose scans enter, and of the scans matched against them.
    noise: LaserNoise,
}

impl<I: SpatialIndex> Reference<I> {
    /// An empty reference over the given (empty) index, for a laser of the default noise
    /// ([`LaserNoise::default`]).
    #[must_use]
    pub fn new(index: I) -> Self {
        Self::with_noise(index, LaserNoise::default())
    }

    /// An empty reference over the given (empty) index, for a laser of `noise`: the one
    /// place a pipeline's laser noise is held. Points entering take their covariances from
    /// it, and matchers that weigh a scan by its noise read it here ([`Reference::noise`]).
    #[must_use]
    pub fn with_noise(index: I, noise: LaserNoise) -> Self {
        Self {
            index,
            info: Vec::new(),
            scans: 0,
            merged: false,
            confirmed: Vec::new(),
            born: Vec::new(),
            cell_size: 0.0,
            cell_cap: 0,
            live: Vec::new(),
            stale: 0,
            looks: Vec::new(),
            around: Vec::new(),
            renumberings: 0,
            noise,
        }
    }

    /// The laser's noise.
    #[must_use]
    pub fn noise(&self) -> &LaserNoise {
        &self.noise
    }

    /// The spatial index of the reference points.
    #[must_use]
    pub fn index(&self) -> &I {
        &self.index
    }

    /// Per-point information, by point id.
    #[must_use]
    pub fn info(&self) -> &[PointInfo] {
        &self.info
    }

    /// Number of points in the index, those a full cell replaced or carving removed and the
    /// next rebuild drops included ([`Reference::stale_len`]).
    #[must_use]
    pub fn len(&self) -> usize {
        self.info.len()
    }

    /// Points a full cell replaced ([`FullCell::EvictStalest`]) or carving removed
    /// ([`Merge::free_space_margin`]) that are still in the index: fewer than an eighth of
    /// [`Reference::len`] after every insertion. Matchers may pair with replaced ones until
    /// the rebuild (carved ones leave the searches at once); the map's own merge rules
    /// ignore both.
    #[must_use]
    pub fn stale_len(&self) -> usize {
        self.stale
    }

    /// Whether point `id` is live (neither replaced by a full cell nor carved).
    #[must_use]
    pub fn is_live(&self, id: PointId) -> bool {
        self.live.get(id as usize).copied().unwrap_or(false)
    }

    /// The live points (those neither replaced nor carved), in id order: the map as it stands.
    #[must_use]
    pub fn live_points(&self) -> Vec<Point2<f64>> {
        let points = self.index.points();
        if self.stale == 0 {
            return points.to_vec();
        }
        points
            .iter()
            .zip(&self.live)
            .filter(|(_, live)| **live)
            .map(|(p, _)| *p)
            .collect()
    }

    /// True when there is nothing to match against.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.info.is_empty()
    }

    /// Per point, by id: the number of the scan that inserted it (as [`Reference::scans`]
    /// counted before that insertion).
    #[must_use]
    pub fn born(&self) -> &[u32] {
        &self.born
    }

    /// Number of scans inserted since the last clear.
    #[must_use]
    pub fn scans(&self) -> usize {
        self.scans
    }

    /// How many times its points were given new ids: by a [`clear`](Self::clear), or by a
    /// rebuild that dropped points a full cell replaced or carving removed (the live points
    /// keep their order). An id, or a length taken as a boundary between ids, held from
    /// before one means nothing after it.
    #[must_use]
    pub fn renumberings(&self) -> u64 {
        self.renumberings
    }

    /// True when scans are merged into this reference (a map: [`Reference::insert_scan`]
    /// with `Some(merge)` since the last clear), false for a scan as reference. A map's older
    /// passes are off from the current estimate by the drift since they were seen, which one
    /// step's odometry does not bound; a matcher may gate them differently.
    #[must_use]
    pub fn is_map(&self) -> bool {
        self.merged
    }

    /// The point of the reference surface through point `id` closest to `p`: the sample slid
    /// along its tangent, at most one sample spacing either way (a polyline through the
    /// samples). The sample itself where its normal is unknown.
    #[must_use]
    pub fn surface_foot(&self, id: crate::PointId, p: &Point2<f64>) -> Point2<f64> {
        let c = self.index.points()[id as usize];
        let info = &self.info[id as usize];
        let tangent = Vector2::new(-info.normal.y, info.normal.x);
        let slide = (p - c).dot(&tangent).clamp(-info.spacing, info.spacing);
        c + tangent * slide
    }

    /// Squared distance from `p` to the reference surface through its nearest point, if that
    /// point lies within squared distance `reach_sq`.
    #[must_use]
    pub fn surface_distance_sq(&self, p: &Point2<f64>, reach_sq: f64) -> Option<f64> {
        self.index
            .nearest_within(p, reach_sq)
            .map(|n| (self.surface_foot(n.id, p) - p).norm_squared())
    }

    /// Removes every point (the laser's noise stays).
    pub fn clear(&mut self) {
        self.index.clear();
        self.info.clear();
        self.scans = 0;
        self.merged = false;
        self.confirmed.clear();
        self.born.clear();
        self.live.clear();
        self.stale = 0;
        self.looks.clear();
        self.renumberings += 1;
    }

    /// Inserts the points of `scan`, seen from `pose` (the laser's pose in the reference
    /// frame), with covariances from the reference's [`LaserNoise`].
    ///
    /// `merge` is `None` for a plain insertion (a scan as reference). With `Some(merge)`
    /// the scan is merged into a map: each new point's spacing is lowered to its distance from
    /// the nearest point already held (and that point's likewise), so a surface seen many times
    /// reports the finer sampling it now has; a new point closer than `merge.resolution` to one
    /// held is not inserted (0 keeps every point), nor one on a surface the map holds
    /// ([`Merge::surface_band`]), nor one whose cell is full ([`Merge::max_cell_points`]).
    /// Before its points enter, the scan carves the map points it sees through
    /// ([`Merge::free_space_margin`]). Returns the number of points inserted; on error nothing
    /// is inserted.
    pub fn insert_scan(
        &mut self,
        scan: &Scan,
        pose: &Pose2,
        merge: Option<Merge>,
    ) -> Result<usize, IndexError> {
        let local = scan_point_info(scan, &self.noise);
        let rot = pose.rotation();
        let global: Vec<Point2<f64>> = scan
            .points()
            .iter()
            .map(|p| pose.transform_point(p))
            .collect();
        for (k, p) in global.iter().enumerate() {
            crate::index::check_point(p, self.index.len() + k)?;
        }
        if let Some(merge) = merge
            && merge.free_space_margin > 0.0
            && merge.free_space_margin.is_finite()
            && self.carve(scan, pose, merge)
        {
            // The index cannot take the carved points out of its searches itself.
            self.rebuild()?;
        }
        if let Some(m) = merge
            && m.max_cell_points > 0
        {
            self.cell_size = m.cell_size;
            self.cell_cap = m.max_cell_points;
        }
        let held = self.index.len();
        // This scan's number, for the points it inserts or confirms.
        let stamp = u32::try_from(self.scans).unwrap_or(u32::MAX);
        let mut inserted = 0;
        for (p, seen) in global.iter().zip(local) {
            let normal: Vector2<f64> = rot * seen.normal;
            let mut info = PointInfo {
                normal,
                spacing: seen.spacing,
                covariance: rot * seen.covariance * rot.transpose(),
                linearity: seen.linearity,
                normal_sigma: seen.normal_sigma,
            };
            if let Some(merge) = merge {
                let resolution = merge.resolution;
                let reach = info.spacing.max(resolution);
                let band = merge.surface_band;
                let banded = band > 0.0 && band.is_finite();
                // One search serves both rules: the nearest point within the spacing's reach
                // is the nearest within the band's wider one. A replaced point no longer
                // counts: the new one may take its place.
                let search = if banded { reach + band } else { reach };
                let nearest = self.nearest_live(p, search);
                // The nearest held point learns how finely its surface has been seen, whether
                // or not this point is kept (the spacing's and the band's skips alike).
                if let Some(n) = nearest.filter(|n| n.dist_sq <= reach * reach) {
                    let d = n.dist_sq.sqrt().max(1e-4);
                    info.spacing = info.spacing.min(d);
                    let other = &mut self.info[n.id as usize];
                    other.spacing = other.spacing.min(d.max(resolution));
                    if d < resolution {
                        self.confirmed[n.id as usize] = stamp;
                        continue;
                    }
                }
                // Against the surfaces held before this scan: its own samples are its
                // surface, not a second look at one.
                if banded
                    && let Some(n) = nearest
                    && (n.id as usize) < held
                    && (self.surface_foot(n.id, p) - p).norm() <= band
                {
                    self.confirmed[n.id as usize] = stamp;
                    continue;
                }
                if let Some(c) = merge.cell(p)
                    && !self.make_room(c, merge, stamp)
                {
                    continue;
                }
            }
            self.index.insert(*p)?;
            self.info.push(info);
            self.confirmed.push(stamp);
            self.born.push(stamp);
            self.live.push(true);
            self.looks.push((1, 0));
            inserted += 1;
        }
        if self.stale > 0 && self.stale * STALE_SHARE >= self.info.len() {
            self.rebuild()?;
        }
        self.scans += 1;
        self.merged |= merge.is_some();
        Ok(inserted)
    }

    /// The live point nearest to `p` within `reach` (m): the nearest point, or, when a full
    /// cell replaced it, the nearest of the rest.
    fn nearest_live(&self, p: &Point2<f64>, reach: f64) -> Option<Neighbour> {
        let nearest = self.index.nearest_within(p, reach * reach)?;
        if self.live[nearest.id as usize] {
            return Some(nearest);
        }
        let mut around = Vec::new();
        self.index.within_radius(p, reach, &mut around);
        around
            .into_iter()
            .filter(|n| self.live[n.id as usize])
            .min_by(|a, b| a.dist_sq.total_cmp(&b.dist_sq).then(a.id.cmp(&b.id)))
    }

    /// Free-space carving ([`Merge::free_space_margin`]) with `scan` seen from `pose`: counts
    /// the looks and misses of the live map points within the scan's reach, and takes those
    /// missed too often out of the index's searches; they leave the index itself at the next
    /// rebuild, as replaced points do. True when the index cannot remove points and must be
    /// rebuilt now.
    fn carve(&mut self, scan: &Scan, pose: &Pose2, merge: Merge) -> bool {
        let margin = merge.free_space_margin;
        let ranges = scan.ranges();
        let status = scan.status();
        let g = scan.geometry;
        let reach = scan
            .points()
            .iter()
            .map(|p| p.coords.norm())
            .fold(0.0, f64::max)
            .min(CARVE_REACH);
        if ranges.len() < 2 || reach <= margin || g.angle_increment <= 0.0 {
            return false;
        }
        let o = Point2::new(pose.x, pose.y);
        let (s, c) = pose.theta.sin_cos();
        let mut around = std::mem::take(&mut self.around);
        self.index.within_radius(&o, reach, &mut around);
        let last = (ranges.len() - 1) as f64;
        let mut rebuild = false;
        for n in &around {
            let id = n.id as usize;
            if !self.live[id] {
                continue;
            }
            let d = n.point - o;
            let (x, y) = (c * d.x + s * d.y, -s * d.x + c * d.y);
            let f = (y.atan2(x) - g.angle_min) / g.angle_increment;
            if !(0.0..last).contains(&f) {
                continue;
            }
            let k = f as usize;
            if status[k] != BeamStatus::Valid || status[k + 1] != BeamStatus::Valid {
                continue;
            }
            let rho = n.dist_sq.sqrt();
            let (a, b) = (ranges[k], ranges[k + 1]);
            let looks = &mut self.looks[id];
            if rho + margin < a.min(b) {
                looks.1 = looks.1.saturating_add(1);
                if looks.1 >= CARVE_MISSES && looks.1 > looks.0 {
                    self.live[id] = false;
                    self.stale += 1;
                    rebuild |= self.index.remove(n.id).is_none();
                }
            } else if (rho - a).abs() <= margin || (rho - b).abs() <= margin {
                looks.0 = looks.0.saturating_add(1);
            }
        }
        self.around = around;
        rebuild
    }

    /// Whether cell `c` can take one more point under `merge`'s cap, replacing its stalest
    /// point if [`FullCell::EvictStalest`] says so: the one scans have confirmed least
    /// recently, and of those the oldest (the lowest id).
    fn make_room(&mut self, c: (i64, i64), merge: Merge, stamp: u32) -> bool {
        let side = merge.cell_size;
        let mut around = std::mem::take(&mut self.around);
        self.cell_search(c, side, &mut around);
        // One pass counts the cell and finds its stalest point; a cell with room, the common
        // case, gathers nothing.
        let stalest_key = |id: PointId| (self.confirmed[id as usize], id);
        let (count, stalest) =
            self.in_cell(&around, c, side)
                .fold((0usize, None::<PointId>), |(n, best), id| {
                    let best = best.filter(|&b| stalest_key(b) <= stalest_key(id));
                    (n + 1, best.or(Some(id)))
                });
        self.around = around;
        if count < merge.max_cell_points as usize {
            return true;
        }
        if merge.full_cell == FullCell::Skip {
            return false;
        }
        let Some(stalest) = stalest else {
            return true;
        };
        if self.confirmed[stalest as usize] >= stamp {
            return false;
        }
        self.live[stalest as usize] = false;
        self.stale += 1;
        true
    }

    /// The index's points within the circumcircle of cell `c` (side `side`), into `around`:
    /// every point of the cell among them, and some of its neighbours'. The cap keeps no
    /// table of its own, so it costs no memory per point; it asks the index once per point
    /// about to enter a map.
    fn cell_search(&self, c: (i64, i64), side: f64, around: &mut Vec<Neighbour>) {
        let centre = Point2::new((c.0 as f64 + 0.5) * side, (c.1 as f64 + 0.5) * side);
        // The half diagonal, widened so that rounding never drops a corner point; the cell
        // test decides.
        let reach = side * (0.5 * std::f64::consts::SQRT_2 + 1e-9);
        self.index.within_radius(&centre, reach, around);
    }

    /// The live points of cell `c` (side `side`) among `around`, the result of
    /// [`Reference::cell_search`], by id.
    fn in_cell<'a>(
        &'a self,
        around: &'a [Neighbour],
        c: (i64, i64),
        side: f64,
    ) -> impl Iterator<Item = PointId> + 'a {
        let points = self.index.points();
        around
            .iter()
            .map(|n| n.id)
            .filter(move |&id| self.live[id as usize] && cell_of(&points[id as usize], side) == c)
    }

    /// The live points of cell `c` (side `side`), by id.
    fn cell_members(&mut self, c: (i64, i64), side: f64) -> Vec<PointId> {
        let mut around = std::mem::take(&mut self.around);
        self.cell_search(c, side, &mut around);
        let members = self.in_cell(&around, c, side).collect();
        self.around = around;
        members
    }

    /// Moves every point by the pose `moved` gives for the number of the scan that inserted
    /// it (as [`Reference::scans`] counted before that insertion; `None` leaves the scan's
    /// points where they are), turning its normal and covariance with it: a stretch of map
    /// laid by drifted scans is laid again where they belong ([`crate::SpatialIndex`] rebuilt,
    /// cells of the cell cap re-bucketed: where moved points crowd a cell past its cap, the
    /// ones confirmed least recently are replaced, as a full cell replaces them). Points
    /// replaced by a full cell or carved are dropped on the way ([`Reference::renumberings`]
    /// counts that); otherwise every point keeps its id. On error (a point moved out of the
    /// index's range) the map is left empty.
    pub fn deform(&mut self, moved: impl Fn(u32) -> Option<Pose2>) -> Result<(), IndexError> {
        let mut points = self.index.points().to_vec();
        for ((p, info), born) in points.iter_mut().zip(&mut self.info).zip(&self.born) {
            let Some(by) = moved(*born) else { continue };
            let rot = by.rotation();
            *p = by.transform_point(p);
            info.normal = rot * info.normal;
            info.covariance = rot * info.covariance * rot.transpose();
        }
        self.index.clear();
        for p in &points {
            if let Err(e) = self.index.insert(*p) {
                self.clear();
                return Err(e);
            }
        }
        if self.stale > 0
            && let Err(e) = self.rebuild()
        {
            self.clear();
            return Err(e);
        }
        if self.cell_cap > 0 && self.cell_size > 0.0 {
            // After the rebuild every point is live. Counts first, so that only the cells
            // over their cap are gathered.
            let size = self.cell_size;
            let mut counts: HashMap<(i64, i64), usize> = HashMap::new();
            for p in self.index.points() {
                *counts.entry(cell_of(p, size)).or_default() += 1;
            }
            let cap = self.cell_cap as usize;
            for (c, _) in counts.into_iter().filter(|&(_, n)| n > cap) {
                let mut ids = self.cell_members(c, size);
                // The most recently confirmed stay; of equally stale ones, the oldest.
                ids.sort_by_key(|&id| (std::cmp::Reverse(self.confirmed[id as usize]), id));
                for id in ids.drain(cap..) {
                    self.live[id as usize] = false;
                    self.stale += 1;
                }
            }
            if self.stale > 0
                && self.stale * STALE_SHARE >= self.info.len()
                && let Err(e) = self.rebuild()
            {
                self.clear();
                return Err(e);
            }
        }
        Ok(())
    }

    /// Drops the replaced points from the index: the live ones are inserted afresh, in their
    /// order (ids change; nothing outside holds them between scans).
    fn rebuild(&mut self) -> Result<(), IndexError> {
        let points = self.index.points().to_vec();
        self.index.clear();
        self.renumberings += 1;
        let mut id_of = vec![PointId::MAX; points.len()];
        let mut k = 0;
        for (old, p) in points.iter().enumerate() {
            if !self.live[old] {
                continue;
            }
            id_of[old] = self.index.insert(*p)?;
            self.info[k] = self.info[old];
            self.confirmed[k] = self.confirmed[old];
            self.born[k] = self.born[old];
            self.looks[k] = self.looks[old];
            k += 1;
        }
        self.info.truncate(k);
        self.confirmed.truncate(k);
        self.born.truncate(k);
        self.looks.truncate(k);
        self.live.clear();
        self.live.resize(k, true);
        self.stale = 0;
        Ok(())
    }
}

/// Free-space carving looks at map points within this distance of the laser (m) at most: far
/// beams are the ones whose bearing errors sweep farthest across the map.
const CARVE_REACH: f64 = 10.0;
/// A point leaves the map only once this many scans saw through it (and more than landed on
/// it): one scan's odd beam (glass, a grazing edge) never carves.
const CARVE_MISSES: u16 = 2;

/// Replaced points are dropped from the index once they make up this share's inverse of it
/// (an eighth): one rebuild of the map's live points per `len / 8` replacements.
const STALE_SHARE: usize = 8;
