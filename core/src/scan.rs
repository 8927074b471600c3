//! Laser scans: polar ranges, their validity, their Cartesian points.

use nalgebra::Point2;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a scan could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ScanError {
    /// The scan has no beams at all.
    #[error("a scan needs at least one beam")]
    NoBeams,
    /// A geometry parameter is not usable.
    #[error("scan parameter `{name}` is {value}: {why}")]
    BadParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong with it.
        why: &'static str,
    },
}

/// Why a single beam carries no usable point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum BeamStatus {
    /// A usable return.
    Valid,
    /// At or beyond the maximum range: no return.
    MaxRange,
    /// Below the minimum range (too close to trust), or exactly 0.
    TooClose,
    /// NaN, infinite or negative.
    Invalid,
}

/// The beam layout of a laser: where each beam points and how far it reaches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BeamGeometry {
    /// Bearing of the first beam in the laser frame (rad).
    pub angle_min: f64,
    /// Bearing step between consecutive beams (rad); negative for clockwise scanners.
    pub angle_increment: f64,
    /// Readings at or above this are no-returns (m).
    pub max_range: f64,
    /// Readings below this are discarded (m), and so are readings of exactly 0 (what many
    /// lasers report for no return; a point at the laser itself has no geometry).
    pub min_range: f64,
}

impl BeamGeometry {
    /// A scanner whose `beams` beams spread evenly over `fov` radians, centred on the heading
    /// (first beam at −fov/2, last at +fov/2).
    #[must_use]
    pub fn centered(beams: usize, fov: f64, max_range: f64) -> Self {
        let increment = if beams > 1 {
            fov / (beams - 1) as f64
        } else {
            0.0
        };
        Self {
            angle_min: -fov / 2.0,
            angle_increment: increment,
            max_range,
            min_range: 0.0,
        }
    }

    /// Bearing of beam `i` (rad).
    #[must_use]
    pub fn angle(&self, i: usize) -> f64 {
        self.angle_min + self.angle_increment * i as f64
    }

    /// Refuses NaN, infinite or non-positive ranges.
    pub fn validate(&self) -> Result<(), ScanError> {
        let bad = |name, value, why| Err(ScanError::BadParameter { name, value, why });
        if !self.angle_min.is_finite() {
            return bad("angle_min", self.angle_min, "must be finite");
        }
        if !self.angle_increment.is_finite() {
            return bad("angle_increment", self.angle_increment, "must be finite");
        }
        if !(self.max_range.is_finite() && self.max_range > 0.0) {
            return bad("max_range", self.max_range, "must be finite and positive");
        }
        if !(self.min_range.is_finite() && self.min_range >= 0.0 && self.min_range < self.max_range)
        {
            return bad(
                "min_range",
                self.min_range,
                "must be finite, non-negative and below max_range",
            );
        }
        Ok(())
    }

    /// Classifies one reading.
    #[must_use]
    pub fn classify(&self, range: f64) -> BeamStatus {
        if !range.is_finite() || range < 0.0 {
            BeamStatus::Invalid
        } else if range >= self.max_range {
            BeamStatus::MaxRange
        } else if range < self.min_range || range == 0.0 {
            BeamStatus::TooClose
        } else {
            BeamStatus::Valid
        }
    }
}

/// One sweep of a 2D laser, in the laser's own frame.
///
/// The raw ranges are kept as measured; every invalid reading is marked in [`Scan::status`] and
/// only valid beams produce points. `points[k]` comes from beam `beam_of_point[k]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Time of the sweep (s).
    pub timestamp: f64,
    /// The beam layout.
    pub geometry: BeamGeometry,
    ranges: Vec<f64>,
    status: Vec<BeamStatus>,
    points: Vec<Point2<f64>>,
    beam_of_point: Vec<u32>,
}

impl Scan {
    /// Builds a scan from raw ranges. Invalid readings are kept and marked, not dropped.
    pub fn new(
        timestamp: f64,
        geometry: BeamGeometry,
        ranges: Vec<f64>,
    ) -> Result<Self, ScanError> {
        geometry.validate()?;
        if ranges.is_empty() {
            return Err(ScanError::NoBeams);
        }
        if !timestamp.is_finite() {
            return Err(ScanError::BadParameter {
                name: "timestamp",
                value: timestamp,
                why: "must be finite",
            });
        }
        let mut status = Vec::with_capacity(ranges.len());
        let mut points = Vec::with_capacity(ranges.len());
        let mut beam_of_point = Vec::with_capacity(ranges.len());
        for (i, &r) in ranges.iter().enumerate() {
            let s = geometry.classify(r);
            status.push(s);
            if s == BeamStatus::Valid {
                let (sin, cos) = geometry.angle(i).sin_cos();
                points.push(Point2::new(r * cos, r * sin));
                beam_of_point.push(i as u32);
            }
        }
        Ok(Self {
            timestamp,
            geometry,
            ranges,
            status,
            points,
            beam_of_point,
        })
    }

    /// Number of beams, valid or not.
    #[must_use]
    pub fn beams(&self) -> usize {
        self.ranges.len()
    }

    /// Raw ranges as measured (m).
    #[must_use]
    pub fn ranges(&self) -> &[f64] {
        &self.ranges
    }

    /// Per-beam validity.
    #[must_use]
    pub fn status(&self) -> &[BeamStatus] {
        &self.status
    }

    /// Cartesian points of the valid beams, in the laser frame.
    #[must_use]
    pub fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    /// The beam index each point came from.
    #[must_use]
    pub fn beam_of_point(&self) -> &[u32] {
        &self.beam_of_point
    }

    /// Number of valid beams.
    #[must_use]
    pub fn valid_count(&self) -> usize {
        self.points.len()
    }

    /// Range of the `k`-th point (not beam).
    #[must_use]
    pub fn point_range(&self, k: usize) -> f64 {
        self.ranges[self.beam_of_point[k] as usize]
    }

    /// Bearing of the `k`-th point (not beam).
    #[must_use]
    pub fn point_angle(&self, k: usize) -> f64 {
        self.geometry.angle(self.beam_of_point[k] as usize)
    }

    /// Counts of beams per status: (valid, max-range, too close, invalid).
    #[must_use]
    pub fn status_counts(&self) -> [usize; 4] {
        let mut c = [0; 4];
        for s in &self.status {
            c[match s {
                BeamStatus::Valid => 0,
                BeamStatus::MaxRange => 1,
                BeamStatus::TooClose => 2,
                BeamStatus::Invalid => 3,
            }] += 1;
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalid_readings_are_marked_not_pointed() {
        let g = BeamGeometry::centered(5, std::f64::consts::PI, 10.0);
        let s = Scan::new(1.0, g, vec![1.0, f64::NAN, 10.0, -1.0, f64::INFINITY]).unwrap();
        assert_eq!(s.beams(), 5);
        assert_eq!(s.valid_count(), 1);
        assert_eq!(
            s.status(),
            &[
                BeamStatus::Valid,
                BeamStatus::Invalid,
                BeamStatus::MaxRange,
                BeamStatus::Invalid,
                BeamStatus::Invalid
            ]
        );
        // First beam points to −90°: the point lies on −y.
        assert!((s.points()[0] - Point2::new(0.0, -1.0)).norm() < 1e-12);
        assert_eq!(s.status_counts(), [1, 1, 0, 3]);
    }

    /// A scan of zero ranges used to put every point at the laser itself, and matching those
    /// points pinned the robot where it stood: a reading of 0 is no return.
    #[test]
    fn zero_ranges_are_no_returns_not_points_at_the_laser() {
        let g = BeamGeometry::centered(4, std::f64::consts::PI, 10.0);
        let s = Scan::new(1.0, g, vec![0.0, 0.0, 2.0, 0.0]).unwrap();
        assert_eq!(s.valid_count(), 1);
        assert_eq!(s.status()[0], BeamStatus::TooClose);
        assert!(s.points().iter().all(|p| p.coords.norm() > 1.0));
    }

    #[test]
    fn bad_geometry_and_empty_scans_are_refused() {
        let g = BeamGeometry::centered(3, 1.0, -1.0);
        assert!(matches!(
            Scan::new(0.0, g, vec![1.0; 3]),
            Err(ScanError::BadParameter {
                name: "max_range",
                ..
            })
        ));
        let g = BeamGeometry::centered(3, 1.0, 5.0);
        assert_eq!(Scan::new(0.0, g, vec![]), Err(ScanError::NoBeams));
    }
}
