//! # qicp-core
//!
//! The vocabulary every qicp crate shares: SE(2) poses ([`Pose2`]), laser scans ([`Scan`]),
//! match results ([`MatchResult`]), and the three plug-in points:
//!
//! - [`SpatialIndex`], with the paper's [`QuadTree`], a [`KdTree`] on kiddo, and the
//!   [`BruteForce`] oracle every index is tested against;
//! - [`CorrespondenceMetric`], with [`ClosestPoint`], IDC's [`MatchingRange`] rule and the
//!   paper's mutual-nearest-neighbour rule [`MutualNearest`] (Alg. 2);
//! - [`ScanMatcher`], matching a [`Scan`] against a [`Reference`] (an index plus per-point
//!   normals, spacing and covariance).
#![warn(missing_docs)]

pub mod config_error;
#[cfg(feature = "testkit")]
pub mod conformance;
pub mod index;
pub mod kdtree;
pub mod matcher;
pub mod metric;
pub mod output;
pub mod pose;
pub mod quadtree;
pub mod record;
pub mod reference;
pub mod result;
pub mod scan;
#[cfg(feature = "testkit")]
pub mod testdata;

pub use config_error::ConfigError;
pub use index::{
    BruteForce, IndexError, Neighbour, PointId, SpatialIndex, around_radius, dist_sq,
    fresh_revision, nearest_then_around,
};
pub use kdtree::KdTree;
pub use matcher::{PriorSource, ScanMatcher};
pub use metric::{ClosestPoint, CorrespondenceMetric, MatchingRange, MutualNearest, Pair, Query};
pub use nalgebra::{Matrix2, Matrix3, Point2, Vector2, Vector3};
pub use pose::{Pose2, normalize_angle};
pub use quadtree::{QuadTree, QuadTreeN};
pub use record::Record;
pub use reference::{
    FullCell, LaserNoise, Merge, PointInfo, Reference, scan_point_info, surface_connections,
    surface_normal,
};
pub use result::{Fallback, MatchResult};
pub use scan::{BeamGeometry, BeamStatus, Scan, ScanError};
