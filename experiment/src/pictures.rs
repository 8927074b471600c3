//! The pictures of a run: maps, paths, and the paper's per-scan figures.

use super::*;

/// Writes `traj` to `path` (TUM) under a temporary name, renamed into place when complete.
pub(super) fn write_trajectory(path: &Path, traj: &[Stamped]) -> Result<()> {
    let mut w = qicp_runner::matching::OutputFile::create(path)?;
    write_tum(&mut w, traj).with_context(|| format!("writing {}", path.display()))?;
    w.commit()
}

/// `traj` moved so its first pose lies on `truth`'s first (the ATE alignment of
/// [`evaluate_ate`]); unchanged without truth.
pub(super) fn aligned(traj: &[Stamped], truth: Option<&[Stamped]>) -> Vec<Pose2> {
    let to_truth = match (traj.first(), truth.and_then(<[Stamped]>::first)) {
        (Some((_, e)), Some((_, t))) => qicp_eval::origin_alignment(e, t),
        _ => Pose2::IDENTITY,
    };
    traj.iter().map(|(_, p)| to_truth * *p).collect()
}

/// A matcher's trajectory: the held one, or read back from its file.
fn trajectory_of(o: &MatcherOutcome) -> Result<std::borrow::Cow<'_, [Stamped]>> {
    Ok(match &o.trajectory {
        Some(t) => std::borrow::Cow::Borrowed(t.as_slice()),
        None => std::borrow::Cow::Owned(
            qicp_io::tum::read_tum(&o.trajectory_file)
                .with_context(|| format!("reading {}", o.trajectory_file.display()))?,
        ),
    })
}

/// Draws a picture at `path` through `draw`, which is given the temporary file to draw into:
/// renamed into place when complete, removed if drawing fails or a signal stops the run.
fn picture<T>(path: &Path, draw: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
    let out = qicp_runner::matching::OutputFile::create(path)?;
    let value = draw(out.temp_path()).with_context(|| format!("drawing {}", path.display()))?;
    out.commit()?;
    Ok(value)
}

/// Draws the map of `o` for a log source: the log read afresh, every scan at the matcher's
/// poses (read back from its trajectory file) into a grid over the bounds gathered while
/// matching. Memory holds the grid and the path, not the scans.
fn streamed_map(
    file: &Path,
    title: &str,
    source: &Source,
    o: &MatcherOutcome,
    truth_poses: Option<&[Pose2]>,
) -> Result<usize> {
    let extent = o
        .extent
        .as_ref()
        .with_context(|| format!("{}: no map bounds were gathered", o.kind()))?;
    let (lo, hi) = extent.bounds();
    if !(lo.0.is_finite() && lo.1.is_finite() && hi.0.is_finite() && hi.1.is_finite()) {
        anyhow::bail!("{}: no scan or pose to draw a map of", o.kind());
    }
    let poses = aligned(&trajectory_of(o)?, source.truth.as_deref());
    let mut canvas = plots::MapCanvas::new(lo, hi);
    let mut k = 0;
    source.each_record(|r| {
        let pose = poses.get(k).with_context(|| {
            format!(
                "{} holds {} poses, fewer than the log's scans",
                o.trajectory_file.display(),
                poses.len()
            )
        })?;
        canvas.insert_scan(&(*pose * r.laser_offset), &r.scan);
        k += 1;
        Ok(())
    })?;
    picture(file, |to| {
        Ok(canvas.draw(to, title, &poses, truth_poses)?)
    })
}

/// The maps of a held drive, drawn in parallel from the records in memory.
fn held_maps(
    out: &Path,
    records: &[Record],
    truth: Option<&[Stamped]>,
    truth_poses: Option<&[Pose2]>,
    outcomes: &[MatcherOutcome],
) -> Vec<(String, Result<usize>)> {
    let scans: Vec<&qicp_core::Scan> = records.iter().map(|r| &r.scan).collect();
    std::thread::scope(|s| {
        let handles: Vec<_> = outcomes
            .iter()
            .map(|o| {
                let scans = &scans;
                s.spawn(move || {
                    let file = format!("map_{}.png", o.kind());
                    let title = format!("{}: every scan at its estimated pose", o.kind());
                    let r = (|| -> Result<usize> {
                        let poses = aligned(&trajectory_of(o)?, truth);
                        let lasers: Vec<Pose2> = poses
                            .iter()
                            .zip(records)
                            .map(|(p, r)| *p * r.laser_offset)
                            .collect();
                        picture(&out.join(&file), |to| {
                            Ok(plots::occupancy_map(
                                to,
                                &title,
                                &lasers,
                                scans,
                                &poses,
                                truth_poses,
                            )?)
                        })
                    })();
                    (file, r)
                })
            })
            .collect();
        joined(handles)
    })
}

/// The results of the map threads; a panicked thread gives an error.
fn joined(
    handles: Vec<std::thread::ScopedJoinHandle<'_, (String, Result<usize>)>>,
) -> Vec<(String, Result<usize>)> {
    handles
        .into_iter()
        .map(|h| {
            h.join().unwrap_or_else(|_| {
                (
                    "map".into(),
                    Err(anyhow::anyhow!("drawing a map: its thread panicked")),
                )
            })
        })
        .collect()
}

/// Draws every picture; returns what each file shows, by file name. A simulated drive's records are held
/// and drawn from memory; a log is read afresh for each matcher's map, and the paths are read
/// back from `odometry.tum` and each `trajectory.tum` (a picture of paths holds them while it
/// is drawn, 24 bytes a scan each).
pub(super) fn draw_pictures(
    out: &Path,
    source: &Source,
    outcomes: &[MatcherOutcome],
) -> Result<BTreeMap<String, String>> {
    let mut pictures = BTreeMap::new();
    let truth = source.truth.as_deref();
    let truth_poses: Option<Vec<Pose2>> = truth.map(|t| t.iter().map(|p| p.1).collect());
    let aligned_note = if truth.is_some() {
        ", start aligned with the truth"
    } else {
        ""
    };

    // Maps (paper Figs. 3, 5): one per matcher; a held drive's are drawn in parallel (each is
    // independent).
    let maps: Vec<(String, Result<usize>)> = match &source.records {
        Records::Held(records) => held_maps(out, records, truth, truth_poses.as_deref(), outcomes),
        // One at a time: each holds a grid, a picture and its path while it is drawn, and
        // reads the log afresh.
        Records::Log { .. } => outcomes
            .iter()
            .map(|o| {
                let file = format!("map_{}.png", o.kind());
                let title = format!("{}: every scan at its estimated pose", o.kind());
                let r = streamed_map(&out.join(&file), &title, source, o, truth_poses.as_deref());
                (file, r)
            })
            .collect(),
    };
    for (file, r) in maps {
        r?;
        pictures.insert(
            file,
            "occupancy grid of every scan at the matcher's poses: black hit, white free, grey unseen; blue estimated path, grey true path (paper Figs. 3, 5)".to_string(),
        );
    }

    // Trajectories.
    let aligned_all: Vec<Vec<Pose2>> = outcomes
        .iter()
        .map(|o| Ok(aligned(&trajectory_of(o)?, truth)))
        .collect::<Result<_>>()?;
    let odo = match source.odometry() {
        Some(odometry) => aligned(&odometry, truth),
        None => {
            let path = out.join("odometry.tum");
            let odometry = qicp_io::tum::read_tum(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            aligned(&odometry, truth)
        }
    };
    let mut series = Vec::new();
    if let Some(t) = &truth_poses {
        series.push(PathSeries {
            label: "ground truth".into(),
            poses: t,
            color: plots::TRUTH_COLOR,
            width: 4,
            dashed: false,
        });
    }
    series.push(PathSeries {
        label: "odometry".into(),
        poses: &odo,
        color: plots::ODOMETRY_COLOR,
        width: 2,
        dashed: false,
    });
    for (k, (o, poses)) in outcomes.iter().zip(&aligned_all).enumerate() {
        series.push(PathSeries {
            label: o.kind(),
            poses,
            color: plots::PALETTE[k % plots::PALETTE.len()],
            width: 2,
            // kd-tree kinds often coincide with their quad-tree twins: dashed, both show.
            dashed: o.config.reference.is_map() && o.config.index() != "quadtree",
        });
    }
    let title = format!("Robot paths, {} scans{aligned_note}", source.scans());
    picture(&out.join("trajectories.png"), |to| {
        Ok(plots::trajectories(to, &title, &series)?)
    })?;
    pictures.insert(
        "trajectories.png".into(),
        "every matcher's path with the ground truth (black) and raw odometry (grey), metres"
            .to_string(),
    );

    // Paper Fig. 4: per family, the boosted matcher in front of the incremental one.
    // The quad-tree form first, as the paper draws it.
    let pairs: Vec<(&MatcherOutcome, &MatcherOutcome)> = outcomes
        .iter()
        .filter(|i| i.config.reference.name() == qicp_matchers::registry::SCAN)
        .filter_map(|i| {
            let twins = || {
                outcomes.iter().filter(|b| {
                    b.config.reference.is_map() && b.config.algorithm() == i.config.algorithm()
                })
            };
            let b = twins()
                .find(|b| b.config.index() == "quadtree")
                .or_else(|| twins().next())?;
            Some((i, b))
        })
        .collect();
    if !pairs.is_empty() {
        let (inc_color, boost_color) = (plots::PALETTE[0], plots::PALETTE[1]);
        let residual: Vec<Panel> = pairs
            .iter()
            .map(|(i, b)| Panel {
                title: format!(
                    "Residual correlation distance, {} vs {}",
                    b.kind(),
                    i.kind()
                ),
                series: vec![
                    ScanSeries {
                        label: i.kind(),
                        values: i.per_scan.residual_mm.clone(),
                        color: inc_color,
                    },
                    ScanSeries {
                        label: b.kind(),
                        values: b.per_scan.residual_mm.clone(),
                        color: boost_color,
                    },
                ],
                reference: None,
                y_cap: None,
            })
            .collect();
        picture(&out.join("residual.png"), |to| {
            Ok(plots::per_scan(
                to,
                "residual correlation distance (mm)",
                &residual,
            )?)
        })?;
        pictures.insert("residual.png".into(), "residual correlation distance per scan (mm), boosted in front of incremental, thick lines the means (paper Fig. 4a-b)".to_string());
        let certainty: Vec<Panel> = pairs
            .iter()
            .map(|(i, b)| Panel {
                title: format!("Matching certainty, {} relative to {}", b.kind(), i.kind()),
                series: vec![ScanSeries {
                    label: format!("{} / {}", b.kind(), i.kind()),
                    values: b
                        .per_scan
                        .certainty
                        .iter()
                        .zip(&i.per_scan.certainty)
                        .map(|(cb, ci)| cb / ci)
                        .collect(),
                    color: boost_color,
                }],
                reference: Some(1.0),
                y_cap: Some(3.0),
            })
            .collect();
        picture(&out.join("certainty.png"), |to| {
            Ok(plots::per_scan(
                to,
                "certainty ratio (boosted / incremental)",
                &certainty,
            )?)
        })?;
        pictures.insert("certainty.png".into(), "per scan, the boosted matcher's certainty sqrt(σxx²+σyy²) (covariance diagonal, m²) divided by the incremental one's; dashed: 1, thick: the mean (paper Fig. 4c-d)".to_string());
    }
    Ok(pictures)
}
