//! # qicp
//!
//! The application layer of qicp: log readers and writers, evaluation metrics, benchmarks,
//! simulation and matching commands. The `qicp` binary is a thin front end over this library.
#![warn(missing_docs)]

pub mod bench;
pub mod bridge_cmd;
pub mod eval;
pub mod experiment;
pub mod logs;
pub mod match_cmd;
pub mod matching;
pub mod plots;
pub mod sim_cmd;
pub mod sweep;
