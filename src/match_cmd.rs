//! `qicp match LOG --matcher KIND [--config FILE] --out DIR`.

use crate::logs::carmen::load_for_command;
use crate::matching::{run_matcher, write_run};
use anyhow::{Context, Result, bail};
use qicp_matchers::{MatcherConfig, MatcherKind};
use std::path::PathBuf;

/// Arguments of `qicp match`.
#[derive(Debug, clap::Args)]
pub struct MatchArgs {
    /// CARMEN log (plain or .bz2); not with --subscribe.
    #[arg(required_unless_present = "subscribe")]
    pub log: Option<PathBuf>,
    /// Matcher kind: idc, wsm, q-idc, q-wsm, kd-idc, kd-wsm. Overrides the config's kind.
    #[arg(long)]
    pub matcher: Option<MatcherKind>,
    /// TOML file with a `[matcher]` table (kind and parameters).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output directory (optional with --subscribe).
    #[arg(long, required_unless_present = "subscribe")]
    pub out: Option<PathBuf>,
    /// Skip and count malformed log lines instead of failing.
    #[arg(long)]
    pub lenient: bool,
    /// Freiburg relations file: score the trajectory and add the figures to summary.json.
    #[arg(long)]
    pub relations: Option<PathBuf>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Take the scans from the iceoryx2 bridge instead of a log.
    #[command(flatten)]
    pub bridge: crate::bridge_cmd::SubscribeArgs,
}

/// Loads the matcher config: a file, a kind, or both (the kind overrides the file's).
pub fn load_config(file: Option<&PathBuf>, kind: Option<MatcherKind>) -> Result<MatcherConfig> {
    let mut config = match (file, kind) {
        (None, None) => bail!("give --matcher KIND or --config FILE"),
        (None, Some(kind)) => MatcherConfig::defaults(kind),
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            MatcherConfig::from_toml(&text).with_context(|| format!("in {}", path.display()))?
        }
    };
    if let Some(kind) = kind {
        config.kind = kind;
    }
    config.validate()?;
    config.fill_defaults();
    Ok(config)
}

/// Runs the command.
pub fn run(args: MatchArgs) -> Result<()> {
    let config = load_config(args.config.as_ref(), args.matcher)?;
    if args.bridge.subscribe {
        return crate::bridge_cmd::run_subscribe(
            &config,
            args.out.as_deref(),
            args.json,
            &args.bridge,
        );
    }
    let (Some(log_path), Some(out)) = (&args.log, &args.out) else {
        bail!("give a LOG and --out DIR (or --subscribe)");
    };
    let log = load_for_command(log_path, args.lenient)?;
    let run = run_matcher(&log.records, &config, true)?;
    write_run(out, &run, &config)?;
    let mut summary = serde_json::to_value(&run.summary)?;
    summary["skipped_lines"] = log.skipped_lines.into();
    if let Some(path) = &args.relations {
        let relations = crate::logs::relations::read_relations(path)?;
        let report = crate::eval::evaluate_relations(&run.trajectory, &relations, 0.1)?;
        summary["relations"] = serde_json::to_value(report)?;
    }
    let text = serde_json::to_string_pretty(&summary)?;
    std::fs::write(out.join("summary.json"), &text)?;
    if args.json {
        println!("{text}");
    } else {
        eprintln!("{text}");
    }
    Ok(())
}
