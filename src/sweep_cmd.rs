//! `qicp sweep LOG --matcher KIND [--relations FILE]`: the command over
//! [`qicp_runner::sweep`], which holds the variants, the runs and the report.

use anyhow::Result;
use qicp_runner::sweep::{
    SweepInput, all_variants, report, select_variants, sweep as run_sweep, table,
};
use std::num::NonZeroUsize;
use std::path::PathBuf;

/// Arguments of `qicp sweep`.
#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// CARMEN log (plain or .bz2), or ROS 2 bag (MCAP) with scans on /scan and odometry on /odom.
    pub log: PathBuf,
    /// Matcher kind: idc, wsm, q-idc, q-wsm, kd-idc, kd-wsm. Overrides the config's kind.
    #[arg(long)]
    pub matcher: Option<String>,
    /// TOML file with a `[matcher]` table: the default configuration.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Freiburg relations file every run is scored with. Without it every variant is scored
    /// against the default run: relations drawn along the default's trajectory (a segment
    /// per metre or 30°, and its revisits of a place; see `--reference`), so the figures are
    /// disagreements with the default, not errors.
    #[arg(long)]
    pub relations: Option<PathBuf>,
    /// Score every run against this trajectory of the log instead (TUM: another matcher's or
    /// a SLAM system's): relations drawn along it, a segment per metre or 30° and a revisit
    /// wherever it comes back within a metre of where it was a minute or more before, so
    /// that a log without relations is swept against a trajectory you trust, not against the
    /// default.
    #[arg(long, value_name = "TUM", conflicts_with = "relations")]
    pub reference: Option<PathBuf>,
    /// Print the report as JSON on stdout (progress stays on stderr).
    #[arg(long)]
    pub json: bool,
    /// Runs at a time (default: the available cores).
    #[arg(long)]
    pub jobs: Option<NonZeroUsize>,
    /// Use only the first N records of the log.
    #[arg(long)]
    pub scans: Option<NonZeroUsize>,
    /// Run only these variants (comma-separated names; the default always runs).
    #[arg(long, value_delimiter = ',')]
    pub variants: Option<Vec<String>>,
    /// Skip and count malformed log lines instead of failing.
    #[arg(long)]
    pub lenient: bool,
    /// The order of a CARMEN log's records: as the file gives them (the order the laser took
    /// them), or sorted by timestamp.
    #[arg(long, value_enum, default_value_t = crate::match_cmd::LogOrder::File)]
    pub order: crate::match_cmd::LogOrder,
    /// A CARMEN log's laser.
    #[command(flatten)]
    pub laser: crate::match_cmd::LaserArgs,
    /// Also write each run's trajectory to DIR/<run>.tum (e.g. default.tum, scans-2.tum), to
    /// see where a variant goes wrong (`qicp eval relations DIR/scans-2.tum RELATIONS --max-dt
    /// 1e-6` scores it as the sweep does, on the records it matched, where the relations' times
    /// are the log's own).
    #[arg(long, value_name = "DIR")]
    pub trajectories: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: SweepArgs) -> Result<()> {
    crate::matching::remove_on_signal()?;
    // Everything that can be refused is checked before the log is read and before matching.
    let config = crate::match_cmd::load_config(args.config.as_ref(), args.matcher.as_deref())?;
    let all = all_variants(&config);
    let variants = match &args.variants {
        Some(names) => select_variants(all, names)?,
        None => all,
    };
    let carmen = args.laser.apply(crate::logs::carmen::CarmenOptions {
        lenient: args.lenient,
        order: args.order.into(),
        ..crate::logs::carmen::CarmenOptions::default()
    });
    let mut input = match (&args.relations, &args.reference) {
        (Some(relations), _) => SweepInput::load_with(&args.log, relations, args.scans, carmen)?,
        (None, Some(reference)) => {
            SweepInput::against_trajectory(&args.log, reference, args.scans, carmen)?
        }
        (None, None) => SweepInput::against_default(&args.log, args.scans, carmen)?,
    };
    if let Some(dir) = &args.trajectories {
        input = input.with_trajectories(dir)?;
    }
    let jobs = args
        .jobs
        .or_else(|| std::thread::available_parallelism().ok())
        .map_or(1, NonZeroUsize::get);
    qicp_core::note!(
        "sweeping {} on {} scans: default + {} variants, {jobs} at a time{}",
        config.kind(),
        input.scans,
        variants.len(),
        if input.against_default {
            " (no relations: the default runs first, and each variant is scored against it)"
        } else {
            ""
        }
    );
    let (default, reports) = run_sweep(
        &input,
        &config,
        &variants,
        jobs,
        |name, result, elapsed| match result {
            Ok(f) => qicp_core::note!(
                "variant {name} done in {:.1} s (trans_mean {:.4} m)",
                elapsed.as_secs_f64(),
                f.trans_mean
            ),
            Err(e) => qicp_core::note!("variant {name} failed: {e}"),
        },
    )?;
    let report = report(&input, &config, default, reports);
    if args.json {
        qicp_core::say!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        qicp_core::output::write_stdout(&table(&report))?;
    }
    Ok(())
}
