//! What a scan is matched against: a spatial index of reference points plus what matchers need
//! to know about each point (its surface normal, the sampling spacing around it and its
//! measurement covariance).
//!
//! Incremental matching keeps one scan here; boosted matching keeps every relevant scan (paper
//! Alg. 1). Either way the matcher sees the same type.

use crate::index::{IndexError, SpatialIndex};
use crate::{Pose2, Scan};
use nalgebra::{Matrix2, Point2, Vector2};
use serde::{Deserialize, Serialize};

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
}

/// Neighbouring beams farther apart than this many times the expected spacing, or than
/// [`MAX_NEIGHBOUR_GAP`], lie on different surfaces.
const GAP_FACTOR: f64 = 3.0;
/// Absolute limit on the distance of two points used to estimate a normal (m).
pub const MAX_NEIGHBOUR_GAP: f64 = 0.5;

/// Per-point normals and spacings of one scan, in the laser frame, from its neighbouring beams.
#[must_use]
pub fn scan_point_info(scan: &Scan, noise: &LaserNoise) -> Vec<PointInfo> {
    let pts = scan.points();
    let beams = scan.beam_of_point();
    let step = scan.geometry.angle_increment.abs().max(1e-6);
    let neighbour = |k: usize, j: usize| -> Option<Point2<f64>> {
        let gap = (pts[k] - pts[j]).norm();
        let expected = scan.point_range(k) * step * beams[k].abs_diff(beams[j]) as f64;
        (beams[k].abs_diff(beams[j]) <= 2
            && gap <= MAX_NEIGHBOUR_GAP.max(GAP_FACTOR * expected)
            && gap < MAX_NEIGHBOUR_GAP * 4.0)
            .then_some(pts[j])
    };
    (0..pts.len())
        .map(|k| {
            let prev = (k > 0).then(|| neighbour(k, k - 1)).flatten();
            let next = (k + 1 < pts.len()).then(|| neighbour(k, k + 1)).flatten();
            let (a, b) = match (prev, next) {
                (Some(a), Some(b)) => (a, b),
                (Some(a), None) => (a, pts[k]),
                (None, Some(b)) => (pts[k], b),
                (None, None) => (pts[k], pts[k]),
            };
            let tangent = b - a;
            let len = tangent.norm();
            let range = scan.point_range(k);
            let mut normal = Vector2::zeros();
            if len > 1e-9 {
                normal = Vector2::new(-tangent.y, tangent.x) / len;
                // Face the sensor (at the laser origin).
                if normal.dot(&pts[k].coords) > 0.0 {
                    normal = -normal;
                }
            }
            let spacing = match (prev, next) {
                (Some(_), Some(_)) => len / 2.0,
                (None, None) => range * step,
                _ => len,
            };
            PointInfo {
                normal,
                spacing: spacing.max(1e-4),
                covariance: noise.point_covariance(range, scan.point_angle(k)),
            }
        })
        .collect()
}

/// A spatial index of reference points with a [`PointInfo`] per point.
#[derive(Debug, Clone, Default)]
pub struct Reference<I> {
    index: I,
    info: Vec<PointInfo>,
    scans: usize,
}

impl<I: SpatialIndex> Reference<I> {
    /// An empty reference over the given (empty) index.
    #[must_use]
    pub fn new(index: I) -> Self {
        Self {
            index,
            info: Vec::new(),
            scans: 0,
        }
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

    /// Number of points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.info.len()
    }

    /// True when there is nothing to match against.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.info.is_empty()
    }

    /// Number of scans inserted since the last clear.
    #[must_use]
    pub fn scans(&self) -> usize {
        self.scans
    }

    /// Removes everything.
    pub fn clear(&mut self) {
        self.index.clear();
        self.info.clear();
        self.scans = 0;
    }

    /// Inserts the points of `scan`, seen from `pose` (the laser's pose in the reference frame).
    ///
    /// When `densify` is set, each new point's spacing is lowered to its distance from the
    /// nearest point already held (and that point's likewise), so a surface seen many times
    /// reports the finer sampling it now has. Returns the number of points inserted; on error
    /// nothing is inserted.
    pub fn insert_scan(
        &mut self,
        scan: &Scan,
        pose: &Pose2,
        noise: &LaserNoise,
        densify: bool,
    ) -> Result<usize, IndexError> {
        let local = scan_point_info(scan, noise);
        let rot = pose.rotation();
        let global: Vec<Point2<f64>> = scan
            .points()
            .iter()
            .map(|p| pose.transform_point(p))
            .collect();
        for (k, p) in global.iter().enumerate() {
            crate::index::check_point(p, self.index.len() + k)?;
        }
        for (p, seen) in global.iter().zip(local) {
            let normal: Vector2<f64> = rot * seen.normal;
            let mut info = PointInfo {
                normal,
                spacing: seen.spacing,
                covariance: rot * seen.covariance * rot.transpose(),
            };
            if densify {
                let limit = info.spacing * info.spacing;
                if let Some(n) = self.index.nearest_within(p, limit) {
                    let d = n.dist_sq.sqrt().max(1e-4);
                    info.spacing = info.spacing.min(d);
                    let other = &mut self.info[n.id as usize];
                    other.spacing = other.spacing.min(d);
                }
            }
            self.index.insert(*p)?;
            self.info.push(info);
        }
        self.scans += 1;
        Ok(global.len())
    }
}
