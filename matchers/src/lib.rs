//! # qicp-matchers
//!
//! The scan matchers of qicp and the pipelines that turn them into laser odometry:
//!
//! - [`Idc`]: Iterative Dual Correspondence (Lu & Milios 1997);
//! - [`Wsm`]: Weighted Scan Matching (Pfister et al. 2002);
//! - [`Pipeline`]: a matcher with a reference policy, scan-to-scan against the latest relevant scan ([`Policy::Incremental`])
//!   or boosted against a map of every relevant scan ([`Policy::Boosted`], paper Alg. 1) with
//!   mutual-nearest correspondences (paper Alg. 2). The named compositions are type aliases:
//!   [`QIdc`], [`QWsm`], [`KdIdc`], [`KdWsm`];
//! - around Alg. 1, each switchable: [`Validator`] checks a match before it enters the map
//!   ([`validation`]), and [`CorrelativeSearch`] (Olson 2009) re-matches a suspect scan from the
//!   best pose of a window around the prediction ([`correlative`]);
//! - [`MatcherConfig`]: the TOML registry that builds any of them as `Box<dyn Odometry>`.
#![warn(missing_docs)]

pub mod config;
pub mod correlative;
pub mod icp;
pub mod idc;
pub mod lsq;
pub mod params;
pub mod pipeline;
pub mod registry;
pub mod validation;
pub mod wsm;

pub use config::{ConfigError, KdIdc, KdWsm, MatcherConfig, MatcherKind, QIdc, QWsm};
pub use correlative::{Candidate, CorrelativeParams, CorrelativeSearch};
pub use icp::IcpParams;
pub use idc::{Idc, IdcAlgorithm, IdcParams};
pub use params::{Param, Range};
pub use pipeline::{Estimate, MotionModel, Odometry, Pipeline, Policy, Relevance};
pub use registry::{Algorithm, AnyIndex, IndexEntry, Metric, ReferenceKind, Registry};
pub use validation::{Check, Fit, Level, ValidationParams, Validator};
pub use wsm::{Wsm, WsmAlgorithm, WsmParams};
