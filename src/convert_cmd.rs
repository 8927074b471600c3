//! `qicp convert LOG OUT.mcap`: a CARMEN log as a ROS 2 bag (MCAP storage), for ROS tools
//! and for `qicp match` on bags.

use crate::logs::carmen::{CarmenOptions, DEFAULT_MAX_BEAMS, RecordOrder};
use crate::logs::{LogOptions, LogReader};
use crate::matching::{BagOutput, progress_spinner};
use anyhow::{Result, bail};
use qicp_runner::output::refuse_to_overwrite;
use std::path::PathBuf;

/// Arguments of `qicp convert`.
#[derive(Debug, clap::Args)]
pub struct ConvertArgs {
    /// CARMEN log (plain or .bz2).
    pub log: PathBuf,
    /// The bag to write (MCAP): `sensor_msgs/msg/LaserScan` on /scan (frame `laser`, ranges as
    /// float32), `nav_msgs/msg/Odometry` on /odom (odom -> base_link), the same transform on
    /// /tf and the laser's pose on the robot on /tf_static.
    pub out: PathBuf,
    /// Skip and count malformed log lines instead of failing.
    #[arg(long)]
    pub lenient: bool,
    /// Readings a laser line may announce at most; longer lines are malformed.
    #[arg(long, default_value_t = DEFAULT_MAX_BEAMS)]
    pub max_beams: usize,
    /// Convert at most this many records (all by default).
    #[arg(long)]
    pub max_records: Option<usize>,
    /// The log's laser.
    #[command(flatten)]
    pub laser: crate::match_cmd::LaserArgs,
}

/// Runs the command.
pub fn run(args: ConvertArgs) -> Result<()> {
    crate::matching::remove_on_signal()?;
    let options = LogOptions {
        carmen: args.laser.apply(CarmenOptions {
            lenient: args.lenient,
            max_beams: args.max_beams,
            // A bag's messages go in time order, and a bag's odometry is interpolated at
            // each scan's stamp from the samples around it: a log whose stamps jitter
            // against its file order (Intel's) is sorted by time here.
            order: RecordOrder::Time,
            ..CarmenOptions::default()
        }),
        ..LogOptions::default()
    };
    refuse_to_overwrite(&args.log, &[&args.out])?;
    let mut reader = LogReader::open(&args.log, &options)?;
    if matches!(reader, LogReader::Bag(_)) {
        bail!("{} is already a bag (MCAP)", args.log.display());
    }
    let mut bag = BagOutput::create(&args.out)?;
    let limit = args.max_records.unwrap_or(usize::MAX);
    let bar = progress_spinner("convert");
    for record in reader.by_ref().take(limit) {
        bag.writer.record(&record?)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    reader.warn(&args.log);
    if reader.records() == 0 {
        return Err(reader.empty(&args.log).into());
    }
    bag.commit()?;
    qicp_core::note!(
        "wrote {} records of {} to {}",
        reader.records(),
        args.log.display(),
        args.out.display()
    );
    Ok(())
}
