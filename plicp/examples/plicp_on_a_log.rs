//! PL-ICP on a CARMEN log through the qicp library: register it, match, score, draw.
//!
//! ```text
//! cargo run --release -p qicp-plicp --example plicp_on_a_log -- \
//!     ../shared/data/intel/intel.clf.bz2 ../shared/data/intel/intel.relations q-plicp out/plicp
//! ```

use anyhow::{Context, Result};
use qicp::eval::evaluate_relations;
use qicp::logs::carmen::{CarmenOptions, read_carmen};
use qicp::logs::relations::read_relations;
use qicp::matching::run_matcher;
use qicp::plots::occupancy_map;
use qicp_matchers::Registry;
use std::path::PathBuf;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [log, relations, kind, out] = args.as_slice() else {
        anyhow::bail!("usage: plicp_on_a_log LOG RELATIONS KIND OUT_DIR (KIND: plicp, q-plicp, …)");
    };
    // The built-in matchers and PL-ICP, with its boosted forms by composition.
    let mut registry = Registry::builtin();
    qicp_plicp::register(&mut registry);
    let config = registry.config(kind)?;

    let log = read_carmen(&PathBuf::from(log), &CarmenOptions::default())?;
    let run = run_matcher(&log.records, &config, true)?;
    let report = evaluate_relations(
        &run.trajectory,
        &read_relations(&PathBuf::from(relations))?,
        0.1,
    )?;
    println!(
        "{kind}: {:.3} m, {:.2}° mean relation error; {:.2} ms per scan; {} map points",
        report.trans_mean,
        report.rot_mean_deg,
        run.summary.ms_per_scan_median,
        run.summary.map_points
    );

    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let path: Vec<_> = run.trajectory.iter().map(|(_, p)| *p).collect();
    let lasers: Vec<_> = path
        .iter()
        .zip(&log.records)
        .map(|(p, r)| *p * r.laser_offset)
        .collect();
    let scans: Vec<_> = log.records.iter().map(|r| &r.scan).collect();
    let file = out.join(format!("map_{kind}.png"));
    occupancy_map(
        &file,
        &format!("{kind}: every scan at its estimated pose"),
        &lasers,
        &scans,
        &path,
        None,
    )?;
    println!("map: {}", file.display());
    Ok(())
}
