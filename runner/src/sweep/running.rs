//! Runs in parallel over the cores, one variant at a time per core.

use super::*;
use qicp_io::tum::Stamped;
use qicp_io::tum::write_tum_pose;

/// The figures of one run.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RunFigures {
    /// Mean translational relation error (m).
    pub trans_mean: f64,
    /// Largest translational relation error (m).
    pub trans_max: f64,
    /// Mean rotational relation error (degrees).
    pub rot_mean_deg: f64,
    /// Median wall time per scan (ms): the only figure that varies from run to run.
    pub ms_per_scan_median: f64,
    /// Live points in the reference at the end (as `qicp match` reports them).
    pub map_points: usize,
    /// Records matched.
    pub scans: usize,
    /// Relations evaluated.
    pub relations: usize,
    /// Relations without poses at their times (outside the scans, or dropped by `scans/2`).
    pub relations_missing: usize,
    /// Relations with a translational error above [`FAILURE_M`].
    pub relations_over_0_5_m: usize,
    /// Each relation's translational error (m), in the relations' order; `None` where the
    /// run has no pose at one of its times. Not in the JSON: it lets a variant that scored
    /// fewer relations than the default (`scans/2`) be compared with the default on the
    /// relations both scored ([`RunFigures::mean_on_relations_of`]). Empty when unknown.
    #[serde(skip)]
    pub relation_errors: Vec<Option<f64>>,
}

/// One run of a sweep: the default, or one variant.
#[derive(Debug, Clone)]
pub struct Job {
    /// `default` or the variant's name.
    pub name: String,
    input: Option<InputVariant>,
    /// The configuration, or why the variant has none.
    config: Result<MatcherConfig, String>,
}

impl Job {
    /// The run with the configuration as given.
    #[must_use]
    pub fn default_run(config: &MatcherConfig) -> Self {
        Self {
            name: "default".to_string(),
            input: None,
            config: Ok(config.clone()),
        }
    }

    /// The run of one variant of `config`.
    #[must_use]
    pub fn variant(config: &MatcherConfig, v: &Variant) -> Self {
        match &v.perturbation {
            Perturbation::Input(i) => Self {
                name: v.name.clone(),
                input: Some(*i),
                config: Ok(config.clone()),
            },
            Perturbation::Parameter { key, factor } => Self {
                name: v.name.clone(),
                input: None,
                config: config
                    .scaled(key, *factor)
                    .map(|mut c| {
                        c.fill_defaults();
                        c
                    })
                    .map_err(|e| format!("invalid configuration: {e}")),
            },
        }
    }

    /// The run named `name` (`default` or a variant of [`all_variants`]).
    pub fn named(config: &MatcherConfig, name: &str) -> Result<Self> {
        if name == "default" {
            return Ok(Self::default_run(config));
        }
        let v = select_variants(all_variants(config), &[name.to_string()])?;
        match v.first() {
            Some(v) => Ok(Self::variant(config, v)),
            None => bail!("unknown variant {name}"),
        }
    }

    /// Matches the (perturbed) records of `input`, read afresh from its log, and scores the
    /// trajectory with its relations.
    /// With [`SweepInput::with_trajectories`] the run also writes its trajectory.
    pub fn run(&self, input: &SweepInput) -> Result<RunFigures> {
        self.run_keeping(input, None)
    }

    /// [`Job::run`], also keeping every pose in `trajectory` (in the order matched), as a
    /// sweep against the default run needs of its default.
    pub fn run_tracking(
        &self,
        input: &SweepInput,
        trajectory: &mut Vec<Stamped>,
    ) -> Result<RunFigures> {
        self.run_keeping(input, Some(trajectory))
    }

    fn run_keeping(
        &self,
        input: &SweepInput,
        keep: Option<&mut Vec<Stamped>>,
    ) -> Result<RunFigures> {
        let Some(path) = input.trajectory_path(&self.name) else {
            return self.run_writing(input.records()?, &input.relations, None, keep);
        };
        // Readable like every other output (0644), and on disk before it takes its name.
        let mut out = crate::output::OutputFile::create(&path)?;
        let figures = self.run_writing(input.records()?, &input.relations, Some(&mut out), keep)?;
        out.commit()?;
        Ok(figures)
    }

    /// Matches `records` (in time order, perturbed as the job says, one at a time) and scores
    /// the trajectory with `relations`, whose times must be the records' own (as
    /// [`SweepInput`] holds them; `RelationProbe::snap` makes them so): a relation is scored
    /// only within [`SNAPPED_MAX_DT`] of them. Memory holds the matcher's map and the poses at the
    /// relations' times, not the records or the trajectory.
    pub fn run_on(
        &self,
        records: impl Iterator<Item = Result<Record>>,
        relations: &[Relation],
    ) -> Result<RunFigures> {
        self.run_writing(records, relations, None, None)
    }

    /// [`Job::run_on`], writing the trajectory to `trajectory` (TUM lines) when the run ends,
    /// with any amendments of a spread re-anchoring, and keeping it in `keep`, as asked.
    pub fn run_writing(
        &self,
        records: impl Iterator<Item = Result<Record>>,
        relations: &[Relation],
        mut trajectory: Option<&mut dyn std::io::Write>,
        keep: Option<&mut Vec<Stamped>>,
    ) -> Result<RunFigures> {
        let config = match &self.config {
            Ok(c) => c,
            Err(e) => bail!("{e}"),
        };
        let records: Box<dyn Iterator<Item = Result<Record>>> = match self.input {
            None => Box::new(records),
            Some(v) => Box::new(v.stream(records)),
        };
        let mut matcher = MatchLoop::new(config)?;
        let mut probe = RelationProbe::new(relations, SNAPPED_MAX_DT)?;
        // A trajectory to write is kept whole: a re-anchoring may amend any of it.
        let mut kept = Vec::new();
        let mut keep = keep.or(trajectory.is_some().then_some(&mut kept));
        for record in records {
            let record = record?;
            let (estimate, _) = matcher.push(&record);
            if let Some(amendment) = matcher.take_amendment() {
                probe.amend(|k| amendment.moved(k));
                if let Some(k) = keep.as_mut() {
                    amendment.apply(k, |(_, pose)| pose);
                }
            }
            probe.push(record.timestamp(), estimate.pose)?;
            if let Some(k) = keep.as_mut() {
                k.push((record.timestamp(), estimate.pose));
            }
        }
        if let (Some(w), Some(k)) = (trajectory.as_mut(), keep.as_ref()) {
            for (t, pose) in k.iter() {
                write_tum_pose(&mut *w, *t, pose).context("writing the trajectory")?;
            }
        }
        let summary = matcher.summary();
        let mut figures = RunFigures {
            trans_mean: f64::NAN,
            trans_max: f64::NAN,
            rot_mean_deg: f64::NAN,
            ms_per_scan_median: summary.ms_per_scan_median,
            map_points: summary.map_points,
            scans: summary.scans,
            relations: 0,
            relations_missing: 0,
            relations_over_0_5_m: 0,
            relation_errors: Vec::new(),
        };
        figures.score(&probe.trajectory(), relations)?;
        Ok(figures)
    }
}

impl RunFigures {
    /// Scores `trajectory` (the poses at the relations' times, or more) with `relations`,
    /// whose times must be the records' own (see [`Job::run_on`]): sets the error figures and
    /// the relation counts.
    pub fn score(&mut self, trajectory: &[Stamped], relations: &[Relation]) -> Result<()> {
        let report = evaluate_relations(trajectory, relations, SNAPPED_MAX_DT)?;
        let (errors, _) = relation_errors(trajectory, relations, SNAPPED_MAX_DT)?;
        self.trans_mean = report.trans_mean;
        self.trans_max = report.trans_max;
        self.rot_mean_deg = report.rot_mean_deg;
        self.relations = report.n;
        self.relations_missing = report.missing;
        self.relations_over_0_5_m = errors
            .iter()
            .map(RelationError::trans)
            .filter(|&e| e > FAILURE_M)
            .count();
        // `relation_errors` gives the scored relations in order, skipping the missing ones.
        let mut scored = errors.iter().peekable();
        self.relation_errors = relations
            .iter()
            .map(|r| {
                scored
                    .next_if(|e| e.t1 == r.t1 && e.t2 == r.t2)
                    .map(RelationError::trans)
            })
            .collect();
        Ok(())
    }

    /// This run's mean translational error over the relations `other` scored, when `other`
    /// scored only some of those this run did (`scans/2` keeps the relations between two
    /// even records); `None` when both scored the same relations, or when either run's
    /// per-relation errors are unknown (figures from outside, or another relations file).
    #[must_use]
    pub fn mean_on_relations_of(&self, other: &RunFigures) -> Option<f64> {
        if self.relation_errors.len() != other.relation_errors.len()
            || self.relation_errors.is_empty()
        {
            return None;
        }
        let both: Vec<f64> = self
            .relation_errors
            .iter()
            .zip(&other.relation_errors)
            .filter_map(|(mine, theirs)| theirs.and(*mine))
            .collect();
        if both.len() == self.relations || both.is_empty() {
            return None;
        }
        Some(both.iter().sum::<f64>() / both.len() as f64)
    }
}

/// The message of a caught panic.
pub(super) fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_string())
}

/// Runs `work` on every item with `jobs` worker threads pulling indices from a shared counter,
/// calling `done` (on this thread) as each item finishes. The results are in item order; a
/// panicking item gives an error, not a dead sweep.
pub fn run_parallel<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    work: impl Fn(&T) -> Result<R> + Sync,
    mut done: impl FnMut(usize, &Result<R, String>, Duration),
) -> Vec<Result<R, String>> {
    let next = AtomicUsize::new(0);
    let mut results: Vec<Option<Result<R, String>>> = items.iter().map(|_| None).collect();
    std::thread::scope(|s| {
        let (tx, rx) = std::sync::mpsc::channel();
        for _ in 0..jobs.clamp(1, items.len().max(1)) {
            let tx = tx.clone();
            let (next, work) = (&next, &work);
            s.spawn(move || {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(item) = items.get(i) else { break };
                    let t0 = Instant::now();
                    let result =
                        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(item)))
                            .map_err(|p| format!("panicked: {}", panic_message(p.as_ref())))
                            .and_then(|r| r.map_err(|e| format!("{e:#}")));
                    if tx.send((i, result, t0.elapsed())).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (i, result, elapsed) in rx {
            done(i, &result, elapsed);
            if let Some(slot) = results.get_mut(i) {
                *slot = Some(result);
            }
        }
    });
    results
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err("no result (worker lost)".to_string())))
        .collect()
}
