//! Bad configurations are refused with a message naming the key; shipped ones load.

use qicp_sim::{ConfigError, SimConfig, Simulation};
use std::path::PathBuf;

fn refused(text: &str) -> String {
    match SimConfig::from_toml_str(text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

fn invalid_key(text: &str) -> String {
    match SimConfig::from_toml_str(text) {
        Err(ConfigError::Invalid { key, .. }) => key,
        other => panic!("expected an invalid value, got {other:?}"),
    }
}

#[test]
fn unknown_world_kind_is_refused_naming_the_kind() {
    let msg = refused("[world]\nkind = \"forest\"\n");
    assert!(msg.contains("kind") && msg.contains("forest"), "{msg}");
    assert!(msg.contains("park") && msg.contains("corridor"), "{msg}");
}

#[test]
fn zero_beams_are_refused() {
    assert_eq!(invalid_key("[laser]\nbeams = 0\n"), "laser.beams");
    let msg = refused("[laser]\nbeams = 0\n");
    assert!(msg.contains("laser.beams"), "{msg}");
}

#[test]
fn negative_ranges_are_refused() {
    assert_eq!(
        invalid_key("[laser]\nmax_range = -5.0\n"),
        "laser.max_range"
    );
    assert_eq!(
        invalid_key("[laser]\nmin_range = -0.1\n"),
        "laser.min_range"
    );
    assert_eq!(
        invalid_key("[laser]\nrange_sigma = -0.1\n"),
        "laser.range_sigma"
    );
}

#[test]
fn unknown_keys_are_refused_by_name() {
    for (text, key) in [
        ("[laser]\nbeam_count = 181\n", "beam_count"),
        ("[robot]\ncolour = \"red\"\n", "colour"),
        ("[world.park]\nflowers = 3\n", "flowers"),
        ("[weather]\nrain = true\n", "weather"),
        (
            "[world]\nkind = \"custom\"\n[[world.obstacles]]\nkind = \"circle\"\ncenter = [1.0, 2.0]\nradius = 0.5\nheight = 2.0\n[drive]\nwaypoints = [[0.0, 0.0], [1.0, 0.0]]\n",
            "height",
        ),
    ] {
        let msg = refused(text);
        assert!(msg.contains(key), "`{key}` not named in: {msg}");
    }
}

#[test]
fn parameters_of_another_world_kind_are_refused() {
    assert_eq!(
        invalid_key("[world]\nkind = \"park\"\n[world.corridor]\ncorridor_width = 2.0\n"),
        "world.corridor"
    );
    assert_eq!(
        invalid_key("[world]\nkind = \"custom\"\n"),
        "drive.waypoints"
    );
}

#[test]
fn other_impossible_values_name_their_key() {
    assert_eq!(
        invalid_key("[robot]\nground_friction = 0.0\n"),
        "robot.ground_friction"
    );
    assert_eq!(invalid_key("[laser]\nfov_deg = 400.0\n"), "laser.fov_deg");
    assert_eq!(invalid_key("[laser]\nrate_hz = 0.0\n"), "laser.rate_hz");
    assert_eq!(invalid_key("[drive]\nspeed = 5.0\n"), "drive.speed");
    assert_eq!(invalid_key("[drive]\nmax_scans = 0\n"), "drive.max_scans");
    assert_eq!(
        invalid_key("[world]\nkind = \"corridor\"\n[world.corridor]\nzigzag_amplitude = 1.5\n"),
        "world.corridor.zigzag_amplitude"
    );
}

#[test]
fn simulation_refuses_an_invalid_config_without_panicking() {
    let mut cfg = SimConfig::default();
    cfg.laser.beams = 0;
    assert!(Simulation::new(cfg).is_err());
}

#[test]
fn defaults_and_shipped_configs_load_and_round_trip() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/worlds");
    let mut found = 0;
    for entry in std::fs::read_dir(&dir).expect("configs/worlds") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            let cfg = SimConfig::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let back = SimConfig::from_toml_str(&cfg.to_toml_string().expect("toml"))
                .expect("effective config reloads");
            assert_eq!(back, cfg, "{}", path.display());
            found += 1;
        }
    }
    assert!(found >= 2);
    let d = SimConfig::default();
    d.validate().expect("defaults are valid");
    assert_eq!(SimConfig::from_toml_str("").expect("empty"), d);
}

/// Values that used to crash the simulator (a capacity overflow, an allocation abort) or
/// hang it are refused up front, naming the key; the bounds themselves still run.
#[test]
fn values_that_crashed_or_hung_the_simulator_are_refused_by_key() {
    let corridor = "[world]\nkind = \"corridor\"\n[world.corridor]\n";
    for (text, key) in [
        ("[laser]\nbeams = 9223372036854775807\n", "laser.beams"),
        ("[laser]\nbeams = 10001\n", "laser.beams"),
        ("[world.park]\nsize = [1e308, 1e308]\n", "world.park.size"),
        ("[world.park]\nsize = [nan, 40.0]\n", "world.park.size"),
        ("[world.park]\nsize = [1000.5, 40.0]\n", "world.park.size"),
        ("[robot]\nsize = [nan, 0.4]\n", "robot.size"),
        ("[robot]\nsize = [0.5, nan]\n", "robot.size"),
        ("[robot]\nencoder_noise = 1e308\n", "robot.encoder_noise"),
        ("[laser]\nrate_hz = 1e-308\n", "laser.rate_hz"),
        (
            "[drive]\nwaypoint_tolerance = 1e5\n",
            "drive.waypoint_tolerance",
        ),
    ] {
        assert_eq!(invalid_key(text), key, "{text}");
    }
    for (line, key) in [
        ("size = [1e308, 1e308]", "world.corridor.size"),
        ("zigzag_period = 1e-308", "world.corridor.zigzag_period"),
        ("wall_thickness = 100000.0", "world.corridor.wall_thickness"),
        ("wall_thickness = 1.2", "world.corridor.wall_thickness"),
        ("door_offset = -0.5", "world.corridor.door_offset"),
        ("door_offset = nan", "world.corridor.door_offset"),
        ("closed_doors = 1.5", "world.corridor.closed_doors"),
        ("closed_doors = nan", "world.corridor.closed_doors"),
        ("furniture = 21", "world.corridor.furniture"),
    ] {
        assert_eq!(invalid_key(&format!("{corridor}{line}\n")), key, "{line}");
    }
    // Huge numbers are shown in exponent form, not in 309 digits.
    let msg = refused("[robot]\nencoder_noise = 1e308\n");
    assert!(msg.contains("1e308") && msg.len() < 200, "{msg}");
    for text in [
        "[laser]\nbeams = 10000\n".to_string(),
        "[world.park]\nsize = [1000.0, 1000.0]\n".to_string(),
        "[robot]\nencoder_noise = 1.0\n".to_string(),
        "[laser]\nrate_hz = 0.01\n".to_string(),
        format!("{corridor}zigzag_period = 0.1\nwall_thickness = 1.19\n"),
        format!("{corridor}door_offset = 100.0\nclosed_doors = 1.0\nfurniture = 20\n"),
    ] {
        SimConfig::from_toml_str(&text).unwrap_or_else(|e| panic!("{text}: {e}"));
    }
}

#[test]
fn foliage_without_a_positive_mean_free_path_is_refused_by_key() {
    for mfp in ["0.0", "-0.3", "nan", "inf"] {
        let text = format!(
            "[world]\nkind = \"custom\"\n[[world.obstacles]]\nkind = \"foliage\"\n\
             center = [3.0, 0.0]\nhalf_size = [1.0, 1.0]\nmean_free_path = {mfp}\n\
             [drive]\nwaypoints = [[0.0, 0.0], [1.0, 0.0]]\n"
        );
        assert_eq!(invalid_key(&text), "world.obstacles", "{mfp}");
        assert!(refused(&text).contains("mean_free_path"), "{mfp}");
        assert_eq!(
            invalid_key(&format!("[world.park]\nhedge_mean_free_path = {mfp}\n")),
            "world.park.hedge_mean_free_path",
            "{mfp}"
        );
    }
}
