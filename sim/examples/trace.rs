//! Prints the true and odometry poses of a drive, one line per scan (debugging aid).
//!
//! How to run: `cargo run --release -p qicp-sim --example trace -- configs/worlds/park.toml`

use qicp_sim::{SimConfig, Simulation};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "configs/worlds/park.toml".into());
    let every: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let cfg = SimConfig::load(path.as_ref())?;
    for (k, r) in Simulation::new(cfg)?.enumerate() {
        let r = r?;
        if k % every == 0 {
            let t = r.truth.unwrap_or_default();
            let o = r.odometry;
            println!(
                "{:8.2}  truth {:8.3} {:8.3} {:7.3}  odom {:8.3} {:8.3} {:7.3}  returns {}",
                r.timestamp(),
                t.x,
                t.y,
                t.theta,
                o.x,
                o.y,
                o.theta,
                r.scan.valid_count()
            );
        }
    }
    Ok(())
}
