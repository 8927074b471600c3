//! `qicp eval …`: trajectory metrics.

use anyhow::Result;
use clap::Subcommand;

/// Evaluations.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {}

pub fn run(c: EvalCommand) -> Result<()> {
    match c {}
}
