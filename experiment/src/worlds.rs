//! `--worlds N`: the experiment on N simulated worlds, reported as medians.

use super::*;

/// Per key (a matcher kind, a boosted / incremental pair) and per figure, the spread of the
/// figure over the worlds' summaries; NaN for a world where `pick` finds nothing.
fn spreads<T>(
    summaries: &[ExperimentSummary],
    keys: &[String],
    figures: &[Figure<T>],
    pick: impl for<'a> Fn(&'a ExperimentSummary, &String) -> Option<&'a T>,
) -> BTreeMap<String, BTreeMap<&'static str, Spread>> {
    keys.iter()
        .map(|key| {
            let per_figure = figures
                .iter()
                .map(|&(name, get)| {
                    let values: Vec<f64> = summaries
                        .iter()
                        .map(|s| pick(s, key).map_or(f64::NAN, get))
                        .collect();
                    (name, Spread::of(&values))
                })
                .collect();
            (key.clone(), per_figure)
        })
        .collect()
}

/// `qicp run --worlds N`: the experiment on N layouts of the simulated world.
/// Most worlds one `--worlds` run takes: each is a whole simulated drive and its matchers.
pub const MAX_WORLDS: usize = 10_000;

pub(super) fn run_worlds(
    args: &RunArgs,
    registry: &Registry,
    config: &ExperimentConfig,
    out: &Path,
    n: usize,
    started: Instant,
) -> Result<()> {
    let Some(sim) = &config.source.sim else {
        anyhow::bail!("--worlds needs a `sim` source: a log has one world");
    };
    if n == 0 {
        anyhow::bail!("--worlds 0: nothing would run");
    }
    if n > MAX_WORLDS {
        anyhow::bail!("--worlds {n}: at most {MAX_WORLDS} worlds");
    }
    let drive = qicp_sim::SimConfig::load(sim)
        .with_context(|| format!("loading drive {}", sim.display()))?;
    let first = config.source.world_seed.unwrap_or(drive.world.seed);
    let first_noise = config.source.seed.unwrap_or(drive.drive.seed);
    let seeds: Vec<u64> = (0..n as u64).map(|k| first.wrapping_add(k)).collect();
    let mut summaries = Vec::with_capacity(n);
    for (k, &seed) in seeds.iter().enumerate() {
        if !args.quiet {
            qicp_core::note!("world {}/{n} (seed {seed})", k + 1);
        }
        let mut c = config.clone();
        c.source.world_seed = Some(seed);
        c.source.seed = Some(first_noise.wrapping_add(k as u64));
        let dir = out.join(format!("world-{seed}"));
        summaries.push(
            run_once(args, registry, &c, &dir, false, Instant::now())
                .with_context(|| format!("world seed {seed}"))?,
        );
    }
    let matchers = spreads(&summaries, &config.run.matchers, &WORLD_FIGURES, |s, k| {
        s.matchers.get(k)
    });
    let pairs: Vec<String> = summaries[0].ratios.keys().cloned().collect();
    let ratios = spreads(&summaries, &pairs, &WORLD_RATIOS, |s, k| s.ratios.get(k));
    let report = WorldsReport {
        source: summaries[0].source.clone(),
        config: args.config.display().to_string(),
        world_seeds: seeds,
        noise_seeds: (0..n as u64).map(|k| first_noise.wrapping_add(k)).collect(),
        scans: Spread::of(&summaries.iter().map(|s| s.scans as f64).collect::<Vec<_>>()),
        matchers,
        ratios,
        wall_seconds: started.elapsed().as_secs_f64(),
    };
    let text = serde_json::to_string_pretty(&report)?;
    let path = out.join("worlds.json");
    write_atomic(&path, format!("{text}\n").as_bytes())?;
    if args.json {
        qicp_core::say!("{text}")?;
    } else if !args.quiet {
        qicp_core::say!("{}", worlds_table(&report, &config.run.matchers))?;
        qicp_core::say!("outputs in {}", out.display())?;
    }
    Ok(())
}

/// The table printed after `--worlds`: median [min-max] of each figure.
pub(super) fn worlds_table(report: &WorldsReport, kinds: &[String]) -> String {
    let worlds = report.world_seeds.len();
    // A spread over fewer worlds than were run says how many it is of.
    let cell = |v: Option<&Spread>, scale: f64, digits: usize| match v {
        Some(&Spread {
            median: Some(m),
            min: Some(lo),
            max: Some(hi),
            n,
        }) => {
            let of = if n < worlds {
                format!(" ({n} of {worlds})")
            } else {
                String::new()
            };
            format!(
                "{:.digits$} [{:.digits$}-{:.digits$}]{of}",
                m * scale,
                lo * scale,
                hi * scale
            )
        }
        _ => "-".into(),
    };
    let columns: [(&str, &str, f64, usize); 6] = [
        ("ATE m", "ate_rmse_m", 1.0, 2),
        ("final m", "final_error_m", 1.0, 2),
        ("resid. mm", "residual_mean_mm", 1.0, 1),
        ("certainty mm²", "certainty_mean", 1e6, 1),
        ("σ mm", "sigma_mean_mm", 1.0, 1),
        ("ms/scan", "ms_per_scan_median", 1.0, 2),
    ];
    let mut rows = vec![
        std::iter::once("matcher".to_string())
            .chain(columns.iter().map(|c| c.0.to_string()))
            .collect::<Vec<_>>(),
    ];
    for k in kinds {
        let m = report.matchers.get(k);
        rows.push(
            std::iter::once(k.to_string())
                .chain(
                    columns
                        .iter()
                        .map(|c| cell(m.and_then(|m| m.get(c.1)), c.2, c.3)),
                )
                .collect(),
        );
    }
    let widths: Vec<usize> = (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let seeds: Vec<String> = report.world_seeds.iter().map(ToString::to_string).collect();
    let mut text = format!(
        "{} — {} worlds (seeds {}), median [min-max]\n",
        report.source,
        seeds.len(),
        seeds.join(", "),
    );
    for r in rows {
        text += &table_line(&r, &widths);
        text.push('\n');
    }
    if !report.ratios.is_empty() {
        text += "\nboosted / incremental, median [min-max]:";
        for (pair, r) in &report.ratios {
            let parts: Vec<String> = ["ate", "residual", "certainty", "sigma"]
                .iter()
                .map(|k| format!("{k} {}", cell(r.get(k), 1.0, 3)))
                .collect();
            text += &format!("\n  {pair}: {}", parts.join(", "));
        }
        text.push('\n');
    }
    text += &format!("\nwall time {:.1} s", report.wall_seconds);
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_figure_missing_in_some_worlds_says_how_many_worlds_it_is_of() {
        // One world of four has no residual (its matcher fell back on every scan): the spread
        // is of the other three, and the table says so instead of passing for all four.
        let spread = Spread::of(&[0.1, f64::NAN, 0.3, 0.5]);
        assert_eq!(
            (spread.median, spread.min, spread.max, spread.n),
            (Some(0.3), Some(0.1), Some(0.5), 3)
        );
        let full = Spread::of(&[0.2, 0.4, 0.6, 0.8]);
        let figures = |s: Spread| BTreeMap::from([("residual_mean_mm", s), ("ate_rmse_m", full)]);
        let report = WorldsReport {
            source: "sim".into(),
            config: "park.toml".into(),
            world_seeds: vec![7, 8, 9, 10],
            noise_seeds: vec![1, 2, 3, 4],
            scans: Spread::of(&[800.0; 4]),
            matchers: BTreeMap::from([("wsm".to_string(), figures(spread))]),
            ratios: BTreeMap::new(),
            wall_seconds: 1.0,
        };
        let table = worlds_table(&report, &["wsm".to_string()]);
        assert!(table.contains("0.3 [0.1-0.5] (3 of 4)"), "{table}");
        assert!(table.contains("0.50 [0.20-0.80] "), "{table}");
        assert!(!table.contains("(4 of 4)"), "{table}");
    }
}
