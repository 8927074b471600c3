//! Bad CARMEN input gets a clear error naming the line, or a counted skip, never a panic; the
//! streaming reader gives the records of a whole-log sort in bounded memory.

use qicp::logs::LogError;
use qicp::logs::carmen::{CarmenOptions, CarmenReader, read_carmen_from};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const STRICT: CarmenOptions = CarmenOptions {
    lenient: false,
    flaser_fov_deg: None,
    max_range: None,
    min_range: 0.0,
    laser_offset: None,
    truepos_max_dt: qicp::logs::carmen::DEFAULT_TRUEPOS_MAX_DT,
    max_beams: qicp::logs::carmen::DEFAULT_MAX_BEAMS,
    // The reorder tests here sort by time; file order is the default (tests/logs_formats.rs).
    order: qicp::logs::carmen::RecordOrder::Time,
    reorder_window: qicp::logs::carmen::DEFAULT_REORDER_WINDOW,
    reorder_records: qicp::logs::carmen::DEFAULT_REORDER_RECORDS,
};

fn read(text: &str, opts: &CarmenOptions) -> Result<qicp::logs::carmen::CarmenLog, LogError> {
    read_carmen_from(&mut text.as_bytes(), "test.clf", opts)
}

/// A `FLASER` line of `n` beams of 2 m at time `t`, odometry x = `x`.
fn flaser(n: usize, t: f64, x: f64) -> String {
    let ranges = vec!["2.0"; n].join(" ");
    format!("FLASER {n} {ranges} {x} 0 0 {x} 0 0 {t} host {t}\n")
}

/// The error of a strict read, as text; panics if the read succeeds.
fn refusal(text: &str) -> String {
    match read(text, &STRICT) {
        Ok(log) => panic!("accepted, {} records", log.records.len()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn num_readings_near_usize_max_is_refused_not_a_panic() {
    let line = "FLASER 18446744073709551615 1 2 3 0 0 0 0 0 0 1.0 host 1.0\n";
    let why = refusal(line);
    assert!(
        why.contains("test.clf:1") && why.contains("beams per scan"),
        "{why}"
    );
    // Lenient: skipped and counted, not a panic.
    let log = read(
        &format!("{line}{}", flaser(3, 2.0, 0.0)),
        &CarmenOptions {
            lenient: true,
            ..STRICT
        },
    )
    .expect("lenient read");
    assert_eq!((log.records.len(), log.info.skipped_lines), (1, 1));
}

#[test]
fn readings_above_max_beams_are_refused() {
    let opts = CarmenOptions {
        max_beams: 100,
        ..STRICT
    };
    let why = read(&flaser(101, 1.0, 0.0), &opts)
        .expect_err("101 beams over a limit of 100")
        .to_string();
    assert!(why.contains("101 readings") && why.contains("100"), "{why}");
    assert!(read(&flaser(100, 1.0, 0.0), &opts).is_ok());
}

#[test]
fn remission_count_near_usize_max_is_refused_not_a_panic() {
    let line = "ROBOTLASER1 0 -1.5 3.0 1.0 80 0.01 0 3 1 1 1 18446744073709551615 \
                0 0 0 0 0 0 0 0 0 0 0 5.0 host 5.0\n";
    let why = refusal(line);
    assert!(why.contains("remissions announced"), "{why}");
}

#[test]
fn param_fov_outside_0_to_360_degrees_is_refused() {
    for fov in ["0", "-180", "1e6", "nan"] {
        let why = refusal(&format!(
            "PARAM laser_front_laser_fov {fov} host 0\n{}",
            flaser(3, 1.0, 0.0)
        ));
        assert!(why.contains("laser_front_laser_fov"), "fov {fov}: {why}");
    }
}

#[test]
fn param_max_range_that_is_not_positive_is_refused() {
    let why = refusal(&format!(
        "PARAM robot_front_laser_max -3 host 0\n{}",
        flaser(3, 1.0, 0.0)
    ));
    assert!(why.contains("robot_front_laser_max"), "{why}");
}

#[test]
fn robotlaser_angular_resolution_zero_is_refused() {
    let line = "ROBOTLASER1 0 -1.5 3.0 0 80 0.01 0 3 1 1 1 0 \
                0 0 0 0 0 0 0 0 0 0 0 5.0 host 5.0\n";
    let why = refusal(line);
    assert!(why.contains("angular_res"), "{why}");
    // Beams spanning more than a full turn cannot be one sweep either.
    let line = "ROBOTLASER1 0 -1.5 3.0 4 80 0.01 0 3 1 1 1 0 \
                0 0 0 0 0 0 0 0 0 0 0 5.0 host 5.0\n";
    assert!(refusal(line).contains("full turn"));
}

/// `start_angle = 1e308` used to be accepted (adding the beam step to it changes nothing, so
/// every beam pointed one way), and so were a fov of 0 or −1.
#[test]
fn robotlaser_start_angle_beyond_a_turn_and_a_fov_outside_0_to_2pi_are_refused() {
    let line = |start: &str, fov: &str| {
        format!(
            "ROBOTLASER1 0 {start} {fov} 0.01 80 0.01 0 3 1 1 1 0 \
             0 0 0 0 0 0 0 0 0 0 0 5.0 host 5.0\n"
        )
    };
    for start in ["1e308", "-7.0"] {
        let why = refusal(&line(start, "3.0"));
        assert!(why.contains("start_angle"), "{why}");
    }
    for fov in ["0", "-1", "7.0"] {
        let why = refusal(&line("-1.5", fov));
        assert!(why.contains("fov"), "{why}");
    }
    read(&line("-1.5", "3.0"), &STRICT).expect("a sane line reads");
}

#[test]
fn poses_beyond_the_map_coordinate_limit_are_refused() {
    let why = refusal(&flaser(3, 1.0, 3e9));
    assert!(why.contains("beyond"), "{why}");
}

#[test]
fn cr_only_line_endings_are_reported_not_read_as_nothing() {
    let text = flaser(3, 1.0, 0.0).replace('\n', "\r") + &flaser(3, 2.0, 0.0).replace('\n', "\r");
    let why = refusal(&text);
    assert!(why.contains("CR-only"), "{why}");
}

#[test]
fn param_changing_the_flaser_layout_after_scans_is_an_error() {
    let text = format!(
        "{}PARAM laser_front_laser_fov 90 host 0\n{}",
        flaser(3, 1.0, 0.0),
        flaser(3, 2.0, 0.0)
    );
    let why = refusal(&text);
    assert!(
        why.contains("test.clf:2") && why.contains("changes the FLASER layout"),
        "{why}"
    );
    // Repeating the value in force is harmless.
    let text = format!(
        "{}PARAM laser_front_laser_fov 180 host 0\n{}",
        flaser(3, 1.0, 0.0),
        flaser(3, 2.0, 0.0)
    );
    assert_eq!(read(&text, &STRICT).expect("same layout").records.len(), 2);
}

/// The brute-force twin of the streaming reader: laser lines jittered in time by less than
/// the reorder window come out in the order of a stable sort by time, ties in file order.
#[test]
fn streaming_reader_gives_the_order_of_a_whole_log_sort() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for round in 0..20 {
        let n = rng.random_range(1..400);
        let mut text = String::new();
        let mut expected = Vec::new();
        for i in 0..n {
            // 10 Hz with jitter up to ±1 s, and some repeated timestamps.
            let mut t = 0.1 * i as f64 + rng.random_range(-1.0..1.0);
            if rng.random_bool(0.1) {
                t = (t * 2.0).round() / 2.0;
            }
            text += &flaser(3, t, i as f64);
            expected.push((t, i as f64));
        }
        expected.sort_by(|a, b| a.0.total_cmp(&b.0));
        let opts = CarmenOptions {
            reorder_window: 2.5,
            ..STRICT
        };
        let got: Vec<(f64, f64)> = CarmenReader::new(text.as_bytes(), "jitter.clf", &opts)
            .expect("reader")
            .map(|r| {
                let r = r.expect("record");
                (r.timestamp(), r.odometry.x)
            })
            .collect();
        assert_eq!(got, expected, "round {round}");
    }
}

#[test]
fn lines_later_than_the_reorder_window_are_dropped_and_counted() {
    let mut text = String::new();
    for i in 0..100 {
        text += &flaser(3, i as f64 * 0.1, 0.0);
    }
    text += &flaser(3, 0.05, 0.0); // 9.9 s late
    let mut reader = CarmenReader::new(text.as_bytes(), "late.clf", &STRICT).expect("reader");
    let times: Vec<f64> = (&mut reader)
        .map(|r| r.expect("record").timestamp())
        .collect();
    assert_eq!(times.len(), 100);
    assert!(times.windows(2).all(|w| w[0] <= w[1]));
    assert_eq!(reader.info.late, 1);
    assert!(reader.info.report().contains("dropped 1 laser lines"));
}

#[test]
fn reorder_buffer_stays_bounded_when_timestamps_stand_still() {
    let mut text = String::new();
    for i in 0..3000 {
        text += &flaser(3, 1.0, i as f64);
    }
    let opts = CarmenOptions {
        reorder_records: 50,
        ..STRICT
    };
    let mut reader = CarmenReader::new(text.as_bytes(), "still.clf", &opts).expect("reader");
    let first = reader.next().expect("a record").expect("record");
    // The first record leaves once the buffer overflows, long before the end of the log.
    let pending = format!("{reader:?}");
    assert!(pending.contains("pending: 50"), "{pending}");
    assert_eq!(first.odometry.x, 0.0);
    let xs: Vec<f64> = reader.map(|r| r.expect("record").odometry.x).collect();
    assert_eq!(xs.len(), 2999);
    assert!(
        xs.windows(2).all(|w| w[0] < w[1]),
        "file order kept for equal times"
    );
}

#[test]
fn truepos_attaches_to_the_nearest_record_while_streaming() {
    let mut text = String::new();
    for i in 0..200 {
        let t = i as f64 * 0.2;
        text += &flaser(3, t, 0.0);
        // Ground truth 50 ms after each scan, x = i.
        let tt = t + 0.05;
        text += &format!("TRUEPOS {i} 0 0 0 0 0 {tt} host {tt}\n");
    }
    let reader = CarmenReader::new(text.as_bytes(), "truth.clf", &STRICT).expect("reader");
    for (i, r) in reader.enumerate() {
        let truth = r.expect("record").truth.expect("truth attached");
        assert_eq!(truth.x, i as f64);
    }
}

#[test]
fn an_error_ends_the_stream() {
    let text = format!(
        "{}FLASER 3 1 2\n{}",
        flaser(3, 1.0, 0.0),
        flaser(3, 2.0, 0.0)
    );
    let items: Vec<_> = CarmenReader::new(text.as_bytes(), "bad.clf", &STRICT)
        .expect("reader")
        .collect();
    assert_eq!(items.len(), 1);
    let why = items[0]
        .as_ref()
        .expect_err("the malformed line")
        .to_string();
    assert!(why.contains("bad.clf:2"), "{why}");
}

#[test]
fn truepos_without_laser_lines_is_held_within_the_window() {
    let mut text = String::new();
    for i in 0..20_000 {
        let t = i as f64 * 0.1;
        text += &format!("TRUEPOS 0 0 0 0 0 0 {t} host {t}\n");
    }
    let mut reader = CarmenReader::new(text.as_bytes(), "truth.clf", &STRICT).expect("reader");
    assert!(reader.next().is_none());
    // The last 5.1 s of truth (52 lines at 10 Hz) are held, not all 20,000 lines.
    let held: usize = format!("{reader:?}")
        .split("truepos: ")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .and_then(|n| n.trim().parse().ok())
        .expect("truepos count in Debug");
    assert!(held <= 52, "{held} truth lines held");
}

/// A UTF-8 byte-order mark before the first line used to turn its tag into an unknown type,
/// and the record was lost without a word: the mark is dropped, and records of types qicp
/// does not read (a misspelt tag among them) are counted where the run's notes list them.
#[test]
fn a_byte_order_mark_is_not_part_of_the_first_tag_and_unknown_tags_are_counted() {
    let text = format!(
        "\u{feff}{}{}{}",
        flaser(5, 1.0, 0.0),
        flaser(5, 2.0, 0.1).replacen("FLASER", "FLASR", 1),
        flaser(5, 3.0, 0.2)
    );
    let log = read(&text, &STRICT).expect("read");
    assert_eq!(log.records.len(), 2);
    assert_eq!(log.records[0].timestamp(), 1.0);
    assert_eq!(log.info.unknown_types.get("FLASR"), Some(&1));
    assert!(
        log.info.report().contains("1 FLASR"),
        "{}",
        log.info.report()
    );
}
