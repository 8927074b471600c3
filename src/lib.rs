//! # qicp
//!
//! The application layer of qicp: log readers and writers, evaluation metrics, benchmarks,
//! simulation and matching commands. The `qicp` binary is a thin front end over this library.
#![warn(missing_docs)]

pub mod bench;
/// Trajectory metrics: the `qicp-eval` crate.
pub use qicp_eval as eval;
/// Log readers and writers: the `qicp-io` crate.
pub use qicp_io as logs;
pub mod bridge_cmd;
pub mod convert_cmd;
pub mod eval_cmd;
/// Experiments (`qicp run`): the `qicp-experiment` crate.
pub use qicp_experiment as experiment;
pub mod match_cmd;
/// The pictures: the `qicp-plots` crate.
pub use qicp_plots as plots;
/// The match loop and its outputs: the `qicp-runner` crate's.
pub use qicp_runner::matching;
pub mod sim_cmd;
/// The robustness sweep: the `qicp-runner` crate's.
pub use qicp_runner::sweep;
pub mod sweep_cmd;

use qicp_matchers::Registry;
use std::sync::LazyLock;

static REGISTRY: LazyLock<Registry> = LazyLock::new(|| {
    let mut registry = Registry::builtin();
    // PL-ICP lives in its own crate, written against the public qicp crates only: the
    // command line offers it by registering it here, next to the built-in algorithms.
    qicp_plicp::register(&mut registry);
    registry
});

/// The registry the `qicp` command resolves matcher names with: the built-in algorithms and
/// indexes, and the matchers of the crates this package registers next to them.
#[must_use]
pub fn registry() -> &'static Registry {
    &REGISTRY
}
