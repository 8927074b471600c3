//! The physics and the shipped drives: slip makes odometry drift, more so on less friction;
//! the robot never enters an obstacle; the park loop closes; park odometry is poor and its
//! laser sparse, the corridor's laser dense.

use qicp_core::Record;
use qicp_sim::{DriveScores, DriveStats, SimConfig, Simulation, World};
use std::path::PathBuf;

fn shipped(name: &str) -> SimConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/worlds")
        .join(name);
    SimConfig::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn run(cfg: SimConfig) -> (Vec<Record>, DriveStats, World) {
    Simulation::run(cfg).expect("simulation runs")
}

/// A 6 m square driven twice in an empty world, noise-free encoders: any drift is slip.
fn square(friction: f64) -> SimConfig {
    let text = format!(
        r#"
[world]
kind = "custom"
[robot]
ground_friction = {friction}
rolling_resistance = 0.05
[laser]
beams = 5
rate_hz = 2.0
[drive]
waypoints = [[0.0, 0.0], [6.0, 0.0], [6.0, 6.0], [0.0, 6.0], [0.0, 0.0],
             [6.0, 0.0], [6.0, 6.0], [0.0, 6.0], [0.0, 0.0]]
speed = 0.5
accel = 1.5
angular_accel_deg = 360.0
"#
    );
    SimConfig::from_toml_str(&text).expect("valid")
}

#[test]
fn less_friction_gives_larger_odometry_drift_on_the_same_route() {
    let mut drift = Vec::new();
    for mu in [0.9, 0.4, 0.15] {
        let (records, stats, _) = run(square(mu));
        assert!(stats.route_completed, "µ = {mu}: route not completed");
        let s = DriveScores::of(&records);
        assert!(s.loop_gap_m < 0.3, "µ = {mu}: loop gap {}", s.loop_gap_m);
        drift.push((mu, s.odometry_final_error_m, s.odometry_ate_m));
    }
    for w in drift.windows(2) {
        assert!(
            w[1].1 > w[0].1 && w[1].2 > w[0].2,
            "drift does not grow as friction falls: {drift:?}"
        );
    }
    assert!(drift[2].1 > 3.0 * drift[0].1, "{drift:?}");
}

#[test]
fn without_slip_or_encoder_error_odometry_follows_the_truth() {
    // High friction, no rolling resistance, a gentle drive: creep is tiny.
    let mut cfg = square(1.0);
    cfg.robot.rolling_resistance = 0.0;
    cfg.drive.accel = 0.3;
    cfg.drive.angular_accel_deg = 60.0;
    let (records, _, _) = run(cfg);
    let s = DriveScores::of(&records);
    assert!(s.odometry_final_error_m < 0.1, "{s:?}");
}

#[test]
fn encoder_bias_bends_odometry_the_predicted_way() {
    // The right wheel reports 1 % more than the left: odometry turns left, by
    // Δθ = 0.01·d / wheel_base, while the truth drives straight.
    let text = r#"
[world]
kind = "custom"
[robot]
encoder_bias = [0.0, 0.01]
rolling_resistance = 0.0
[laser]
beams = 3
[drive]
waypoints = [[0.0, 0.0], [10.0, 0.0]]
accel = 0.3
"#;
    let (records, _, _) = run(SimConfig::from_toml_str(text).expect("valid"));
    let last = records.last().expect("records");
    let truth = last.truth.expect("truth");
    let d = truth.x;
    let expected = 0.01 * d * 1.005 / 0.4; // the right wheel travels d·(1 + 0.01/2) on average
    assert!(truth.theta.abs() < 0.01, "truth turned: {}", truth.theta);
    assert!(
        (last.odometry.theta - expected).abs() < 0.05 * expected,
        "odometry heading {} vs {expected}",
        last.odometry.theta
    );
}

fn assert_never_inside(records: &[Record], stats: &DriveStats, world: &World, name: &str) {
    assert_eq!(
        stats.contact_steps, 0,
        "{name}: the robot touched an obstacle"
    );
    assert!(
        stats.min_clearance_m > 0.33,
        "{name}: clearance {}",
        stats.min_clearance_m
    );
    for r in records {
        let t = r.truth.expect("truth");
        let d = world.signed_distance(&nalgebra::Point2::new(t.x, t.y));
        assert!(
            d > 0.33,
            "{name}: at t = {} the robot is {d} m from an obstacle",
            t.x
        );
    }
}

#[test]
fn park_drive_is_realistic() {
    let (records, stats, world) = run(shipped("park.toml"));
    let s = DriveScores::of(&records);
    assert_never_inside(&records, &stats, &world, "park");
    // About 800 scans at 1 Hz, one clockwise loop back to the start.
    assert!((700..=900).contains(&s.scans), "{s:?}");
    assert!(stats.route_completed);
    assert!(s.loop_gap_m < 0.5, "{s:?}");
    assert!(s.path_length_m > 150.0, "{s:?}");
    // Starts in the bottom-right corner; the loop is clockwise (negative signed area).
    let start = records[0].truth.expect("truth");
    let (lo, hi) = world.bounds;
    let (w, h) = (hi.x - lo.x, hi.y - lo.y);
    assert!(
        start.x > lo.x + 0.6 * w && start.y < lo.y + 0.4 * h,
        "{start:?}"
    );
    let area: f64 = records
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0].truth.expect("t"), w[1].truth.expect("t"));
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        / 2.0;
    assert!(area < -1000.0, "signed area {area}");
    // Poor odometry, sparse laser.
    assert!(s.odometry_final_error_m > 3.0, "{s:?}");
    assert!(s.returns_fraction < 0.15, "{s:?}");
}

#[test]
fn corridor_drive_is_dense_and_odometry_better_than_in_the_park() {
    let (records, stats, world) = run(shipped("corridor.toml"));
    let s = DriveScores::of(&records);
    assert_never_inside(&records, &stats, &world, "corridor");
    assert!(stats.route_completed);
    assert!(s.loop_gap_m < 0.5, "{s:?}");
    assert!(s.returns_fraction > 0.8, "{s:?}");
    assert!(s.odometry_final_error_m < 2.0, "{s:?}");
    // The robot zigzags: its heading swings both ways on every side of the corridor.
    let turns = records
        .windows(2)
        .filter(|w| {
            let (a, b) = (w[0].truth.expect("t"), w[1].truth.expect("t"));
            qicp_core::normalize_angle(b.theta - a.theta).abs() > 0.2
        })
        .count();
    assert!(turns > 20, "only {turns} turns");
}
