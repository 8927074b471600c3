//! Simulates one drive and prints its scores.
//!
//! How to run: `cargo run --release -p qicp-sim --example drive -- configs/worlds/park.toml`

use qicp_sim::{DriveScores, SimConfig, Simulation};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "configs/worlds/park.toml".into());
    let cfg = SimConfig::load(path.as_ref())?;
    let t0 = std::time::Instant::now();
    let (records, stats, world) = Simulation::run(cfg)?;
    let wall = t0.elapsed().as_secs_f64();
    let s = DriveScores::of(&records);
    println!(
        "world {:?}, {} obstacles, route {:.1} m",
        world.kind,
        world.obstacles.len(),
        world.route_length()
    );
    println!("{s:#?}");
    println!("{stats:#?}");
    println!("wall {wall:.3} s");
    Ok(())
}
