//! # qicp-matchers
//!
//! The scan matchers of qicp and the pipelines that turn them into laser odometry:
//!
//! - [`Idc`]: Iterative Dual Correspondence (Lu & Milios 1997);
//! - [`Wsm`]: Weighted Scan Matching (Pfister et al. 2002);
//! - [`Pipeline`]: a matcher with a reference policy ([`ReferencePolicy`]), scan-to-scan against
//!   the latest relevant scan ([`ScanPolicy`], [`Policy::Incremental`]) or boosted against a map
//!   of every relevant scan ([`MapPolicy`], [`Policy::Boosted`], paper Alg. 1) with
//!   mutual-nearest correspondences (paper Alg. 2). The named compositions are type aliases:
//!   [`QIdc`], [`QWsm`], [`KdIdc`], [`KdWsm`];
//! - around Alg. 1, each switchable: [`Validator`] checks a match before it enters the map
//!   ([`validation`]), and [`CorrelativeSearch`] (Olson 2009) re-matches a suspect scan from the
//!   best pose of a window around the prediction ([`correlative`]), and [`Revisit`]
//!   re-anchors a match to the old map when the robot comes back to ground it mapped long
//!   before ([`revisit`]);
//! - [`Registry`]: algorithms, indexes and reference policies by name, composed by a
//!   [`MatcherConfig`] (from TOML or a name such as `"q-wsm"`) into a `Box<dyn Odometry>`.
//!   Another crate adds its matcher with [`Registry::register`] (see `qicp-plicp`), its
//!   parameters declared once ([`Param`]) and checked like the built-in ones, and its reference
//!   policy ([`ReferencePolicy`]) with [`Registry::register_reference`].
//!
//! ```
//! use qicp_core::{Pose2, Record, testdata::SyntheticWorld};
//! use qicp_matchers::Registry;
//!
//! let mut q_wsm = Registry::builtin().config("q-wsm")?.build()?;
//! let room = SyntheticWorld::room();
//! for k in 0..20 {
//!     let truth = Pose2::new(0.1 * k as f64, 0.0, 0.02 * k as f64);
//!     let odometry = truth * Pose2::new(0.01 * k as f64, 0.0, 0.0); // slipping wheels
//!     let scan = room.scan(&truth, 0.005, k as u64);
//!     let estimate = q_wsm.process(&Record { scan, odometry, truth: None, laser_offset: Pose2::IDENTITY });
//!     assert!(estimate.pose.distance(&truth) < 0.02);
//! }
//! # Ok::<(), qicp_matchers::ConfigError>(())
//! ```
#![warn(missing_docs)]

pub mod calibration;
pub mod config;
pub mod correlative;
pub mod degeneracy;
pub mod icp;
pub mod idc;
pub mod lsq;
pub mod params;
pub mod pipeline;
pub mod policy;
pub mod registry;
pub mod revisit;
mod steering;
pub mod trail;
pub mod validation;
pub mod wsm;

pub use config::{
    ConfigError, KdIdc, KdWsm, LASER_PARAMETERS, MatcherConfig, MatcherKind, QIdc, QWsm,
};
pub use correlative::{Candidate, CorrelativeParams, CorrelativeSearch};
pub use icp::IcpParams;
pub use idc::{Idc, IdcAlgorithm, IdcParams};
pub use params::{Acts, Param, Range};
pub use pipeline::{Estimate, MotionModel, Odometry, Pipeline, Policy, Relevance};
pub use policy::{MapPolicy, Matched, ReferencePolicy, ReferenceStore, ScanPolicy};
pub use registry::{Algorithm, AnyIndex, IndexEntry, Metric, ReferenceEntry, Registry};
pub use revisit::{Proposal, Revisit, RevisitParams, Vouch};
pub use validation::{Check, FieldOfView, Fit, Level, Placed, ValidationParams, Validator};
pub use wsm::{Wsm, WsmAlgorithm, WsmParams};
