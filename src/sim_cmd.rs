//! `qicp sim CONFIG --out DIR`.

use anyhow::Result;

/// Arguments of `qicp sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {}

/// Runs the command.
pub fn run(_a: SimArgs) -> Result<()> {
    anyhow::bail!("not yet implemented")
}
