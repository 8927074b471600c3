//! `qicp eval …`: trajectory metrics.

use anyhow::Result;
use clap::Subcommand;

/// Evaluations.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {}

/// Runs the command.
pub fn run(c: EvalCommand) -> Result<()> {
    match c {}
}
