//! `qicp`: the command-line front end of the qicp scan-matching framework.

use qicp::{bench, bridge_cmd, convert_cmd, eval_cmd, experiment, match_cmd, sim_cmd, sweep_cmd};

use anyhow::Result;
use clap::{Parser, Subcommand};
use qicp_core::output::StdoutError;
use std::process::ExitCode;

/// 2D laser scan matching boosted by quad trees (Slamet, Visser, Pfingsthorn).
#[derive(Debug, Parser)]
#[command(name = "qicp", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Benchmarks (print a table, or JSON with --json).
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Convert a CARMEN log into a ROS 2 bag (MCAP: LaserScan, Odometry, /tf).
    Convert(convert_cmd::ConvertArgs),
    /// Evaluate trajectories.
    #[command(subcommand)]
    Eval(eval_cmd::EvalCommand),
    /// Match every scan of a CARMEN log or ROS 2 bag with one matcher; write trajectory, per-scan figures
    /// and a summary.
    Match(match_cmd::MatchArgs),
    /// List the registered algorithms (with their parameters' defaults, ranges and docs),
    /// indexes, reference policies and the composed matcher names.
    Matchers,
    /// Publish a CARMEN log's scans through the iceoryx2 bridge (`--publish`).
    Replay(bridge_cmd::ReplayArgs),
    /// Run an experiment: simulate or load a drive, run every matcher on it, score them and
    /// draw the paper's figures.
    Run(experiment::RunArgs),
    /// Simulate a drive and write a CARMEN log, ground truth and odometry.
    Sim(sim_cmd::SimArgs),
    /// Run a matcher on a log as configured and under fixed input and parameter variants,
    /// score every run with relations and report how much each variant costs.
    Sweep(sweep_cmd::SweepArgs),
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        // stdout's reader went away (`qicp sweep … --json | head -1`): it has what it
        // wanted, and the command ends quietly, as ripgrep does.
        Err(e) if reader_went_away(&e) => ExitCode::SUCCESS,
        Err(e) => {
            qicp_core::note!("Error: {e:?}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Bench(c) => bench::run(c),
        Command::Convert(a) => convert_cmd::run(a),
        Command::Eval(c) => eval_cmd::run(c),
        Command::Match(a) => match_cmd::run(a),
        Command::Matchers => {
            qicp_core::output::write_stdout(&match_cmd::listing(qicp::registry())?)?;
            Ok(())
        }
        Command::Replay(a) => bridge_cmd::run_replay(a),
        Command::Run(a) => experiment::run(&a, qicp::registry()),
        Command::Sim(a) => sim_cmd::run(a),
        Command::Sweep(a) => sweep_cmd::run(a),
    }
}

/// Whether `e` is a result written to a stdout whose reader has closed it (and not, say, a
/// bridge socket whose peer went away, which is an error).
fn reader_went_away(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<StdoutError>()
            .is_some_and(StdoutError::reader_went_away)
    })
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// Every `conflicts_with`, `requires` and default names an argument that exists.
    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }
}
