//! The wire types: `#[repr(C)]`, fixed layout, no pointers, shared as-is through iceoryx2.
//!
//! Every field is 4 or 8 bytes wide and 8-byte fields sit at multiples of 8, so the C, C++
//! and Python (`ctypes.Structure`) mirrors in `bridge/README.md` and
//! `bridge/examples/subscriber.py` have the same layout with no packing pragmas. The layout
//! tests at the bottom of this file pin the sizes and offsets.

use iceoryx2::prelude::ZeroCopySend;
use qicp_core::{BeamGeometry, Fallback, MatchResult, Pose2, Record, Scan, ScanError};

/// Version of the layout below; bumped on any change of a field's place, type or meaning,
/// checked by every subscriber. 2: `certainty` is sqrt(σxx² + σyy²) in m² (was sqrt(σxx + σyy)
/// in m). 3: every message names its publisher (`ScanHeader::publisher`,
/// `PoseMessage::publisher` and `scan_publisher`), so a sequence number is always read as
/// (publisher, seq).
pub const LAYOUT_VERSION: u32 = 3;

/// `kind` of a message carrying data (a scan or a pose).
pub const KIND_DATA: u32 = 0;
/// `kind` of the end-of-stream marker: no payload; its `seq` is the number of data messages the
/// publisher sent before it (so a subscriber can count a lost tail).
pub const KIND_END_OF_STREAM: u32 = 1;

/// `ScanHeader::flags` bit: `truth` holds a ground-truth pose.
pub const FLAG_HAS_TRUTH: u32 = 1;

/// A 2D pose (x, y in metres, theta in radians), 24 bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("qicp::PoseC")]
pub struct PoseC {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// Heading (rad).
    pub theta: f64,
}

impl From<Pose2> for PoseC {
    fn from(p: Pose2) -> Self {
        Self {
            x: p.x,
            y: p.y,
            theta: p.theta,
        }
    }
}

impl From<PoseC> for Pose2 {
    fn from(p: PoseC) -> Self {
        // Not `Pose2::new`: it would re-normalise theta, and a round trip must be exact.
        Pose2 {
            x: p.x,
            y: p.y,
            theta: p.theta,
        }
    }
}

/// The identity a publisher writes into its messages: iceoryx2's unique id of the publisher port
/// (the `publisher_id` of every sample's header), folded to 64 bits; never 0, so that 0 can
/// stand for "no publisher". A restarted publisher has a new identity.
#[must_use]
pub fn publisher_identity(unique_id: u128) -> u64 {
    let folded = (unique_id as u64) ^ ((unique_id >> 64) as u64);
    folded.max(1)
}

/// The user header of a scan sample (144 bytes); the sample's payload is the slice of `beams`
/// ranges (`f64`, metres, raw as measured) that follows it in shared memory.
///
/// Service `<prefix>/scan`: payload `[f64]`, user header `ScanHeader`
/// (iceoryx2 type names `"f64"` and `"qicp::ScanHeader"`).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("qicp::ScanHeader")]
pub struct ScanHeader {
    /// [`LAYOUT_VERSION`].
    pub layout_version: u32,
    /// [`KIND_DATA`] or [`KIND_END_OF_STREAM`].
    pub kind: u32,
    /// 0, 1, 2, … per publisher (see `publisher`); a restarted publisher starts again at 0.
    pub seq: u64,
    /// Time of the sweep (s).
    pub timestamp: f64,
    /// Robot pose by odometry at the sweep.
    pub odometry: PoseC,
    /// Robot pose by ground truth (valid if `flags & FLAG_HAS_TRUTH`).
    pub truth: PoseC,
    /// Pose of the laser in the robot frame.
    pub laser_offset: PoseC,
    /// Bearing of the first beam (rad).
    pub angle_min: f64,
    /// Bearing step between beams (rad).
    pub angle_increment: f64,
    /// Readings at or beyond this are "no return" (m).
    pub max_range: f64,
    /// Readings below this are invalid (m).
    pub min_range: f64,
    /// Number of ranges in the payload.
    pub beams: u32,
    /// [`FLAG_HAS_TRUTH`].
    pub flags: u32,
    /// The publisher's identity ([`publisher_identity`]): `seq` counts within it.
    pub publisher: u64,
}

impl ScanHeader {
    /// The header of `record`, numbered `seq`.
    #[must_use]
    pub fn of(record: &Record, seq: u64) -> Self {
        let g = record.scan.geometry;
        Self {
            layout_version: LAYOUT_VERSION,
            kind: KIND_DATA,
            seq,
            timestamp: record.timestamp(),
            odometry: record.odometry.into(),
            truth: record.truth.map(PoseC::from).unwrap_or_default(),
            laser_offset: record.laser_offset.into(),
            angle_min: g.angle_min,
            angle_increment: g.angle_increment,
            max_range: g.max_range,
            min_range: g.min_range,
            beams: record.scan.beams() as u32,
            flags: if record.truth.is_some() {
                FLAG_HAS_TRUTH
            } else {
                0
            },
            publisher: 0,
        }
    }

    /// The end-of-stream marker after `sent` data messages.
    #[must_use]
    pub fn end_of_stream(sent: u64) -> Self {
        Self {
            layout_version: LAYOUT_VERSION,
            kind: KIND_END_OF_STREAM,
            seq: sent,
            ..Self::default()
        }
    }

    /// The beam layout.
    #[must_use]
    pub fn geometry(&self) -> BeamGeometry {
        BeamGeometry {
            angle_min: self.angle_min,
            angle_increment: self.angle_increment,
            max_range: self.max_range,
            min_range: self.min_range,
        }
    }

    /// Rebuilds the record from this header and the ranges read in place from the sample.
    ///
    /// This is the one copy on the receiving side: [`Scan`] owns its `Vec<f64>` of ranges,
    /// so `ranges` (still in shared memory) is copied once into it; the transport itself
    /// copied nothing between the publisher's write into the loaned sample and this read.
    ///
    /// Poses must be finite and within ±[`MAX_COORDINATE`](qicp_core::index::MAX_COORDINATE)
    /// m (the largest coordinate a map holds), as the log readers require: a neighbour's
    /// garbage is refused here, not matched into a trajectory of NaNs.
    pub fn to_record(&self, ranges: &[f64]) -> Result<Record, ScanError> {
        let usable = |name: &'static str, p: &PoseC| {
            let limit = qicp_core::index::MAX_COORDINATE;
            if !(p.x.is_finite() && p.y.is_finite() && p.x.abs() <= limit && p.y.abs() <= limit) {
                let value = if p.x.is_finite() && p.x.abs() <= limit {
                    p.y
                } else {
                    p.x
                };
                let why = "must be finite and within the map's coordinate range";
                return Err(ScanError::BadParameter { name, value, why });
            }
            if !p.theta.is_finite() {
                let why = "heading must be finite";
                return Err(ScanError::BadParameter {
                    name,
                    value: p.theta,
                    why,
                });
            }
            Ok(())
        };
        usable("odometry", &self.odometry)?;
        usable("laser_offset", &self.laser_offset)?;
        if self.flags & FLAG_HAS_TRUTH != 0 {
            usable("truth", &self.truth)?;
        }
        Ok(Record {
            scan: Scan::new(self.timestamp, self.geometry(), ranges.to_vec())?,
            odometry: self.odometry.into(),
            truth: (self.flags & FLAG_HAS_TRUTH != 0).then(|| self.truth.into()),
            laser_offset: self.laser_offset.into(),
        })
    }
}

/// `PoseMessage::fallback` codes (0: matched).
pub mod fallback_code {
    /// The scan was matched.
    pub const MATCHED: u32 = 0;
    /// Too few valid beams.
    pub const TOO_FEW_POINTS: u32 = 1;
    /// Too few correspondences.
    pub const TOO_FEW_CORRESPONDENCES: u32 = 2;
    /// Nothing to match against (the first scan).
    pub const EMPTY_REFERENCE: u32 = 3;
    /// Degenerate least-squares system.
    pub const DEGENERATE: u32 = 4;
    /// The match was refused by validation; the pose is the prediction.
    pub const REFUSED: u32 = 5;
}

/// One pose estimate of the matcher (176 bytes), the payload of `<prefix>/pose`
/// (iceoryx2 type name `"qicp::PoseMessage"`, no user header).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("qicp::PoseMessage")]
pub struct PoseMessage {
    /// [`LAYOUT_VERSION`].
    pub layout_version: u32,
    /// [`KIND_DATA`] or [`KIND_END_OF_STREAM`].
    pub kind: u32,
    /// 0, 1, 2, … per pose publisher (see `publisher`).
    pub seq: u64,
    /// `seq` of the scan this pose estimates, in the numbering of `scan_publisher`.
    pub scan_seq: u64,
    /// Time of the scan (s).
    pub timestamp: f64,
    /// Robot pose in the world (frame of the first odometry reading).
    pub pose: PoseC,
    /// Covariance of the match (x, y, theta), row-major 3×3; NaN where the matcher gives none.
    pub covariance: [f64; 9],
    /// Residual correlation distance (m); NaN for a fallback.
    pub residual: f64,
    /// Matching certainty sqrt(σxx² + σyy²) of the covariance diagonal (m²); NaN for a fallback.
    pub certainty: f64,
    /// [`fallback_code`]: 0 if matched, else why the scan fell back to odometry.
    pub fallback: u32,
    /// 1 if the scan entered the matcher's reference (map).
    pub inserted: u32,
    /// Iterations the matcher ran.
    pub iterations: u32,
    /// Correspondences in the final iteration.
    pub correspondences: u32,
    /// The pose publisher's identity ([`publisher_identity`]): `seq` counts within it.
    pub publisher: u64,
    /// The identity of the scan's publisher ([`ScanHeader::publisher`]): `scan_seq` counts
    /// within it.
    pub scan_publisher: u64,
}

impl PoseMessage {
    /// The message for one estimate.
    #[must_use]
    pub fn of(
        seq: u64,
        scan_seq: u64,
        timestamp: f64,
        pose: Pose2,
        result: &MatchResult,
        inserted: bool,
    ) -> Self {
        let matched = result.fallback.is_none();
        let mut covariance = [f64::NAN; 9];
        for r in 0..3 {
            for c in 0..3 {
                covariance[3 * r + c] = result.covariance[(r, c)];
            }
        }
        Self {
            layout_version: LAYOUT_VERSION,
            kind: KIND_DATA,
            seq,
            scan_seq,
            timestamp,
            pose: pose.into(),
            covariance,
            residual: if matched { result.residual } else { f64::NAN },
            certainty: if matched {
                result.certainty()
            } else {
                f64::NAN
            },
            fallback: match result.fallback {
                None => fallback_code::MATCHED,
                Some(Fallback::TooFewPoints { .. }) => fallback_code::TOO_FEW_POINTS,
                Some(Fallback::TooFewCorrespondences { .. }) => {
                    fallback_code::TOO_FEW_CORRESPONDENCES
                }
                Some(Fallback::EmptyReference) => fallback_code::EMPTY_REFERENCE,
                Some(Fallback::Degenerate) => fallback_code::DEGENERATE,
                Some(Fallback::Refused) => fallback_code::REFUSED,
            },
            inserted: u32::from(inserted),
            iterations: result.iterations,
            correspondences: u32::try_from(result.correspondences).unwrap_or(u32::MAX),
            publisher: 0,
            scan_publisher: 0,
        }
    }

    /// The end-of-stream marker after `sent` poses.
    #[must_use]
    pub fn end_of_stream(sent: u64) -> Self {
        Self {
            layout_version: LAYOUT_VERSION,
            kind: KIND_END_OF_STREAM,
            seq: sent,
            ..Self::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    /// The layout documented in bridge/README.md and mirrored in examples/subscriber.py.
    #[test]
    fn layouts_match_the_documentation() {
        assert_eq!(size_of::<PoseC>(), 24);
        assert_eq!(size_of::<ScanHeader>(), 144);
        assert_eq!(align_of::<ScanHeader>(), 8);
        assert_eq!(offset_of!(ScanHeader, seq), 8);
        assert_eq!(offset_of!(ScanHeader, timestamp), 16);
        assert_eq!(offset_of!(ScanHeader, odometry), 24);
        assert_eq!(offset_of!(ScanHeader, truth), 48);
        assert_eq!(offset_of!(ScanHeader, laser_offset), 72);
        assert_eq!(offset_of!(ScanHeader, angle_min), 96);
        assert_eq!(offset_of!(ScanHeader, min_range), 120);
        assert_eq!(offset_of!(ScanHeader, beams), 128);
        assert_eq!(offset_of!(ScanHeader, flags), 132);
        assert_eq!(offset_of!(ScanHeader, publisher), 136);

        assert_eq!(size_of::<PoseMessage>(), 176);
        assert_eq!(align_of::<PoseMessage>(), 8);
        assert_eq!(offset_of!(PoseMessage, scan_seq), 16);
        assert_eq!(offset_of!(PoseMessage, timestamp), 24);
        assert_eq!(offset_of!(PoseMessage, pose), 32);
        assert_eq!(offset_of!(PoseMessage, covariance), 56);
        assert_eq!(offset_of!(PoseMessage, residual), 128);
        assert_eq!(offset_of!(PoseMessage, certainty), 136);
        assert_eq!(offset_of!(PoseMessage, fallback), 144);
        assert_eq!(offset_of!(PoseMessage, correspondences), 156);
        assert_eq!(offset_of!(PoseMessage, publisher), 160);
        assert_eq!(offset_of!(PoseMessage, scan_publisher), 168);
    }

    #[test]
    fn publisher_identity_is_never_zero_and_keeps_both_halves() {
        assert_eq!(publisher_identity(0), 1);
        assert_ne!(publisher_identity(5), publisher_identity(6));
        assert_ne!(publisher_identity(1 << 64), publisher_identity(2 << 64));
    }

    #[test]
    fn record_round_trips_exactly() {
        let geometry = BeamGeometry::centered(181, std::f64::consts::PI, 20.0);
        let ranges: Vec<f64> = (0..181).map(|i| 1.0 + f64::from(i) * 0.013).collect();
        let record = Record {
            scan: Scan::new(12.5, geometry, ranges.clone()).expect("scan"),
            odometry: Pose2::new(1.0, -2.0, 0.3),
            truth: Some(Pose2::new(1.1, -2.1, 0.31)),
            laser_offset: Pose2::new(0.1, 0.0, 0.0),
        };
        let header = ScanHeader::of(&record, 7);
        assert_eq!(header.seq, 7);
        let back = header.to_record(&ranges).expect("record");
        assert_eq!(back, record);

        let no_truth = Record {
            truth: None,
            ..record
        };
        let back = ScanHeader::of(&no_truth, 0)
            .to_record(&ranges)
            .expect("record");
        assert_eq!(back.truth, None);
    }
}
