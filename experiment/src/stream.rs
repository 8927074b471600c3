//! A log source, scan by scan: raw odometry and every matcher read the log afresh, write their
//! outputs as the scans come, and keep what the scores and pictures need, not the records.
//!
//! What a matcher's run holds, besides its own map: the poses nearest the relations' times
//! (a [`RelationProbe`]), the three per-scan values of [`PerScan`] (24 bytes a scan) and, only
//! when the source has ground truth (which is held whole all the same), the whole trajectory
//! for the ATE. The pictures read the trajectories back from their files.

use super::*;
use qicp_eval::{RelationProbe, origin_alignment};
use qicp_io::tum::write_tum_pose;
use qicp_matchers::trail::Amendment;
use qicp_runner::matching::{MatchLoop, RunWriter, progress_bar};

/// One trajectory as it streams past: the poses a relation may need and, when there is truth
/// to score it against, every pose.
struct Track {
    probe: Option<RelationProbe>,
    whole: Option<Vec<Stamped>>,
}

impl Track {
    fn new(source: &Source) -> Result<Self> {
        let probe = source
            .relations
            .as_deref()
            .map(|r| RelationProbe::new(r, qicp_eval::DEFAULT_MAX_DT))
            .transpose()?;
        Ok(Self {
            probe,
            whole: source.truth.is_some().then(Vec::new),
        })
    }

    fn push(&mut self, t: f64, pose: Pose2) -> Result<()> {
        if let Some(probe) = &mut self.probe {
            probe.push(t, pose)?;
        }
        if let Some(whole) = &mut self.whole {
            whole.push((t, pose));
        }
        Ok(())
    }

    /// Moves the poses pushed so far as `amendment` says (by their order of pushing).
    fn amend(&mut self, amendment: &Amendment) {
        if let Some(probe) = &mut self.probe {
            probe.amend(|k| amendment.moved(k));
        }
        if let Some(whole) = &mut self.whole {
            amendment.apply(whole, |(_, pose)| pose);
        }
    }

    fn scores(&self, source: &Source) -> Result<Scores> {
        let near = self.probe.as_ref().map(RelationProbe::trajectory);
        Scores::of_parts(self.whole.as_deref(), near.as_deref(), source)
    }
}

/// Writes raw odometry at the laser times to `path` (TUM), reading the log afresh, and scores
/// it.
/// The file is written under a temporary name beside `path` and renamed when complete, so a
/// pass that fails leaves no partial file.
pub(super) fn odometry_pass(source: &Source, path: &Path) -> Result<Scores> {
    let mut w = qicp_runner::matching::OutputFile::create(path)?;
    let mut track = Track::new(source)?;
    source.each_record(|r| {
        write_tum_pose(&mut w, r.timestamp(), &r.odometry)
            .with_context(|| format!("writing {}", path.display()))?;
        track.push(r.timestamp(), r.odometry)
    })?;
    w.commit()?;
    track.scores(source).context("scoring odometry")
}

/// Runs `matcher` over the source's records as they are read, writing `trajectory.tum` and
/// `matches.csv` into `dir` as it goes (renamed into place when complete). With `pictures`
/// it also gathers the bounds of the matcher's map picture (at the poses the picture draws:
/// aligned with the truth's start, when there is truth).
pub(super) fn run_streamed(
    source: &Source,
    matcher: &MatcherConfig,
    dir: &Path,
    show_progress: bool,
    pictures: bool,
) -> Result<MatcherOutcome> {
    let t = Instant::now();
    let kind = matcher.kind();
    let mut matching = MatchLoop::new(matcher)?;
    let mut writer = RunWriter::create(dir)?.keeping_poses(matching.amends());
    let mut track = Track::new(source)?;
    let mut per_scan = PerScan::default();
    let truth = source.truth.as_deref();
    let mut extent = pictures.then(plots::MapExtent::new);
    if let (Some(e), Some(truth)) = (&mut extent, truth) {
        for (_, p) in truth {
            e.add_pose(p);
        }
    }
    let mut to_truth: Option<Pose2> = None;
    let bar = if show_progress {
        progress_bar(source.scans(), &kind)
    } else {
        indicatif::ProgressBar::hidden()
    };
    source
        .each_record(|record| {
            let (estimate, row) = matching.push(record);
            if let Some(amendment) = matching.take_amendment() {
                writer.amend(&amendment)?;
                track.amend(&amendment);
            }
            let t = record.timestamp();
            writer.push(t, &estimate.pose, &row)?;
            track.push(t, estimate.pose)?;
            per_scan.push(&row);
            if let Some(e) = &mut extent {
                // As `pictures::aligned`: the first pose moved onto the truth's first.
                let align =
                    *to_truth.get_or_insert_with(|| match truth.and_then(<[Stamped]>::first) {
                        Some((_, t0)) => origin_alignment(&estimate.pose, t0),
                        None => Pose2::IDENTITY,
                    });
                e.add_scan(&(align * estimate.pose * record.laser_offset), &record.scan);
            }
            bar.inc(1);
            Ok(())
        })
        .with_context(|| format!("running {kind}"))?;
    bar.finish_and_clear();
    writer.commit(matcher, None)?;
    let scores = track
        .scores(source)
        .with_context(|| format!("scoring {kind}"))?;
    Ok(MatcherOutcome {
        config: matcher.clone(),
        trajectory: track.whole,
        trajectory_file: dir.join("trajectory.tum"),
        per_scan,
        summary: matching.summary(),
        scores,
        seconds: t.elapsed().as_secs_f64(),
        extent,
    })
}
