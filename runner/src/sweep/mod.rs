//! Robustness sweeps (`qicp sweep LOG --matcher KIND --relations FILE`): how robust a matcher is to its input and
//! to its parameters (issue 12).
//!
//! The matcher runs on the log once as configured ("default") and once per variant, and every
//! run is scored with the Freiburg relations. A variant perturbs one thing:
//!
//! - **input variants** (deterministic, seeded): fewer scans ([`every_other_record`]), fewer
//!   beams ([`every_other_beam`]), odometry drift ([`noisy_increment`]), a slipping wheel
//!   ([`biased_increment`]), range noise ([`noisy_ranges`]), a shorter-sighted laser
//!   ([`capped_range`]);
//! - **parameter variants**: every key of
//!   [`MatcherConfig::steering_parameters`] times 0.7 and times 1.4, one at a time.
//!
//! The ratio of a variant is its mean translational relation error over the default's; the
//! sweep reports the worst and the median ratio. The runs are spread over worker threads; each
//! run is deterministic, so the figures (all but the wall times) do not depend on `--jobs`.

use crate::matching::MatchLoop;
use anyhow::{Context, Result, bail};
use qicp_core::{BeamGeometry, BeamStatus, Pose2, Record, Scan, ScanError};
use qicp_eval::stats::median;
use qicp_eval::{RelationError, RelationProbe, evaluate_relations, relation_errors};
use qicp_io::carmen::CarmenOptions;
use qicp_io::relations::{Relation, read_relations};
use qicp_io::{LogOptions, LogReader};
use qicp_matchers::MatcherConfig;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

mod perturb;
mod running;
mod variants;

pub use perturb::*;
pub use running::*;
pub use variants::*;

/// Association window (s) of the relations: as `qicp match --relations`.
pub const MAX_DT: f64 = 0.1;
/// A relation whose translational error exceeds this (m) counts as a failure.
pub const FAILURE_M: f64 = 0.5;
/// Seed of the random input variants (issue 12).
pub const SEED: u64 = 12;
/// Factors every steering parameter is scaled by, one at a time.
pub const PARAMETER_FACTORS: [f64; 2] = [0.7, 1.4];

/// Odometry noise: σ of x and y per metre travelled (m/m).
pub const ODOM_NOISE_XY_PER_M: f64 = 0.05;
/// Odometry noise: σ of the heading per metre travelled (2°/m, in rad/m).
pub const ODOM_NOISE_THETA_PER_M: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Odometry noise: σ of the heading per radian turned (rad/rad).
pub const ODOM_NOISE_THETA_PER_RAD: f64 = 0.05;
/// Odometry bias: scale of the translation of every increment.
pub const ODOM_BIAS_SCALE: f64 = 1.05;
/// Odometry bias: heading added per metre travelled (1°/m, in rad/m).
pub const ODOM_BIAS_THETA_PER_M: f64 = std::f64::consts::PI / 180.0;
/// Range noise σ (m).
pub const RANGE_NOISE_SIGMA: f64 = 0.01;
/// Maximum range (m) of the `max-range-10` variant.
pub const CAPPED_MAX_RANGE: f64 = 10.0;

/// One variant's line of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VariantReport {
    /// The variant's name.
    pub name: String,
    /// Its figures (absent when it could not run).
    #[serde(flatten)]
    pub figures: Option<RunFigures>,
    /// Its `trans_mean` over the default's.
    pub ratio: Option<f64>,
    /// Why it could not run (an invalid scaled configuration, say).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The sweep's report (`--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepReport {
    /// The log.
    pub log: String,
    /// Registry name of the matcher.
    pub matcher: String,
    /// Records of the log used.
    pub scans: usize,
    /// Relations in the relations file.
    pub relations_total: usize,
    /// The run with the configuration as given.
    pub default: RunFigures,
    /// Every variant, in report order.
    pub variants: Vec<VariantReport>,
    /// The largest ratio of the variants that ran.
    pub worst_ratio: Option<f64>,
    /// The variant with the largest ratio.
    pub worst_variant: Option<String>,
    /// The median ratio of the variants that ran (the mean of the middle two for an even
    /// count).
    pub median_ratio: Option<f64>,
    /// Relations of the default run with a translational error above 0.5 m.
    pub relations_over_0_5_m: usize,
}

/// The runs of a sweep: the default, then one per variant, in report order.
#[must_use]
pub fn plan(config: &MatcherConfig, variants: &[Variant]) -> Vec<Job> {
    std::iter::once(Job::default_run(config))
        .chain(variants.iter().map(|v| Job::variant(config, v)))
        .collect()
}

/// Sweeps `variants` of the matcher `config` over the records of `input`, scored with its
/// relations, with `jobs` runs at a time; `progress` hears of each run as it finishes (name,
/// result, time). Every run reads the log afresh, so memory holds `jobs` maps and no log.
pub fn sweep(
    input: &SweepInput,
    config: &MatcherConfig,
    variants: &[Variant],
    jobs: usize,
    mut progress: impl FnMut(&str, &Result<RunFigures, String>, Duration),
) -> Result<(RunFigures, Vec<VariantReport>)> {
    let jobs_list = plan(config, variants);
    let mut results = run_parallel(
        &jobs_list,
        jobs,
        |job| job.run(input),
        |i, result, elapsed| {
            if let Some(job) = jobs_list.get(i) {
                progress(&job.name, result, elapsed);
            }
        },
    )
    .into_iter();
    let default = match results.next() {
        Some(Ok(figures)) => figures,
        Some(Err(e)) => bail!("the default run failed: {e}"),
        None => bail!("the default run gave no result"),
    };
    let reports = jobs_list
        .iter()
        .skip(1)
        .zip(results)
        .map(|(job, result)| variant_report(&job.name, result, &default))
        .collect();
    Ok((default, reports))
}

fn fmt_f(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        "-".to_string()
    }
}

/// The report as a table: the default, one line per variant, the summary.
#[must_use]
pub fn table(report: &SweepReport) -> String {
    use std::fmt::Write;
    let width = report
        .variants
        .iter()
        .map(|v| v.name.len())
        .chain(std::iter::once("default".len()))
        .max()
        .unwrap_or(7);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{} on {} ({} scans, {} relations in file)",
        report.matcher, report.log, report.scans, report.relations_total
    );
    let _ = writeln!(
        out,
        "{:width$}  {:>10}  {:>9}  {:>8}  {:>6}  {:>6}  {:>6}  {:>10}  {:>7}",
        "variant",
        "trans_mean",
        "trans_max",
        "rot_mean",
        "ratio",
        "n",
        ">0.5m",
        "map_points",
        "ms/scan"
    );
    let line = |name: &str, f: &RunFigures, ratio: Option<f64>| {
        format!(
            "{name:width$}  {:>10}  {:>9}  {:>8}  {:>6}  {:>6}  {:>6}  {:>10}  {:>7}",
            fmt_f(f.trans_mean, 4),
            fmt_f(f.trans_max, 3),
            fmt_f(f.rot_mean_deg, 3),
            ratio.map_or_else(|| "-".to_string(), |r| fmt_f(r, 2)),
            f.relations,
            f.relations_over_0_5_m,
            f.map_points,
            fmt_f(f.ms_per_scan_median, 2),
        )
    };
    let _ = writeln!(out, "{}", line("default", &report.default, Some(1.0)));
    for v in &report.variants {
        match (&v.figures, &v.error) {
            (Some(f), _) => {
                let _ = writeln!(out, "{}", line(&v.name, f, v.ratio));
            }
            (None, e) => {
                let _ = writeln!(
                    out,
                    "{:width$}  error: {}",
                    v.name,
                    e.as_deref().unwrap_or("no result")
                );
            }
        }
    }
    let _ = writeln!(
        out,
        "worst ratio {} ({}), median ratio {}; default: {} of {} relations above {FAILURE_M} m",
        report
            .worst_ratio
            .map_or_else(|| "-".to_string(), |r| fmt_f(r, 2)),
        report.worst_variant.as_deref().unwrap_or("-"),
        report
            .median_ratio
            .map_or_else(|| "-".to_string(), |r| fmt_f(r, 2)),
        report.relations_over_0_5_m,
        report.default.relations
    );
    out
}

/// A sweep's inputs, checked: the log, read afresh by every run (so that memory holds no
/// log), and the relations every run is scored with.
#[derive(Debug)]
pub struct SweepInput {
    /// The log, as named in reports.
    pub log: String,
    path: PathBuf,
    options: LogOptions,
    /// Records of the log the runs use.
    pub scans: usize,
    /// The relations every run is scored with.
    pub relations: Vec<Relation>,
}

impl SweepInput {
    /// Reads the relations, then streams the log once (its first `scans` records): a CARMEN
    /// log (`lenient` skips malformed lines) or a ROS 2 bag with scans on `/scan` and odometry
    /// on `/odom`. That pass counts the records and checks that some relation falls within
    /// them, so that an unreadable log or the relations file of another log fails before any
    /// matching.
    pub fn load(
        log: &Path,
        relations: &Path,
        scans: Option<NonZeroUsize>,
        lenient: bool,
    ) -> Result<Self> {
        let relations_name = relations.display().to_string();
        let relations = read_relations(relations)
            .with_context(|| format!("reading relations {relations_name}"))?;
        if relations.is_empty() {
            bail!("{relations_name} holds no relations");
        }
        let options = LogOptions {
            carmen: CarmenOptions {
                lenient,
                ..CarmenOptions::default()
            },
            ..LogOptions::default()
        };
        let mut probe = RelationProbe::new(&relations, MAX_DT)?;
        let mut reader = LogReader::open(log, &options)?;
        let mut count = 0;
        let mut span = (f64::NAN, f64::NAN);
        for record in reader
            .by_ref()
            .take(scans.map_or(usize::MAX, NonZeroUsize::get))
        {
            let record = record.with_context(|| format!("reading {}", log.display()))?;
            probe.push(record.timestamp(), record.odometry)?;
            if count == 0 {
                span.0 = record.timestamp();
            }
            span.1 = record.timestamp();
            count += 1;
        }
        reader.warn(log);
        if count == 0 {
            return Err(reader.empty(log).into());
        }
        let (found, _) = relation_errors(&probe.trajectory(), &relations, MAX_DT)?;
        if found.is_empty() {
            bail!(
                "none of the {} relations of {relations_name} falls within the {count} scans \
                 used ({} to {} s): do they belong to this log?",
                relations.len(),
                span.0,
                span.1
            );
        }
        Ok(Self {
            log: log.display().to_string(),
            path: log.to_path_buf(),
            options,
            scans: count,
            relations,
        })
    }

    /// The records the runs use, read afresh from the log, one at a time.
    pub fn records(&self) -> Result<impl Iterator<Item = Result<Record>> + use<>> {
        let reader = LogReader::open(&self.path, &self.options)
            .with_context(|| format!("reading {}", self.path.display()))?;
        Ok(reader
            .take(self.scans)
            .map(|r| r.map_err(anyhow::Error::from)))
    }
}

/// The report of a sweep of `config` on `input`: the default run, the variants, the worst and
/// the median ratio.
#[must_use]
pub fn report(
    input: &SweepInput,
    config: &MatcherConfig,
    default: RunFigures,
    variants: Vec<VariantReport>,
) -> SweepReport {
    let ratios: Vec<(f64, &str)> = variants
        .iter()
        .filter_map(|v| v.ratio.map(|r| (r, v.name.as_str())))
        .filter(|(r, _)| !r.is_nan())
        .collect();
    let worst = ratios.iter().copied().max_by(|a, b| a.0.total_cmp(&b.0));
    let median_ratio = median(&ratios.iter().map(|r| r.0).collect::<Vec<_>>());
    let worst_ratio = worst.map(|w| w.0);
    let worst_variant = worst.map(|w| w.1.to_string());
    SweepReport {
        log: input.log.clone(),
        matcher: config.kind(),
        scans: input.scans,
        relations_total: input.relations.len(),
        relations_over_0_5_m: default.relations_over_0_5_m,
        default,
        worst_ratio,
        worst_variant,
        median_ratio,
        variants,
    }
}

/// The ratio of a variant's figures to the default's, as reports give it.
#[must_use]
pub fn variant_report(
    name: &str,
    result: Result<RunFigures, String>,
    default: &RunFigures,
) -> VariantReport {
    let (figures, error) = match result {
        Ok(f) => (Some(f), None),
        Err(e) => (None, Some(e)),
    };
    VariantReport {
        name: name.to_string(),
        ratio: figures.as_ref().map(|f| f.trans_mean / default.trans_mean),
        figures,
        error,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(ranges: Vec<f64>) -> Scan {
        let geometry = BeamGeometry {
            angle_min: -1.0,
            angle_increment: 0.1,
            max_range: 20.0,
            min_range: 0.1,
        };
        Scan::new(3.0, geometry, ranges).expect("valid scan")
    }

    fn records(odometry: &[Pose2]) -> Vec<Record> {
        odometry
            .iter()
            .enumerate()
            .map(|(i, &odometry)| Record {
                scan: Scan::new(i as f64, BeamGeometry::centered(5, 1.0, 20.0), vec![1.0; 5])
                    .expect("valid scan"),
                odometry,
                truth: None,
                laser_offset: Pose2::IDENTITY,
            })
            .collect()
    }

    /// A straight drive along x from the origin in `steps` equal steps.
    fn straight(length: f64, steps: usize) -> Vec<Pose2> {
        (0..=steps)
            .map(|i| Pose2::new(length * i as f64 / steps as f64, 0.0, 0.0))
            .collect()
    }

    /// A seeded random drive: wandering odometry, ranges with no-returns and invalid readings.
    fn random_records(n: usize, seed: u64) -> Vec<Record> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut odometry = Pose2::new(1.0, -2.0, 0.3);
        (0..n)
            .map(|i| {
                let step = Pose2::new(
                    rng.random_range(0.0..0.3),
                    rng.random_range(-0.05..0.05),
                    rng.random_range(-0.2..0.2),
                );
                odometry = odometry.compose(&step);
                let ranges = (0..37)
                    .map(|_| match rng.random_range(0..10) {
                        0 => -1.0,
                        1 => 30.0,
                        _ => rng.random_range(0.2..18.0),
                    })
                    .collect();
                Record {
                    scan: Scan::new(
                        0.1 * i as f64,
                        BeamGeometry::centered(37, 3.0, 20.0),
                        ranges,
                    )
                    .expect("valid scan"),
                    odometry,
                    truth: None,
                    laser_offset: Pose2::IDENTITY,
                }
            })
            .collect()
    }

    #[test]
    fn a_streamed_input_variant_gives_the_records_of_the_whole_log_form() {
        for seed in 0..3 {
            let records = random_records(41, seed);
            for variant in InputVariant::ALL {
                let whole = variant.apply(&records).expect("applies");
                let streamed: Vec<Record> = variant
                    .stream(records.iter().cloned().map(Ok))
                    .collect::<Result<_>>()
                    .expect("streams");
                assert_eq!(streamed, whole, "{} (seed {seed})", variant.name());
                assert_ne!(streamed, records, "{} changed nothing", variant.name());
            }
        }
    }

    #[test]
    fn a_streamed_input_variant_passes_errors_on_and_keeps_going() {
        let records = random_records(6, 1);
        let input = records.iter().enumerate().map(|(i, r)| {
            if i == 2 {
                Err(anyhow::anyhow!("bad line"))
            } else {
                Ok(r.clone())
            }
        });
        let out: Vec<Result<Record>> = InputVariant::EveryOtherRecord.stream(input).collect();
        // Records 0, 1, 3, 4, 5 count; 0, 3 and 5 are kept, and the error is not lost.
        assert_eq!(out.len(), 4);
        assert!(out[1].as_ref().is_err_and(|e| e.to_string() == "bad line"));
        let kept: Vec<f64> = out.iter().flatten().map(Record::timestamp).collect();
        assert_eq!(kept, [0.0, 0.1 * 3.0, 0.1 * 5.0]);
    }

    #[test]
    fn every_other_beam_halves_the_beams_and_keeps_their_bearings() {
        let s = scan((0..11).map(|i| 1.0 + f64::from(i)).collect());
        let half = every_other_beam(&s).expect("valid");
        assert_eq!(half.beams(), 6);
        for (k, i) in (0..11).step_by(2).enumerate() {
            assert!((half.geometry.angle(k) - s.geometry.angle(i)).abs() < 1e-12);
            assert_eq!(half.ranges()[k], s.ranges()[i]);
        }
    }

    #[test]
    fn every_other_record_keeps_the_even_ones() {
        let r = records(&straight(1.0, 4));
        let kept: Vec<f64> = every_other_record(&r)
            .iter()
            .map(Record::timestamp)
            .collect();
        assert_eq!(kept, [0.0, 2.0, 4.0]);
    }

    #[test]
    fn odometry_bias_on_a_straight_metre() {
        // One increment of 1 m: exactly 1.05 m and 1°.
        let one = biased_increment(Pose2::new(1.0, 0.0, 0.0));
        assert!((one.x - 1.05).abs() < 1e-12 && one.y.abs() < 1e-12);
        assert!((one.theta.to_degrees() - 1.0).abs() < 1e-12);
        // A hundred 1 cm steps: 1.05 m travelled on a gentle arc, 1° turned in all.
        let poses = perturb_increments(&straight(1.0, 100), biased_increment);
        let end = poses.last().copied().unwrap_or_default();
        assert!((end.x.hypot(end.y) - 1.05).abs() < 1e-4, "{end:?}");
        assert!((end.theta.to_degrees() - 1.0).abs() < 1e-9, "{end:?}");
        assert_eq!(poses.first().copied(), Some(Pose2::IDENTITY));
    }

    #[test]
    fn perturbed_odometry_starts_at_the_first_pose_and_keeps_it_unperturbed() {
        let start = Pose2::new(3.0, -2.0, 0.5);
        let path: Vec<Pose2> = straight(2.0, 10).iter().map(|p| start.compose(p)).collect();
        let same = perturb_increments(&path, |d| d);
        for (a, b) in path.iter().zip(&same) {
            assert!(a.distance(b) < 1e-9 && (a.theta - b.theta).abs() < 1e-9);
        }
        let biased = perturb_increments(&path, biased_increment);
        assert_eq!(biased.first(), path.first());
        let end = biased.last().copied().unwrap_or_default();
        assert!((start.distance(&end) - 2.1).abs() < 1e-3, "{end:?}");
    }

    #[test]
    fn odometry_noise_is_deterministic_for_a_seed_and_drifts() {
        let r = records(&straight(5.0, 50));
        let a = InputVariant::OdometryNoise.apply(&r).expect("applies");
        let b = InputVariant::OdometryNoise.apply(&r).expect("applies");
        assert_eq!(a, b);
        let mut rng = ChaCha8Rng::seed_from_u64(SEED + 1);
        let poses: Vec<Pose2> = r.iter().map(|r| r.odometry).collect();
        let c = perturb_increments(&poses, |d| noisy_increment(d, &mut rng));
        assert_ne!(a.last().map(|r| r.odometry), c.last().copied());
        let drift = a
            .last()
            .zip(r.last())
            .map(|(a, r)| a.odometry.distance(&r.odometry))
            .unwrap_or_default();
        assert!(drift > 1e-4 && drift < 1.5, "drift {drift}");
        // A robot standing still gets no noise.
        let still = perturb_increments(&[Pose2::IDENTITY; 5], |d| noisy_increment(d, &mut rng));
        assert!(still.iter().all(|p| *p == Pose2::IDENTITY));
    }

    #[test]
    fn range_noise_leaves_invalid_readings_alone() {
        let s = scan(vec![1.0, f64::NAN, 25.0, 0.05, 2.0, -1.0, 3.0]);
        let mut rng = ChaCha8Rng::seed_from_u64(SEED);
        let noisy = noisy_ranges(&s, 0.01, &mut rng).expect("valid");
        for (i, (&before, &after)) in s.ranges().iter().zip(noisy.ranges()).enumerate() {
            if s.status()[i] == BeamStatus::Valid {
                assert_ne!(before, after);
                assert!((before - after).abs() < 0.06);
            } else {
                assert!(before.to_bits() == after.to_bits(), "beam {i} changed");
            }
        }
    }

    #[test]
    fn capped_range_turns_far_returns_into_no_returns() {
        let s = scan(vec![1.0, 9.9, 10.0, 15.0]);
        let capped = capped_range(&s, 10.0).expect("valid");
        assert_eq!(capped.valid_count(), 2);
        assert_eq!(capped.status()[3], BeamStatus::MaxRange);
        assert_eq!(capped.ranges(), s.ranges());
        // A laser that sees less than 10 m keeps its own range.
        let near = capped_range(&capped_range(&s, 5.0).expect("valid"), 10.0).expect("valid");
        assert!((near.geometry.max_range - 5.0).abs() < 1e-12);
    }

    #[test]
    fn variants_follow_the_steering_parameters() {
        let config = MatcherConfig::defaults(qicp_matchers::MatcherKind::QWsm);
        let all = all_variants(&config);
        let parameters = config.steering_parameters();
        assert_eq!(all.len(), InputVariant::ALL.len() + 2 * parameters.len());
        assert!(all.iter().any(|v| v.name == "icp.max_dist_start*0.7"));
        assert!(all.iter().any(|v| v.name == "icp.max_dist_start*1.4"));
        let names = [
            "odom-bias".to_string(),
            "scans/2".to_string(),
            "default".to_string(),
        ];
        let picked = select_variants(all.clone(), &names).expect("known");
        let picked: Vec<&str> = picked.iter().map(|v| v.name.as_str()).collect();
        assert_eq!(picked, ["scans/2", "odom-bias"]);
        let err = select_variants(all, &["nope".to_string()]).expect_err("unknown");
        let msg = err.to_string();
        assert!(msg.contains("nope") && msg.contains("beams/2"), "{msg}");
    }

    #[test]
    fn parallel_results_are_in_item_order_and_panics_are_errors() {
        let items: Vec<u32> = (0..20).collect();
        for jobs in [1, 3, 64] {
            let mut seen = 0;
            let out = run_parallel(
                &items,
                jobs,
                |&i| {
                    if i == 7 {
                        panic!("seven");
                    }
                    Ok(i * 2)
                },
                |_, _, _| seen += 1,
            );
            assert_eq!(seen, 20);
            for (i, r) in out.iter().enumerate() {
                match r {
                    Ok(v) => assert_eq!(*v as usize, i * 2),
                    Err(e) => assert!(i == 7 && e.contains("seven"), "{e}"),
                }
            }
        }
    }
}
