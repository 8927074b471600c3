//! # qicp-runner
//!
//! Running a matcher over records, for the command line, the Python package and anyone who
//! drives qicp from Rust:
//!
//! - [`matching`]: the loop that feeds records to a matcher and times it ([`matching::MatchLoop`],
//!   [`matching::run_matcher`]), its per-scan rows and summary, and the run's output files
//!   written in place only when complete ([`matching::RunWriter`]);
//! - [`sweep`]: the robustness sweep: a matcher as configured and under fixed input and
//!   parameter variants, every run scored with the Freiburg relations.
#![warn(missing_docs)]

pub mod matching;
pub mod output;
pub mod sweep;
