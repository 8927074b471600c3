//! The records of a run, and how every matcher on them is scored.

use super::*;

/// The records of an experiment, with whatever scores them.
#[derive(Debug)]
pub struct Source {
    /// What the records are (`sim:<path>`, `log:<path>` or `bag:<path>`).
    pub name: String,
    /// Laser records in time order: held, or read afresh from the log for each pass.
    pub records: Records,
    /// True robot poses, where known.
    pub truth: Option<Vec<Stamped>>,
    /// Freiburg relations, where given.
    pub relations: Option<Vec<Relation>>,
}

/// Where an experiment's records come from.
#[derive(Debug)]
pub enum Records {
    /// A simulated drive, held whole (it is short, and holds its ground truth).
    Held(Vec<Record>),
    /// A log (CARMEN, plain or bz2, or a ROS 2 bag), streamed from the file for every pass so
    /// that memory does not grow with its length.
    Log {
        /// The log file.
        path: PathBuf,
        /// How to read it.
        options: Box<qicp_io::LogOptions>,
        /// Records the experiment uses (the first ones).
        scans: usize,
        /// The file's length and modification time when it was counted: every pass checks
        /// them, so that a log replaced or cut during a run is an error, not a run over two
        /// different logs.
        identity: FileIdentity,
    },
}

/// What identifies a log file between passes: its length and modification time.
pub type FileIdentity = (u64, Option<std::time::SystemTime>);

/// The [`FileIdentity`] of `path`, or `None` when it is not a regular file (a pipe, a
/// device), which can be read only once.
fn file_identity(path: &Path) -> Result<Option<FileIdentity>> {
    let m = std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(m.is_file().then(|| (m.len(), m.modified().ok())))
}

impl Source {
    /// Simulates the drive, or reads the log once: to count the records the run uses (the first
    /// `max_scans`), check that it has some, and take the true poses a log may carry. A log's
    /// records are not kept; every matcher reads them afresh ([`Source::each_record`]).
    pub fn load(c: &SourceConfig) -> Result<Self> {
        let (name, records, truth) = if let Some(sim) = &c.sim {
            let cfg = c.drive(sim)?;
            let (mut records, _, _) = qicp_sim::Simulation::run(cfg)
                .with_context(|| format!("simulating {}", sim.display()))?;
            if let Some(n) = c.max_scans {
                records.truncate(n);
            }
            let name = format!("sim:{}", sim.display());
            if records.is_empty() {
                anyhow::bail!("{name}: no laser records");
            }
            let truth = records.iter().all(|r| r.truth.is_some()).then(|| {
                records
                    .iter()
                    .filter_map(|r| r.truth.map(|t| (r.timestamp(), t)))
                    .collect()
            });
            (name, Records::Held(records), truth)
        } else if let Some(log) = &c.log {
            let prefix = if qicp_io::rosbag::is_mcap(log) {
                "bag"
            } else {
                "log"
            };
            let name = format!("{prefix}:{}", log.display());
            let options = c.log_options();
            // A pipe or a device can be read only once: its records are held, as a
            // simulated drive's are.
            let identity = file_identity(log)?;
            let mut held = Vec::new();
            let mut reader = qicp_io::LogReader::open(log, &options)
                .with_context(|| format!("reading {}", log.display()))?;
            // The true poses the records carry: kept only while every record has one.
            let mut carried: Option<Vec<Stamped>> = Some(Vec::new());
            let mut scans = 0;
            for record in reader.by_ref().take(c.max_scans.unwrap_or(usize::MAX)) {
                let record = record.with_context(|| format!("reading {}", log.display()))?;
                carried = carried.and_then(|mut t| {
                    let pose = record.truth?;
                    t.push((record.timestamp(), pose));
                    Some(t)
                });
                scans += 1;
                if identity.is_none() {
                    held.push(record);
                }
            }
            reader.warn(log);
            if scans == 0 {
                anyhow::bail!("{name}: no laser records");
            }
            let truth = match c.truth()? {
                Some(t) => Some(t),
                None => carried,
            };
            let records = match identity {
                Some(identity) => Records::Log {
                    path: log.clone(),
                    options: Box::new(options),
                    scans,
                    identity,
                },
                None => Records::Held(held),
            };
            (name, records, truth)
        } else {
            anyhow::bail!("`source`: give `sim` or `log`");
        };
        let relations = match &c.relations {
            Some(p) => Some(read_relations(p).with_context(|| format!("reading {}", p.display()))?),
            None => None,
        };
        Ok(Self {
            name,
            records,
            truth,
            relations,
        })
    }

    /// Records the experiment uses.
    #[must_use]
    pub fn scans(&self) -> usize {
        match &self.records {
            Records::Held(r) => r.len(),
            Records::Log { scans, .. } => *scans,
        }
    }

    /// Calls `f` on every record in time order: the held ones, or the log's read afresh one
    /// at a time. Stops at the first error (of the log or of `f`).
    pub fn each_record(&self, mut f: impl FnMut(&Record) -> Result<()>) -> Result<()> {
        match &self.records {
            Records::Held(records) => records.iter().try_for_each(f),
            Records::Log {
                path,
                options,
                scans,
                identity,
            } => {
                let changed = || {
                    anyhow::anyhow!(
                        "{} changed during the run (it held {scans} records when counted); \
                         every matcher reads the log afresh, so it must stay as it is",
                        path.display()
                    )
                };
                if file_identity(path)?.as_ref() != Some(identity) {
                    return Err(changed());
                }
                let reader = qicp_io::LogReader::open(path, options)
                    .with_context(|| format!("reading {}", path.display()))?;
                let mut read = 0;
                for record in reader.take(*scans) {
                    let record = record.with_context(|| format!("reading {}", path.display()))?;
                    f(&record)?;
                    read += 1;
                }
                if read != *scans || file_identity(path)?.as_ref() != Some(identity) {
                    return Err(changed());
                }
                Ok(())
            }
        }
    }

    /// Raw odometry at the laser times of held records (none for a log: see
    /// `stream::odometry_pass`).
    #[must_use]
    pub fn odometry(&self) -> Option<Vec<Stamped>> {
        match &self.records {
            Records::Held(records) => Some(
                records
                    .iter()
                    .map(|r| (r.timestamp(), r.odometry))
                    .collect(),
            ),
            Records::Log { .. } => None,
        }
    }
}

// Scoring

/// What one trajectory scores.
#[derive(Debug, Clone)]
pub struct Scores {
    /// Against ground truth, where known.
    pub ate: Option<AteReport>,
    /// Against Freiburg relations, where given.
    pub relations: Option<RelationsReport>,
}

impl Scores {
    /// Scores `traj` with whatever the source has.
    pub fn of(traj: &[Stamped], source: &Source) -> Result<Self> {
        Self::of_parts(Some(traj), Some(traj), source)
    }

    /// Scores a trajectory from its parts: `whole` against the truth (required when the source
    /// has truth) and `near_relations` (at least the poses nearest the relations' times, as
    /// a [`RelationProbe`](qicp_eval::RelationProbe) picks them) against the relations
    /// (required when it has relations).
    pub fn of_parts(
        whole: Option<&[Stamped]>,
        near_relations: Option<&[Stamped]>,
        source: &Source,
    ) -> Result<Self> {
        let ate = match &source.truth {
            Some(truth) => {
                let traj = whole.context("the whole trajectory is needed for ATE")?;
                let opts = AteOptions::default();
                let report = evaluate_ate(traj, truth, &opts)?;
                if 2 * report.n < traj.len() {
                    // A ground truth of a few poses scores a few poses: 0 m from one pair.
                    qicp_core::note!(
                        "warning: only {} of the trajectory's {} poses have a ground-truth pose \
                         within {} s: the ATE covers those alone",
                        report.n,
                        traj.len(),
                        opts.max_dt
                    );
                }
                Some(report)
            }
            None => None,
        };
        let relations = match &source.relations {
            Some(rel) => {
                let traj = near_relations.context("no poses for the relations")?;
                let r = evaluate_relations(traj, rel, qicp_eval::DEFAULT_MAX_DT)?;
                if r.n == 0 {
                    // Odometry is scored first, so this stops a run before its matchers.
                    anyhow::bail!(
                        "none of the {} relations has poses within {} s of this log's \
                         records: are they the log's?",
                        rel.len(),
                        qicp_eval::DEFAULT_MAX_DT
                    );
                }
                Some(r)
            }
            None => None,
        };
        Ok(Self { ate, relations })
    }

    /// The figures `summary.json` gives of these scores.
    #[must_use]
    pub fn figures(&self) -> Scored {
        Scored {
            truth: self.ate.as_ref().map(TruthFigures::from),
            relations: self.relations,
        }
    }
}

/// One matcher's results.
#[derive(Debug)]
pub struct MatcherOutcome {
    /// The effective configuration.
    pub config: MatcherConfig,
    /// Robot pose per record, held when the records are (a simulated drive) or when there is
    /// truth to score it against (the truth is held all the same); otherwise the poses are in
    /// `trajectory.tum` only.
    pub trajectory: Option<Vec<Stamped>>,
    /// Where the trajectory was written.
    pub trajectory_file: PathBuf,
    /// Per-scan values the ratios and the per-scan figures need.
    pub per_scan: PerScan,
    /// Totals.
    pub summary: MatchSummary,
    /// Scores.
    pub scores: Scores,
    /// Wall time of the whole run (s), matching and bookkeeping.
    pub seconds: f64,
    /// Bounds of the matcher's map picture, gathered while matching (log sources, when
    /// pictures are drawn).
    pub extent: Option<plots::MapExtent>,
}

/// The three per-scan values an experiment keeps of every matcher, in full precision
/// (`matches.csv` rounds them): 24 bytes per scan, for the boosted / incremental ratios
/// (taken over the scans both matched; the per-scan median needs every scan's) and the
/// paper's Fig. 4 panels.
#[derive(Debug, Clone, Default)]
pub struct PerScan {
    /// Residual correlation distance (mm); NaN for a fallback.
    pub residual_mm: Vec<f64>,
    /// Matching certainty (m²); NaN for a fallback.
    pub certainty: Vec<f64>,
    /// Position standard deviation (mm); NaN for a fallback.
    pub sigma_mm: Vec<f64>,
}

impl PerScan {
    /// Adds one scan's row.
    pub fn push(&mut self, row: &ScanRow) {
        self.residual_mm.push(row.residual_mm);
        self.certainty.push(row.certainty);
        self.sigma_mm.push(row.sigma_mm);
    }

    /// Scans held.
    #[must_use]
    pub fn len(&self) -> usize {
        self.certainty.len()
    }

    /// Whether no scan is held.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.certainty.is_empty()
    }
}

impl MatcherOutcome {
    pub(super) fn kind(&self) -> String {
        self.config.kind()
    }

    /// The figures `summary.json` gives of this matcher.
    #[must_use]
    pub fn figures(&self) -> MatcherFigures {
        MatcherFigures::new(self.scores.figures(), &self.summary)
    }
}

/// The kind of the scan-to-scan twin of a boosted matcher (same algorithm), if it is one.
#[must_use]
pub fn incremental_of(config: &MatcherConfig) -> Option<String> {
    config
        .reference
        .is_map()
        .then(|| config.algorithm().to_string())
}

/// The mean of `boosted` over the mean of `incremental`, both over the scans where both are
/// finite: where one matcher fell back and the other matched, neither's value counts, so the
/// ratio compares the two on the same scans. NaN when they share none.
fn ratio_of_means(boosted: &[f64], incremental: &[f64]) -> f64 {
    let (mut sb, mut si, mut n) = (0.0, 0.0, 0usize);
    for (b, i) in boosted.iter().zip(incremental) {
        if b.is_finite() && i.is_finite() {
            sb += b;
            si += i;
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { sb / si }
}

/// Boosted / incremental ratios of every boosted kind whose twin also ran, by
/// `"<boosted>/<incremental>"`.
pub(super) fn ratios(outcomes: &[MatcherOutcome]) -> BTreeMap<String, Ratios> {
    let mut out = BTreeMap::new();
    for b in outcomes {
        let Some(inc) = incremental_of(&b.config) else {
            continue;
        };
        let Some(i) = outcomes.iter().find(|o| o.kind() == inc) else {
            continue;
        };
        let truth = b.scores.ate.as_ref().zip(i.scores.ate.as_ref());
        let relations = b.scores.relations.as_ref().zip(i.scores.relations.as_ref());
        // Per scan (paper Fig. 4c-d): the mean is at the mercy of a few near-degenerate
        // incremental matches, the median is not.
        let per_scan: Vec<f64> = b
            .per_scan
            .certainty
            .iter()
            .zip(&i.per_scan.certainty)
            .map(|(cb, ci)| cb / ci)
            .filter(|r| r.is_finite())
            .collect();
        let (pb, pi) = (&b.per_scan, &i.per_scan);
        let r = Ratios {
            ate: truth.map(|(ab, ai)| ab.ate_rmse_m / ai.ate_rmse_m),
            final_error: truth.map(|(ab, ai)| ab.final_error_m / ai.final_error_m),
            relations_trans: relations.map(|(rb, ri)| rb.trans_mean / ri.trans_mean),
            residual: ratio_of_means(&pb.residual_mm, &pi.residual_mm),
            certainty: ratio_of_means(&pb.certainty, &pi.certainty),
            sigma: ratio_of_means(&pb.sigma_mm, &pi.sigma_mm),
            scans_both_matched: pb
                .certainty
                .iter()
                .zip(&pi.certainty)
                .filter(|(cb, ci)| cb.is_finite() && ci.is_finite())
                .count(),
            certainty_per_scan_mean: per_scan.iter().sum::<f64>() / per_scan.len() as f64,
            // The mean of the middle two for an even count, as every other median reported.
            certainty_per_scan_median: qicp_eval::stats::median(&per_scan).unwrap_or(f64::NAN),
        };
        out.insert(format!("{}/{}", b.kind(), inc), r);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CARMEN log of `n` scans of a robot creeping along a wall.
    fn log(n: usize) -> String {
        (0..n)
            .map(|i| {
                let ranges = vec!["2.0"; 181].join(" ");
                let (x, t) = (i as f64 * 0.01, i as f64 * 0.1);
                format!("FLASER 181 {ranges} {x} 0 0 {x} 0 0 {t} host {t}\n")
            })
            .collect()
    }

    #[test]
    fn a_log_that_changes_between_passes_is_an_error_not_a_second_log() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("drive.clf");
        std::fs::write(&path, log(20)).expect("written");
        let source = Source::load(&SourceConfig {
            log: Some(path.clone()),
            ..SourceConfig::default()
        })
        .expect("loads");
        assert_eq!(source.scans(), 20);
        let count = |s: &Source| {
            let mut n = 0;
            s.each_record(|_| {
                n += 1;
                Ok(())
            })
            .map(|()| n)
        };
        assert_eq!(count(&source).expect("the same log"), 20);
        // Cut short (a truncated copy, a log rewritten by its recorder).
        std::fs::write(&path, log(12)).expect("rewritten");
        let err = count(&source).expect_err("changed").to_string();
        assert!(err.contains("changed during the run"), "{err}");
        // One sentence, not a source line's indentation in the middle of it.
        assert!(!err.contains("  "), "{err}");
    }

    #[test]
    fn a_ratio_of_means_compares_the_two_matchers_on_the_scans_both_matched() {
        // Scan 1: the boosted matcher fell back; scan 2: the incremental one. Over each
        // matcher's own scans the ratio would read (1 + 9 + 5) / 3 over (2 + 4 + 6) / 3 = 1.25.
        let boosted = [1.0, f64::NAN, 9.0, 5.0];
        let incremental = [2.0, 4.0, f64::NAN, 6.0];
        assert!((ratio_of_means(&boosted, &incremental) - 6.0 / 8.0).abs() < 1e-12);
        assert!(ratio_of_means(&[f64::NAN, 1.0], &[1.0, f64::NAN]).is_nan());
        assert!(ratio_of_means(&[], &[]).is_nan());
    }
}
