//! `--worlds N`: the experiment on N simulated worlds, reported as medians.

use super::*;

/// Figures of one matcher summarised over the worlds of `--worlds`.
pub(super) const WORLD_FIGURES: [&str; 8] = [
    "ate_rmse_m",
    "final_error_m",
    "rpe_trans_per_m",
    "residual_mean_mm",
    "certainty_mean",
    "sigma_mean_mm",
    "ms_per_scan_median",
    "fallbacks",
];

/// Ratios of a boosted / incremental pair summarised over the worlds of `--worlds`.
pub(super) const WORLD_RATIOS: [&str; 6] = [
    "ate",
    "final_error",
    "residual",
    "certainty",
    "sigma",
    "certainty_per_scan_median",
];

/// `{"median", "min", "max"}` of the finite values (the median of an even count is the mean
/// of the two middle values); nulls when there are none.
pub(super) fn spread(values: &[f64]) -> Value {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return json!({"median": null, "min": null, "max": null});
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    json!({"median": median, "min": v[0], "max": v[n - 1]})
}

/// `qicp run --worlds N`: the experiment on N layouts of the simulated world.
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
    let drive = qicp_sim::SimConfig::load(sim)
        .with_context(|| format!("loading drive {}", sim.display()))?;
    let first = config.source.world_seed.unwrap_or(drive.world.seed);
    let first_noise = config.source.seed.unwrap_or(drive.drive.seed);
    let seeds: Vec<u64> = (0..n as u64).map(|k| first + k).collect();
    let mut summaries = Vec::with_capacity(n);
    for (k, &seed) in seeds.iter().enumerate() {
        if !args.quiet {
            eprintln!("world {}/{n} (seed {seed})", k + 1);
        }
        let mut c = config.clone();
        c.source.world_seed = Some(seed);
        c.source.seed = Some(first_noise + k as u64);
        let dir = out.join(format!("world-{seed}"));
        summaries.push(
            run_once(args, registry, &c, &dir, false, Instant::now())
                .with_context(|| format!("world seed {seed}"))?,
        );
    }
    let collect = |get: &dyn Fn(&Value) -> &Value| -> Vec<f64> {
        summaries
            .iter()
            .map(|s| get(s).as_f64().unwrap_or(f64::NAN))
            .collect()
    };
    let mut matchers = Map::new();
    for kind in &config.run.matchers {
        let mut m = Map::new();
        for figure in WORLD_FIGURES {
            let values = collect(&|s| &s["matchers"][kind.as_str()][figure]);
            m.insert(figure.into(), spread(&values));
        }
        matchers.insert(kind.clone(), Value::Object(m));
    }
    let mut ratios = Map::new();
    if let Some(pairs) = summaries[0]["ratios"].as_object() {
        for pair in pairs.keys() {
            let mut m = Map::new();
            for figure in WORLD_RATIOS {
                let values = collect(&|s| &s["ratios"][pair][figure]);
                m.insert(figure.into(), spread(&values));
            }
            ratios.insert(pair.clone(), Value::Object(m));
        }
    }
    let report = json!({
        "source": summaries[0]["source"],
        "config": args.config.display().to_string(),
        "world_seeds": seeds,
        "noise_seeds": (0..n as u64).map(|k| first_noise + k).collect::<Vec<_>>(),
        "scans": spread(&collect(&|s| &s["scans"])),
        "matchers": matchers,
        "ratios": ratios,
        "wall_seconds": started.elapsed().as_secs_f64(),
    });
    let text = serde_json::to_string_pretty(&report)?;
    let path = out.join("worlds.json");
    write_atomic(&path, format!("{text}\n").as_bytes())?;
    if args.json {
        println!("{text}");
    } else if !args.quiet {
        println!("{}", worlds_table(&report, &config.run.matchers));
        println!("outputs in {}", out.display());
    }
    Ok(())
}

/// The table printed after `--worlds`: median [min-max] of each figure.
pub(super) fn worlds_table(report: &Value, kinds: &[String]) -> String {
    let cell = |v: &Value, scale: f64, digits: usize| match (
        v["median"].as_f64(),
        v["min"].as_f64(),
        v["max"].as_f64(),
    ) {
        (Some(m), Some(lo), Some(hi)) => format!(
            "{:.digits$} [{:.digits$}-{:.digits$}]",
            m * scale,
            lo * scale,
            hi * scale
        ),
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
        let m = &report["matchers"][k.as_str()];
        rows.push(
            std::iter::once(k.to_string())
                .chain(columns.iter().map(|c| cell(&m[c.1], c.2, c.3)))
                .collect(),
        );
    }
    let widths: Vec<usize> = (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut text = format!(
        "{} — {} worlds (seeds {}), median [min-max]\n",
        report["source"].as_str().unwrap_or("?"),
        report["world_seeds"].as_array().map_or(0, Vec::len),
        report["world_seeds"]
            .as_array()
            .map(|s| {
                let s: Vec<String> = s.iter().map(ToString::to_string).collect();
                s.join(", ")
            })
            .unwrap_or_default(),
    );
    for r in rows {
        text += &table_line(&r, &widths);
        text.push('\n');
    }
    if let Some(ratios) = report["ratios"].as_object().filter(|r| !r.is_empty()) {
        text += "\nboosted / incremental, median [min-max]:";
        for (pair, r) in ratios {
            let parts: Vec<String> = ["ate", "residual", "certainty", "sigma"]
                .iter()
                .map(|k| format!("{k} {}", cell(&r[*k], 1.0, 3)))
                .collect();
            text += &format!("\n  {pair}: {}", parts.join(", "));
        }
        text.push('\n');
    }
    text += &format!(
        "\nwall time {:.1} s",
        report["wall_seconds"].as_f64().unwrap_or(f64::NAN)
    );
    text
}
