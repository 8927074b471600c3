//! `qicp bench …`: user-facing benchmarks that print JSON.

use anyhow::Result;
use clap::Subcommand;

/// Benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {}

/// Runs the command.
pub fn run(c: BenchCommand) -> Result<()> {
    match c {}
}
