//! The records of a run, and how every matcher on them is scored.

use super::*;

/// The records of an experiment, with whatever scores them.
#[derive(Debug)]
pub struct Source {
    /// What the records are (`sim:<path>` or `log:<path>`).
    pub name: String,
    /// Laser records in time order.
    pub records: Vec<Record>,
    /// True robot poses, where known.
    pub truth: Option<Vec<Stamped>>,
    /// Freiburg relations, where given.
    pub relations: Option<Vec<Relation>>,
}

impl Source {
    /// Simulates the drive or reads the log the config names.
    pub fn load(c: &SourceConfig) -> Result<Self> {
        let (name, mut records, mut truth) = if let Some(sim) = &c.sim {
            let cfg = c.drive(sim)?;
            let (records, _, _) = qicp_sim::Simulation::run(cfg)
                .with_context(|| format!("simulating {}", sim.display()))?;
            (format!("sim:{}", sim.display()), records, None)
        } else if let Some(log) = c.log.as_ref().filter(|l| crate::logs::rosbag::is_mcap(l)) {
            // A bag streams; only the scans the run uses are kept.
            let mut reader = crate::logs::LogReader::open(log, &c.log_options())?;
            let records = reader
                .by_ref()
                .take(c.max_scans.unwrap_or(usize::MAX))
                .collect::<Result<Vec<_>, _>>()
                .with_context(|| format!("reading {}", log.display()))?;
            reader.warn(log);
            (format!("bag:{}", log.display()), records, c.truth()?)
        } else if let Some(log) = &c.log {
            let opts = CarmenOptions {
                lenient: c.lenient,
                ..CarmenOptions::default()
            };
            let read =
                read_carmen(log, &opts).with_context(|| format!("reading {}", log.display()))?;
            if read.info.skipped_lines > 0 {
                eprintln!(
                    "warning: skipped {} malformed lines of {}",
                    read.info.skipped_lines,
                    log.display()
                );
            }
            (format!("log:{}", log.display()), read.records, c.truth()?)
        } else {
            anyhow::bail!("`source`: give `sim` or `log`");
        };
        if let Some(n) = c.max_scans {
            records.truncate(n);
        }
        if records.is_empty() {
            anyhow::bail!("{name}: no laser records");
        }
        if truth.is_none() && records.iter().all(|r| r.truth.is_some()) {
            truth = Some(
                records
                    .iter()
                    .filter_map(|r| r.truth.map(|t| (r.timestamp(), t)))
                    .collect(),
            );
        }
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

    /// Raw odometry at the laser times.
    #[must_use]
    pub fn odometry(&self) -> Vec<Stamped> {
        self.records
            .iter()
            .map(|r| (r.timestamp(), r.odometry))
            .collect()
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
        let ate = match &source.truth {
            Some(truth) => Some(evaluate_ate(traj, truth, &AteOptions::default())?),
            None => None,
        };
        let relations = match &source.relations {
            Some(rel) => {
                let r = evaluate_relations(traj, rel, crate::eval::DEFAULT_MAX_DT)?;
                if r.n == 0 {
                    eprintln!(
                        "warning: none of the {} relations falls on this log's times: \
                         are they the log's?",
                        rel.len()
                    );
                }
                Some(r)
            }
            None => None,
        };
        Ok(Self { ate, relations })
    }

    pub(super) fn insert_into(&self, m: &mut Map<String, Value>) -> Result<()> {
        if let Some(a) = &self.ate {
            m.insert("ate_rmse_m".into(), json!(a.ate_rmse_m));
            m.insert("rpe_trans_per_m".into(), json!(a.rpe_trans_per_m));
            m.insert("rpe_rot_deg_per_m".into(), json!(a.rpe_rot_deg_per_m));
            m.insert("final_error_m".into(), json!(a.final_error_m));
        }
        if let Some(r) = &self.relations {
            m.insert("relations".into(), serde_json::to_value(r)?);
        }
        Ok(())
    }
}

/// One matcher's results.
#[derive(Debug)]
pub struct MatcherOutcome {
    /// The effective configuration.
    pub config: MatcherConfig,
    /// Robot pose per record.
    pub trajectory: Vec<Stamped>,
    /// Per-scan figures.
    pub rows: Vec<ScanRow>,
    /// Totals.
    pub summary: MatchSummary,
    /// Scores.
    pub scores: Scores,
    /// Wall time of the whole run (s), matching and bookkeeping.
    pub seconds: f64,
}

impl MatcherOutcome {
    pub(super) fn kind(&self) -> String {
        self.config.kind()
    }

    pub(super) fn to_json(&self) -> Result<Value> {
        let s = &self.summary;
        let mut m = Map::new();
        self.scores.insert_into(&mut m)?;
        for (k, v) in [
            ("residual_mean_mm", json!(s.residual_mean_mm)),
            ("certainty_mean", json!(s.certainty_mean)),
            ("sigma_mean_mm", json!(s.sigma_mean_mm)),
            ("ms_per_scan_median", json!(s.ms_per_scan_median)),
            ("ms_per_scan_p99", json!(s.ms_per_scan_p99)),
            ("map_points", json!(s.map_points)),
            ("fallbacks", json!(s.fallbacks)),
            ("fallback_reasons", json!(s.fallback_reasons)),
            ("inserted", json!(s.inserted)),
            ("searched", json!(s.searched)),
            ("recovered", json!(s.recovered)),
            ("refused", json!(s.refused)),
            ("withheld", json!(s.withheld)),
            ("matching_seconds", json!(s.wall_seconds)),
        ] {
            m.insert(k.into(), v);
        }
        Ok(Value::Object(m))
    }
}

/// The kind of the scan-to-scan twin of a boosted matcher (same algorithm), if it is one.
#[must_use]
pub fn incremental_of(config: &MatcherConfig) -> Option<String> {
    (config.reference == ReferenceKind::Map).then(|| config.algorithm().to_string())
}

/// Boosted / incremental ratios of every boosted kind whose twin also ran:
/// `{"q-wsm/wsm": {"ate": …, "residual": …, "certainty": …, "sigma": …, "relations_trans": …}}`.
pub(super) fn ratios(outcomes: &[MatcherOutcome]) -> Value {
    let mut out = Map::new();
    for b in outcomes {
        let Some(inc) = incremental_of(&b.config) else {
            continue;
        };
        let Some(i) = outcomes.iter().find(|o| o.kind() == inc) else {
            continue;
        };
        let ratio = |x: f64, y: f64| json!(x / y);
        let mut m = Map::new();
        if let (Some(ab), Some(ai)) = (&b.scores.ate, &i.scores.ate) {
            m.insert("ate".into(), ratio(ab.ate_rmse_m, ai.ate_rmse_m));
            m.insert(
                "final_error".into(),
                ratio(ab.final_error_m, ai.final_error_m),
            );
        }
        if let (Some(rb), Some(ri)) = (&b.scores.relations, &i.scores.relations) {
            m.insert(
                "relations_trans".into(),
                ratio(rb.trans_mean, ri.trans_mean),
            );
        }
        m.insert(
            "residual".into(),
            ratio(b.summary.residual_mean_mm, i.summary.residual_mean_mm),
        );
        m.insert(
            "certainty".into(),
            ratio(b.summary.certainty_mean, i.summary.certainty_mean),
        );
        m.insert(
            "sigma".into(),
            ratio(b.summary.sigma_mean_mm, i.summary.sigma_mean_mm),
        );
        // Per scan (paper Fig. 4c-d): the mean is at the mercy of a few near-degenerate
        // incremental matches, the median is not.
        let per_scan: Vec<f64> = b
            .rows
            .iter()
            .zip(&i.rows)
            .map(|(rb, ri)| rb.certainty / ri.certainty)
            .filter(|r| r.is_finite())
            .collect();
        let mean = per_scan.iter().sum::<f64>() / per_scan.len() as f64;
        m.insert("certainty_per_scan_mean".into(), json!(mean));
        m.insert(
            "certainty_per_scan_median".into(),
            json!(crate::matching::quantile(&per_scan, 0.5)),
        );
        out.insert(format!("{}/{}", b.kind(), inc), Value::Object(m));
    }
    Value::Object(out)
}
