//! `qicp match LOG --matcher KIND [--config FILE] --out DIR`.

use crate::eval::{RelationProbe, evaluate_relations};
use crate::logs::carmen::{CarmenOptions, RecordOrder};
use crate::logs::relations::read_relations;
use crate::logs::rosbag::{BagOptions, OdometrySource};
use crate::logs::{LogOptions, LogReader};
use crate::matching::{BagOutput, MatchLoop, RunWriter, progress_spinner};
use anyhow::{Context, Result, bail};
use qicp_matchers::MatcherConfig;
use qicp_runner::output::refuse_to_overwrite;
use std::path::{Path, PathBuf};

/// Arguments of `qicp match`.
#[derive(Debug, clap::Args)]
pub struct MatchArgs {
    /// CARMEN log (plain or .bz2) or ROS 2 bag (MCAP; see --scan-topic); not with
    /// --subscribe.
    #[arg(required_unless_present = "subscribe")]
    pub log: Option<PathBuf>,
    /// Matcher kind: a composed name such as idc, wsm, q-idc, q-wsm, kd-idc, kd-wsm
    /// (`qicp matchers` lists them). Overrides the config's kind.
    #[arg(long)]
    pub matcher: Option<String>,
    /// TOML file with a `[matcher]` table (kind and parameters).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output directory (optional with --subscribe).
    #[arg(long, required_unless_present = "subscribe")]
    pub out: Option<PathBuf>,
    /// Skip and count malformed log lines instead of failing.
    #[arg(long, conflicts_with = "subscribe")]
    pub lenient: bool,
    /// Readings a laser line may announce at most; longer lines are malformed.
    #[arg(long, default_value_t = crate::logs::carmen::DEFAULT_MAX_BEAMS, conflicts_with = "subscribe")]
    pub max_beams: usize,
    /// The order of a CARMEN log's records: as the file gives them (the order the laser took
    /// them), or sorted by timestamp (as `qicp convert` writes a bag).
    #[arg(long, value_enum, default_value_t = LogOrder::File, conflicts_with = "subscribe")]
    pub order: LogOrder,
    /// Freiburg relations file: score the trajectory and add the figures to summary.json
    /// (not with --subscribe).
    #[arg(long, conflicts_with = "subscribe")]
    pub relations: Option<PathBuf>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Where a ROS 2 bag's scans and odometry are.
    #[command(flatten)]
    pub bag: BagArgs,
    /// A CARMEN log's laser.
    #[command(flatten)]
    pub laser: LaserArgs,
    /// Also write a ROS 2 bag (MCAP): the scans, the odometry and the estimated poses
    /// (`nav_msgs/msg/Odometry` on /qicp/odom and the /tf transform map -> odom), to play in
    /// Foxglove or RViz beside the input.
    #[arg(long, value_name = "FILE", conflicts_with = "subscribe")]
    pub out_mcap: Option<PathBuf>,
    /// Take the scans from the iceoryx2 bridge instead of a log.
    #[command(flatten)]
    pub bridge: crate::bridge_cmd::SubscribeArgs,
}

/// A CARMEN log's laser, where its lines and `PARAM`s do not say it right: an option given
/// here wins over the log. A ROS 2 bag, whose scans carry their own, is refused with them.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LaserArgs {
    /// Field of view of `FLASER` scans (degrees, in (0, 360]). Default: the log's
    /// `PARAM laser_front_laser_fov`, else 180.
    #[arg(long, value_name = "DEG", value_parser = |s: &str| laser_value(s, crate::logs::carmen::fov_deg_problem))]
    pub fov_deg: Option<f64>,
    /// Readings at or beyond this are no-returns (m). Default: `PARAM robot_front_laser_max`
    /// for `FLASER` lines, else 81 (SICK LMS no-returns read 81.83-81.91 m); a `ROBOTLASER1`
    /// line's own `max_range` field.
    #[arg(long, value_name = "M", value_parser = |s: &str| laser_value(s, crate::logs::carmen::max_range_problem))]
    pub max_range: Option<f64>,
    /// Readings below this are discarded (m). Default 0.
    #[arg(long, value_name = "M", value_parser = |s: &str| laser_value(s, crate::logs::carmen::min_range_problem))]
    pub min_range: Option<f64>,
}

/// A number that `problem` does not refuse (`--fov-deg`, `--max-range`, `--min-range`).
fn laser_value(s: &str, problem: fn(f64) -> Option<&'static str>) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    problem(v).map_or(Ok(v), |why| Err(why.into()))
}

impl LaserArgs {
    /// `carmen` with these options set.
    #[must_use]
    pub fn apply(&self, carmen: CarmenOptions) -> CarmenOptions {
        CarmenOptions {
            flaser_fov_deg: self.fov_deg.or(carmen.flaser_fov_deg),
            max_range: self.max_range.or(carmen.max_range),
            min_range: self.min_range.unwrap_or(carmen.min_range),
            ..carmen
        }
    }

    /// Whether any option is given.
    #[must_use]
    pub fn any(&self) -> bool {
        self.fov_deg.is_some() || self.max_range.is_some() || self.min_range.is_some()
    }
}

/// The order of a CARMEN log's records ([`RecordOrder`]), as `--order` gives it:
/// `RecordOrder` with clap's derive, which `qicp-io` does without (its names are
/// [`RecordOrder::name`]'s).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum LogOrder {
    /// File order: the order the laser took them.
    #[default]
    File,
    /// Sorted by timestamp.
    Time,
}

impl From<LogOrder> for RecordOrder {
    fn from(order: LogOrder) -> Self {
        match order {
            LogOrder::File => RecordOrder::File,
            LogOrder::Time => RecordOrder::Time,
        }
    }
}

/// Where a ROS 2 bag's scans and odometry are (ignored for CARMEN logs).
#[derive(Debug, Clone, clap::Args)]
pub struct BagArgs {
    /// The `sensor_msgs/msg/LaserScan` topic of a bag.
    #[arg(long, default_value = "/scan", conflicts_with = "subscribe")]
    pub scan_topic: String,
    /// The `nav_msgs/msg/Odometry` topic of a bag.
    #[arg(long, default_value = "/odom", conflicts_with_all = ["odom_frame", "subscribe"])]
    pub odom_topic: String,
    /// Take odometry from /tf instead: the transform from this frame to --base-frame.
    #[arg(long, conflicts_with = "subscribe")]
    pub odom_frame: Option<String>,
    /// The robot's frame, with --odom-frame.
    #[arg(long, default_value = "base_link", requires = "odom_frame")]
    pub base_frame: String,
    /// The bag has no odometry: every scan is read with the same pose and predicted at the
    /// last checked velocity (`[matcher.motion] stall_velocity`); the poses are the laser's.
    #[arg(long, conflicts_with_all = ["odom_topic", "odom_frame", "subscribe"])]
    pub no_odometry: bool,
}

impl BagArgs {
    /// The reader options these arguments give, with the CARMEN ones.
    #[must_use]
    pub fn log_options(&self, carmen: CarmenOptions) -> LogOptions {
        let odometry = if self.no_odometry {
            OdometrySource::None
        } else {
            OdometrySource::from_names(
                &self.odom_topic,
                self.odom_frame.as_deref(),
                &self.base_frame,
            )
        };
        let max_beams = carmen.max_beams;
        LogOptions {
            carmen,
            bag: BagOptions {
                max_beams,
                ..BagOptions::new(self.scan_topic.clone(), odometry)
            },
        }
    }
}

/// Loads the matcher config: a file, a kind, or both (the kind overrides the file's).
pub fn load_config(file: Option<&PathBuf>, kind: Option<&str>) -> Result<MatcherConfig> {
    let registry = crate::registry();
    let mut config = match (file, kind) {
        (None, None) => bail!("give --matcher KIND or --config FILE"),
        (None, Some(kind)) => registry.config(kind)?,
        (Some(path), _) => {
            let mut text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            if let Some(kind) = kind {
                text = with_kind(&text, kind).with_context(|| format!("in {}", path.display()))?;
            }
            registry
                .parse(&text)
                .with_context(|| format!("in {}", path.display()))?
        }
    };
    config.validate()?;
    config.fill_defaults();
    Ok(config)
}

/// The TOML document `text` with its matcher named `kind` instead (the axes it gave dropped).
fn with_kind(text: &str, kind: &str) -> Result<String> {
    let mut doc: toml::Table = toml::from_str(text)?;
    if let Some(toml::Value::Table(m)) = doc.get_mut("matcher") {
        for axis in ["algorithm", "reference", "index"] {
            m.remove(axis);
        }
        m.insert("kind".into(), kind.into());
    }
    Ok(toml::to_string(&doc)?)
}

/// How far (s) a trajectory pose may lie from a relation's time and still stand for it.
const RELATIONS_MAX_DT: f64 = 0.1;

/// Runs the command.
pub fn run(args: MatchArgs) -> Result<()> {
    if args.bridge.subscribe && args.laser.any() {
        bail!(
            "--fov-deg, --max-range and --min-range describe a log's laser: not with --subscribe"
        );
    }
    let config = load_config(args.config.as_ref(), args.matcher.as_deref())?;
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
    crate::matching::remove_on_signal()?;
    // Everything that can be refused is checked before the first scan is matched.
    let relations = args
        .relations
        .as_ref()
        .map(|p| read_relations(p))
        .transpose()?;
    let mut probe = relations
        .as_ref()
        .map(|r| RelationProbe::new(r, RELATIONS_MAX_DT))
        .transpose()?;
    let options = args.bag.log_options(args.laser.apply(CarmenOptions {
        lenient: args.lenient,
        max_beams: args.max_beams,
        order: args.order.into(),
        ..CarmenOptions::default()
    }));
    let outputs: Vec<_> = RunWriter::FILES.iter().map(|f| out.join(f)).collect();
    let mut outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    outputs.extend(args.out_mcap.as_deref());
    refuse_to_overwrite(log_path, &outputs)?;
    let mut reader = LogReader::open(log_path, &options)?;
    let mut matcher = MatchLoop::new(&config)?;
    let mut writer = RunWriter::create(out)?.keeping_poses(matcher.amends());
    let mut bag = args
        .out_mcap
        .as_deref()
        .map(BagOutput::create)
        .transpose()?;

    // Scan by scan: memory holds the matcher's map and the reorder window, not the log.
    let bar = progress_spinner(&config.kind());
    let mut first = true;
    for record in &mut reader {
        let record = record?;
        // Relations of another, earlier log are told at the first scan, not after matching.
        if std::mem::take(&mut first)
            && let (Some(probe), Some(path)) = (&probe, &args.relations)
            && probe.all_before(record.timestamp())
        {
            bail!(
                "every relation of {} lies before the log's first scan ({:.3} s): is it the \
                 log's relations file?",
                path.display(),
                record.timestamp()
            );
        }
        let (estimate, row) = matcher.push(&record);
        if let Some(amendment) = matcher.take_amendment() {
            writer.amend(&amendment)?;
            if let Some(probe) = &mut probe {
                probe.amend(|k| amendment.moved(k));
            }
        }
        writer.push(record.timestamp(), &estimate.pose, &row)?;
        if let Some(bag) = &mut bag {
            bag.writer.record(&record)?;
            bag.writer
                .estimate(record.timestamp(), estimate.pose, record.odometry)?;
        }
        if let Some(probe) = &mut probe {
            probe.push(record.timestamp(), estimate.pose)?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    reader.warn(log_path);
    if reader.records() == 0 {
        return Err(reader.empty(log_path).into());
    }

    let totals = matcher.summary();
    if let Some(warning) = totals.fallback_warning() {
        qicp_core::note!("warning: {warning}");
    }
    let mut summary = serde_json::to_value(&totals)?;
    summary["skipped_lines"] = reader.skipped_lines().into();
    summary["late_lines"] = reader.dropped().into();
    summary["out_of_order_lines"] = reader.out_of_order().into();
    let mut unscored = None;
    if let (Some(relations), Some(probe), Some(path)) = (&relations, &probe, &args.relations) {
        let report = evaluate_relations(&probe.trajectory(), relations, RELATIONS_MAX_DT)?;
        if report.n == 0 {
            unscored = Some(format!(
                "no relation of {} has poses within {RELATIONS_MAX_DT} s in the run ({} \
                 relations, log from {:.3} to {:.3} s): is it the log's relations file?",
                path.display(),
                relations.len(),
                reader.span().map_or(f64::NAN, |s| s.0),
                reader.span().map_or(f64::NAN, |s| s.1),
            ));
        }
        summary["relations"] = serde_json::to_value(report)?;
    }
    let text = serde_json::to_string_pretty(&summary)?;
    if let Some(bag) = bag {
        bag.commit()?;
    }
    writer.commit(&config, Some(&text))?;
    if args.json {
        qicp_core::say!("{text}")?;
    } else {
        qicp_core::note!("{text}");
    }
    if let Some(why) = unscored {
        bail!(why);
    }
    Ok(())
}

/// One line per declared parameter: its default (from `section`), range, whether the sweep
/// perturbs it, and its documentation.
fn write_parameters(
    out: &mut String,
    params: &[qicp_matchers::Param],
    section: Option<&toml::Table>,
) -> std::fmt::Result {
    use std::fmt::Write;
    for p in params {
        let value = section
            .and_then(|s| s.get(p.key))
            .map_or_else(|| "?".into(), ToString::to_string);
        let steering = if p.steering { " [swept]" } else { "" };
        writeln!(
            out,
            "    {} = {value}  ({}){steering}: {}",
            p.key,
            p.range.describe(),
            p.doc
        )?;
    }
    Ok(())
}

/// What `qicp matchers` prints: every algorithm with its parameters (default, range, doc),
/// the indexes and reference policies, and the composed names.
pub fn listing(registry: &qicp_matchers::Registry) -> Result<String> {
    use std::fmt::Write;
    let mut out =
        String::from("algorithms ([matcher] algorithm = NAME; parameters in [matcher.NAME]):\n");
    for name in registry.algorithm_names() {
        let Some((summary, params)) = registry.parameters(name) else {
            continue;
        };
        let defaults = registry.config(name)?.to_table()?;
        let section = defaults.get(name).and_then(toml::Value::as_table);
        writeln!(out, "  {name}: {summary}")?;
        write_parameters(&mut out, params, section)?;
    }
    let laser = qicp_matchers::MatcherConfig::from_toml("[matcher]\nkind = \"wsm\"")?.to_table()?;
    let laser = laser.get("laser").and_then(toml::Value::as_table);
    writeln!(
        out,
        "laser noise ([matcher.laser], every algorithm; [swept] where the algorithm weighs by it):"
    )?;
    write_parameters(&mut out, qicp_matchers::LASER_PARAMETERS, laser)?;
    writeln!(
        out,
        "indexes ([matcher] index = NAME; prefix of composed names):"
    )?;
    for i in registry.indexes() {
        writeln!(out, "  {} ({}-): {}", i.name(), i.prefix(), i.summary())?;
    }
    writeln!(out, "references ([matcher] reference = NAME):")?;
    for r in registry.references() {
        writeln!(out, "  {}: {}", r.name(), r.summary())?;
    }
    writeln!(out, "names (--matcher NAME, [matcher] kind = NAME):")?;
    writeln!(out, "  {}", registry.names().join(", "))?;
    Ok(out)
}

#[cfg(test)]
mod order_tests {
    use super::LogOrder;
    use crate::logs::carmen::RecordOrder;
    use clap::ValueEnum;

    #[test]
    fn the_command_lines_order_names_are_the_readers() {
        for order in LogOrder::value_variants() {
            let name = order.to_possible_value().expect("a name");
            let record = RecordOrder::from(*order);
            assert_eq!(name.get_name(), record.name());
            assert_eq!(name.get_name().parse::<RecordOrder>(), Ok(record));
        }
        assert!("sideways".parse::<RecordOrder>().is_err());
    }
}
