//! CARMEN and TUM readers and writers on small logs made here: every record type, unsorted
//! input, bzip2, malformed lines, NaN ranges, round trips; and `qicp eval` on files.
#![allow(clippy::unwrap_used)] // tests: a panic is the failure report

use bzip2::Compression;
use bzip2::write::BzEncoder;
use qicp::logs::LogError;
use qicp::logs::carmen::{
    CarmenLog, CarmenOptions, RecordOrder, read_carmen, read_carmen_from, write_carmen,
};
use qicp::logs::tum::{read_tum, write_tum};
use qicp_core::{BeamGeometry, BeamStatus, Pose2, Record, Scan, normalize_angle};
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Write;
use std::path::PathBuf;

/// A scratch directory of its own for each test.
fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qicp-logs-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn read_str(text: &str, opts: &CarmenOptions) -> Result<CarmenLog, LogError> {
    read_carmen_from(&mut text.as_bytes(), "test.clf", opts)
}

fn flaser(ranges: &[f64], odom: (f64, f64, f64), t: f64) -> String {
    let r: Vec<String> = ranges.iter().map(f64::to_string).collect();
    format!(
        "FLASER {} {} {} {} {} {} {} {} {t} host {t}",
        ranges.len(),
        r.join(" "),
        odom.0,
        odom.1,
        odom.2,
        odom.0,
        odom.1,
        odom.2
    )
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

const EVERY_TYPE: &str = "\
# a comment
# message formats defined: PARAM SYNC ODOM FLASER RLASER ROBOTLASER1 TRUEPOS
PARAM robot_frontlaser_offset 0.25 nohost 0
PARAM robot_front_laser_max 30 nohost 0
PARAM laser_front_laser_fov 90 nohost 0
SYNC tag 1.0 host 1.0

ODOM 1 2 0.5 0.1 0.2 0 10.0 host 0.1
FLASER 5 1 2 3 30 40 1 2 0.5 1 2 0.5 10.05 host 0.2
RLASER 3 1 2 3 0 0 0 0 0 0 10.06 host 0.2
TRUEPOS 1.1 2.1 0.51 1 2 0.5 10.06 host 0.2
ROBOTLASER1 0 -1.5 3.0 0.75 20 0.01 0 5 1 2 3 4 25 2 7 7 1.5 2.5 0.2 1 2 0.2 0 0 0 0 0 10.2 host 0.3
ODOM 1 2 0.2 0 0 0 10.3 host 0.4
TRUEPOS 1.2 2.2 0.21 1 2 0.2 10.25 host 0.4
SYNC tag 11.0 host 1.0
";

#[test]
fn every_record_type_is_read() {
    let log = read_str(EVERY_TYPE, &CarmenOptions::default()).unwrap();
    println!("{}", log.report());
    assert_eq!(log.records.len(), 2);
    assert_eq!(log.info.counts.get("FLASER"), Some(&1));
    assert_eq!(log.info.counts.get("ROBOTLASER1"), Some(&1));
    assert_eq!(log.info.counts.get("ODOM"), Some(&2));
    assert_eq!(log.info.counts.get("TRUEPOS"), Some(&2));
    assert_eq!(log.info.counts.get("PARAM"), Some(&3));
    assert_eq!(log.info.unknown_types.get("SYNC"), Some(&2));
    assert_eq!(log.info.unknown_types.get("RLASER"), Some(&1));
    assert!(log.report().contains("2 SYNC"));
    assert_eq!(log.odometry.len(), 2);
    assert_eq!(log.odometry[0], (10.0, Pose2::new(1.0, 2.0, 0.5)));
    assert_eq!(
        log.info
            .params
            .get("laser_front_laser_fov")
            .map(String::as_str),
        Some("90")
    );

    // FLASER: geometry from the PARAMs (90°, 30 m, laser 0.25 m ahead), odometry from odom_*.
    let f = &log.records[0];
    assert_eq!(f.timestamp(), 10.05);
    assert_eq!(f.odometry, Pose2::new(1.0, 2.0, 0.5));
    assert_eq!(f.laser_offset, Pose2::new(0.25, 0.0, 0.0));
    let g = f.scan.geometry;
    assert!(close(g.angle_min, -PI / 4.0) && close(g.angle_increment, PI / 8.0));
    assert_eq!(g.max_range, 30.0);
    assert_eq!(f.scan.ranges(), &[1.0, 2.0, 3.0, 30.0, 40.0]);
    assert_eq!(f.scan.status_counts(), [3, 2, 0, 0]);
    // TRUEPOS at 10.06 is nearest to the FLASER at 10.05.
    assert_eq!(f.truth, Some(Pose2::new(1.1, 2.1, 0.51)));

    // ROBOTLASER1: geometry from the line, laser pose in the robot frame, robot pose as odometry.
    let r = &log.records[1];
    assert_eq!(r.timestamp(), 10.2);
    assert_eq!(r.odometry, Pose2::new(1.0, 2.0, 0.2));
    let g = r.scan.geometry;
    assert_eq!(
        (g.angle_min, g.angle_increment, g.max_range),
        (-1.5, 0.75, 20.0)
    );
    assert_eq!(r.scan.status_counts(), [4, 1, 0, 0]);
    let expect = Pose2::new(1.0, 2.0, 0.2).between(&Pose2::new(1.5, 2.5, 0.2));
    assert!((r.laser_offset.x - expect.x).abs() < 1e-12);
    assert!((r.laser_offset.y - expect.y).abs() < 1e-12);
    assert!(r.laser_offset.theta.abs() < 1e-12);
    assert_eq!(r.truth, Some(Pose2::new(1.2, 2.2, 0.21)));
}

#[test]
fn explicit_options_win_over_params() {
    let opts = CarmenOptions {
        flaser_fov_deg: Some(180.0),
        max_range: Some(35.0),
        laser_offset: Some(Pose2::new(0.1, 0.0, 0.0)),
        truepos_max_dt: 0.001,
        ..CarmenOptions::default()
    };
    let log = read_str(EVERY_TYPE, &opts).unwrap();
    let g = log.records[0].scan.geometry;
    assert!(close(g.angle_min, -FRAC_PI_2) && close(g.angle_increment, PI / 4.0));
    assert_eq!(g.max_range, 35.0);
    assert_eq!(log.records[0].laser_offset, Pose2::new(0.1, 0.0, 0.0));
    // The explicit maximum range applies to ROBOTLASER1 lines too.
    assert_eq!(log.records[1].scan.geometry.max_range, 35.0);
    // TRUEPOS 10 ms away from the FLASER is too far now.
    assert_eq!(log.records[0].truth, None);

    let bad = CarmenOptions {
        max_range: Some(-1.0),
        ..CarmenOptions::default()
    };
    assert!(matches!(
        read_str(EVERY_TYPE, &bad),
        Err(LogError::InvalidOption {
            name: "max_range",
            ..
        })
    ));
}

#[test]
fn defaults_without_params_and_any_beam_count() {
    for beams in [1usize, 7, 180, 181, 360, 361, 1081] {
        let ranges: Vec<f64> = (0..beams).map(|i| 1.0 + i as f64 * 0.01).collect();
        let text = flaser(&ranges, (0.0, 0.0, 0.0), 5.0);
        let log = read_str(&text, &CarmenOptions::default()).unwrap();
        let s = &log.records[0].scan;
        assert_eq!(s.beams(), beams);
        let g = s.geometry;
        assert_eq!(g.max_range, 81.0);
        assert!(close(g.angle_min, -FRAC_PI_2), "{beams}: {g:?}");
        let last = g.angle(beams - 1);
        let expect = match beams {
            1 => -FRAC_PI_2,
            180 => 89f64.to_radians(),
            360 => 89.5f64.to_radians(),
            _ => FRAC_PI_2,
        };
        assert!(close(last, expect), "{beams}: last beam at {last}");
    }
}

/// 40 `FLASER` scans of 180 beams under `PARAM robot_front_laser_max 30`, their ranges
/// spread over 1-28 m, with every fifth beam reading `code` where one is given.
fn coded_log(code: Option<f64>) -> String {
    let mut text = String::from("PARAM robot_front_laser_max 30 nohost 0\n");
    for scan in 0..40 {
        let ranges: Vec<f64> = (0..180)
            .map(|i| match code {
                Some(c) if i % 5 == 0 => c,
                _ => 1.0 + ((i * 7 + scan * 3) % 2700) as f64 / 100.0,
            })
            .collect();
        text += &flaser(&ranges, (0.0, 0.0, 0.0), f64::from(scan));
        text += "\n";
    }
    text
}

#[test]
fn a_no_return_code_below_the_declared_max_range_is_found() {
    let log = read_str(&coded_log(Some(29.5)), &CarmenOptions::default()).unwrap();
    let (range, count, per_cm) = log.info.ranges.no_return_code().expect("found");
    assert!(
        close(range, 29.5) && count == 40 * 36 && per_cm == 0.0,
        "{range} {count} {per_cm}"
    );
    // The maximum range the warning names drops the code, and nothing stands out then.
    let below = CarmenOptions {
        max_range: Some(29.495),
        ..CarmenOptions::default()
    };
    let log = read_str(&coded_log(Some(29.5)), &below).unwrap();
    assert_eq!(log.info.ranges.no_return_code(), None);
    assert_eq!(log.records[0].scan.valid_count(), 180 - 36);
    // Ranges spread as a room's are: no code.
    let log = read_str(&coded_log(None), &CarmenOptions::default()).unwrap();
    assert_eq!(log.info.ranges.no_return_code(), None);
}

/// `coded_log` without its `PARAM robot_front_laser_max`: the log does not say its maximum
/// range, and the reader's 81 m is a guess.
fn undeclared(text: &str) -> String {
    text.lines()
        .filter(|l| !l.starts_with("PARAM robot_front_laser_max"))
        .map(|l| format!("{l}\n"))
        .collect()
}

/// Read by path, a log that does not give its maximum range is probed at its head for a
/// no-return code: one found is read as no-returns from the first record on, and the log's
/// info says which and why. A maximum range the options give, or the log declares, is read
/// as given: the code is then read as points, and the read's counts name it.
#[test]
fn a_no_return_code_at_the_head_of_a_log_is_read_as_no_returns() {
    let path = scratch("probe").join("coded.clf");
    std::fs::write(&path, undeclared(&coded_log(Some(50.0)))).unwrap();
    let log = read_carmen(&path, &CarmenOptions::default()).unwrap();
    let code = log.info.no_return_code.expect("a code");
    assert!(
        close(code.range, 50.0) && code.count == 40 * 36 && code.records == 40,
        "{code:?}"
    );
    assert!(close(code.max_range(), 49.995), "{code:?}");
    for r in &log.records {
        assert_eq!(r.scan.valid_count(), 180 - 36);
        assert!(close(r.scan.geometry.max_range, 49.995));
    }
    assert_eq!(log.info.ranges.no_return_code(), None);
    // The streaming reader reads the same.
    let streamed: Vec<Record> =
        qicp::logs::carmen::CarmenReader::open(&path, &CarmenOptions::default())
            .unwrap()
            .map(Result::unwrap)
            .collect();
    assert_eq!(streamed, log.records);
    // The guess given as the maximum: the code is read as points, and the counts name it.
    let given = CarmenOptions {
        max_range: Some(81.0),
        ..CarmenOptions::default()
    };
    let log = read_carmen(&path, &given).unwrap();
    assert_eq!(log.info.no_return_code, None);
    assert_eq!(log.records[0].scan.valid_count(), 180);
    assert!(log.info.ranges.no_return_code().is_some());
    // A log that declares its maximum is read as it says.
    std::fs::write(&path, coded_log(Some(29.5))).unwrap();
    let log = read_carmen(&path, &CarmenOptions::default()).unwrap();
    assert_eq!(log.info.no_return_code, None);
    assert_eq!(log.records[0].scan.valid_count(), 180);
    assert!(log.info.ranges.no_return_code().is_some());
    // A log without a code is read as it is.
    std::fs::write(&path, undeclared(&coded_log(None))).unwrap();
    let log = read_carmen(&path, &CarmenOptions::default()).unwrap();
    assert_eq!(log.info.no_return_code, None);
    assert!(close(log.records[0].scan.geometry.max_range, 81.0));
}

/// A robot standing still reads its farthest return, through a door, in the same beam again
/// and again: many readings of one range far above the metre below it, as a code would give,
/// but in one beam, where a code stands wherever a beam finds nothing. It stays a point.
#[test]
fn a_far_return_a_standing_robot_reads_again_is_not_a_no_return_code() {
    let mut text = String::new();
    for scan in 0..300 {
        let ranges: Vec<f64> = (0..180)
            .map(|i| {
                if i == 90 {
                    27.9
                } else {
                    1.0 + f64::from(i % 45) * 0.2
                }
            })
            .collect();
        text += &flaser(&ranges, (0.0, 0.0, 0.0), f64::from(scan) * 0.2);
        text += "\n";
    }
    let path = scratch("standing").join("door.clf");
    std::fs::write(&path, &text).unwrap();
    let log = read_carmen(&path, &CarmenOptions::default()).unwrap();
    // The whole log's counts would call it a code; the probe's beams do not.
    assert!(log.info.ranges.no_return_code().is_some());
    assert_eq!(log.info.no_return_code, None);
    assert_eq!(log.records[0].scan.valid_count(), 180);
}

/// Laser lines whose timestamps run back, and two ODOM lines out of order.
fn jittered_log() -> String {
    [
        flaser(&[1.0; 3], (3.0, 0.0, 0.0), 3.0),
        flaser(&[1.0; 3], (1.0, 0.0, 0.0), 1.0),
        flaser(&[1.0; 3], (2.0, 0.0, 0.0), 2.0),
        flaser(&[1.0; 3], (2.5, 0.0, 0.0), 2.0),
        "ODOM 9 0 0 0 0 0 9 h 9".to_string(),
        "ODOM 8 0 0 0 0 0 8 h 8".to_string(),
    ]
    .join("\n")
}

/// Each record's time and odometry x, in the order read.
fn times_and_x(log: &CarmenLog) -> Vec<(f64, f64)> {
    log.records
        .iter()
        .map(|r| (r.timestamp(), r.odometry.x))
        .collect()
}

#[test]
fn records_come_in_file_order_by_default_and_jitter_is_counted() {
    let log = read_str(&jittered_log(), &CarmenOptions::default()).unwrap();
    assert_eq!(
        times_and_x(&log),
        [(3.0, 3.0), (1.0, 1.0), (2.0, 2.0), (2.0, 2.5)]
    );
    assert_eq!(log.info.out_of_order, 1);
    assert_eq!(log.info.late, 0);
    assert_eq!(log.info.span, Some((1.0, 3.0)));
    assert!(
        log.report()
            .contains("out of time order (kept in file order)")
    );
    assert_eq!(log.odometry[0].0, 8.0, "ODOM lines are sorted by time");
}

/// In file order a record whose stamp runs back still finds its `TRUEPOS`, given before or
/// after it in the file: the truths of the window are kept, not those after the record
/// delivered last.
#[test]
fn jittered_records_in_file_order_keep_their_ground_truth() {
    let text = [
        flaser(&[1.0; 3], (0.0, 0.0, 0.0), 2.0),
        "TRUEPOS 20 0 0 0 0 0 2.0 h 2.0".to_string(),
        "TRUEPOS 15 0 0 0 0 0 1.5 h 1.5".to_string(),
        flaser(&[1.0; 3], (0.0, 0.0, 0.0), 1.5),
        flaser(&[1.0; 3], (0.0, 0.0, 0.0), 3.0),
        "TRUEPOS 30 0 0 0 0 0 3.0 h 3.0".to_string(),
    ]
    .join("\n");
    for order in [RecordOrder::File, RecordOrder::Time] {
        let opts = CarmenOptions {
            order,
            ..CarmenOptions::default()
        };
        let log = read_str(&text, &opts).unwrap();
        let truths: Vec<(f64, f64)> = log
            .records
            .iter()
            .map(|r| (r.timestamp(), r.truth.expect("a truth").x))
            .collect();
        let want: &[(f64, f64)] = match order {
            RecordOrder::File => &[(2.0, 20.0), (1.5, 15.0), (3.0, 30.0)],
            RecordOrder::Time => &[(1.5, 15.0), (2.0, 20.0), (3.0, 30.0)],
        };
        assert_eq!(truths, want, "{order:?}");
    }
}

#[test]
fn time_order_sorts_records_stably() {
    let opts = CarmenOptions {
        order: RecordOrder::Time,
        ..CarmenOptions::default()
    };
    let log = read_str(&jittered_log(), &opts).unwrap();
    assert_eq!(
        times_and_x(&log),
        [(1.0, 1.0), (2.0, 2.0), (2.0, 2.5), (3.0, 3.0)]
    );
    assert_eq!(log.info.out_of_order, 1);
    assert!(log.report().contains("out of time order (sorted)"));
}

#[test]
fn nan_and_odd_ranges_are_readings_not_errors() {
    let text = "FLASER 6 1.5 nan -nan NaN inf -2 0 0 0 0 0 0 1 h 1";
    let log = read_str(text, &CarmenOptions::default()).unwrap();
    let s = &log.records[0].scan;
    assert_eq!(s.beams(), 6);
    assert!(s.ranges()[1].is_nan());
    assert_eq!(s.status()[0], BeamStatus::Valid);
    assert!(s.status()[1..].iter().all(|b| *b == BeamStatus::Invalid));
    assert_eq!(s.valid_count(), 1);
}

#[test]
fn malformed_lines_name_their_line_and_lenient_mode_counts_them() {
    let good = flaser(&[1.0; 4], (0.0, 0.0, 0.0), 1.0);
    let cases = [
        ("FLASER 4 1 1 1 1 0 0 0 0 0 0 2 h", "13 needed"),
        ("FLASER 4 1 1 1 1 0 0 zero 0 0 0 2 h 2", "not a number"),
        ("FLASER 5 1 1 1 1 0 0 0 0 0 0 2 h 2", "beam count mismatch"),
        ("FLASER 3 1 1 1 1 0 0 0 0 0 0 2 h 2", "beam count mismatch"),
        ("FLASER x 1 1 1 1 0 0 0 0 0 0 2 h 2", "not a count"),
        ("FLASER 4 1 1 1 1 0 0 0 0 0 0 nan h 2", "not finite"),
        ("ODOM 1 2", "too few fields"),
        ("TRUEPOS 1 2 3 4 5 6 7 h 7 extra", "unexpected fields"),
        ("PARAM lonely", "too few fields"),
        (
            "ROBOTLASER1 0 -1.5 3.0 0.75 20 0.01 0 5 1 2 3 4 25 3 7 7 1.5 2.5 0.2 1 2 0.2 0 0 0 0 0 10.2 host 0.3",
            "remissions",
        ),
    ];
    for (bad, why) in cases {
        let text = format!("# header\n{good}\n\n{bad}\n{good}\n");
        let err = read_str(&text, &CarmenOptions::default()).unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(&err, LogError::Malformed { line: 4, path, .. } if path == "test.clf"),
            "{bad}: {msg}"
        );
        assert!(msg.starts_with("test.clf:4: "), "{msg}");
        assert!(msg.contains(why), "{bad}: `{msg}` should say `{why}`");

        let lenient = CarmenOptions {
            lenient: true,
            ..CarmenOptions::default()
        };
        let log = read_str(&text, &lenient).unwrap();
        assert_eq!(log.info.skipped_lines, 1, "{bad}");
        assert_eq!(log.records.len(), 2);
        assert!(log.info.skipped_examples[0].contains("test.clf:4"));
        assert!(log.report().contains("skipped 1 malformed lines"));
    }
}

#[test]
fn bzip2_logs_are_recognised_by_content_and_streamed() {
    let dir = scratch("bz2");
    let text = EVERY_TYPE;
    let plain = dir.join("log.clf");
    std::fs::write(&plain, text).unwrap();
    // Two concatenated streams (as pbzip2 writes), under a name that does not say bz2.
    let packed = dir.join("log.data");
    let half = text.len() / 2;
    let half = text[..half].rfind('\n').unwrap() + 1;
    let mut bytes = Vec::new();
    for part in [&text[..half], &text[half..]] {
        let mut enc = BzEncoder::new(Vec::new(), Compression::best());
        enc.write_all(part.as_bytes()).unwrap();
        bytes.extend(enc.finish().unwrap());
    }
    assert!(bytes.starts_with(b"BZh"));
    std::fs::write(&packed, &bytes).unwrap();

    let a = read_carmen(&plain, &CarmenOptions::default()).unwrap();
    let b = read_carmen(&packed, &CarmenOptions::default()).unwrap();
    assert_eq!(a.records, b.records);
    assert_eq!(a.info.counts, b.info.counts);
    assert_eq!(a.records.len(), 2);

    let missing = read_carmen(&dir.join("absent.clf"), &CarmenOptions::default()).unwrap_err();
    assert!(matches!(missing, LogError::Io { .. }));
    assert!(missing.to_string().contains("absent.clf"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_truncated_bzip2_log_is_refused_not_read_as_a_short_log() {
    let dir = scratch("bz2-cut");
    let mut enc = BzEncoder::new(Vec::new(), Compression::best());
    enc.write_all(EVERY_TYPE.as_bytes()).unwrap();
    let bytes = enc.finish().unwrap();
    // Cut anywhere after the header: inside the block, inside the end-of-stream marker, or
    // one byte short of the whole stream.
    for cut in [10, bytes.len() / 2, bytes.len() - 10, bytes.len() - 1] {
        let path = dir.join(format!("cut{cut}.clf.bz2"));
        std::fs::write(&path, &bytes[..cut]).unwrap();
        for lenient in [false, true] {
            let opts = CarmenOptions {
                lenient,
                ..CarmenOptions::default()
            };
            let err = read_carmen(&path, &opts).unwrap_err();
            let text = err.to_string();
            assert!(text.contains(&format!("cut{cut}.clf.bz2")), "{text}");
            assert!(text.contains("EOF"), "cut {cut}, lenient {lenient}: {text}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
/// Records of a simulated drive: 181 beams over 180°, some NaN and max-range readings.
fn drive(n: usize, geometry: BeamGeometry, offset: Pose2) -> Vec<Record> {
    (0..n)
        .map(|i| {
            let f = i as f64;
            let ranges: Vec<f64> = (0..181)
                .map(|b| match (i + b) % 37 {
                    0 => f64::NAN,
                    1 => 81.9,
                    _ => 1.0 + ((f * 0.1 + b as f64 * 0.05).sin() + 1.0) * 3.1234567,
                })
                .collect();
            Record {
                scan: Scan::new(1e9 + f * 0.2 + 0.001_234_567, geometry, ranges).unwrap(),
                odometry: Pose2::new(f * 0.1, (f * 0.3).sin() / 7.0, f * 0.05),
                truth: (i % 3 != 0).then(|| Pose2::new(f * 0.1 + 1e-3, f.cos(), -f * 0.05)),
                laser_offset: offset,
            }
        })
        .collect()
}

fn assert_same(a: &[Record], b: &[Record]) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.timestamp(), y.timestamp());
        assert_eq!(x.scan.beams(), y.scan.beams());
        for (r, s) in x.scan.ranges().iter().zip(y.scan.ranges()) {
            assert!(r == s || (r.is_nan() && s.is_nan()), "{r} vs {s}");
        }
        assert_eq!(x.scan.status(), y.scan.status());
        assert_eq!(x.odometry, y.odometry);
        assert_eq!(x.truth, y.truth);
        let (g, h) = (x.scan.geometry, y.scan.geometry);
        assert!(close(g.angle_min, h.angle_min) && close(g.angle_increment, h.angle_increment));
        assert_eq!(g.max_range, h.max_range);
        let d = x.laser_offset.between(&y.laser_offset);
        assert!(d.x.abs() < 1e-12 && d.y.abs() < 1e-12 && normalize_angle(d.theta).abs() < 1e-12);
    }
}

#[test]
fn carmen_round_trip_as_flaser() {
    let geometry = BeamGeometry::centered(181, PI, 80.0);
    let records = drive(30, geometry, Pose2::new(0.3, 0.0, 0.0));
    let mut out = Vec::new();
    write_carmen(&mut out, &records).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(text.contains("PARAM robot_front_laser_max 80 "));
    assert!(text.contains("PARAM laser_front_laser_fov 180 "));
    assert_eq!(text.matches("\nFLASER 181 ").count(), 30);
    assert_eq!(text.matches("\nODOM ").count(), 30);
    assert_eq!(text.matches("\nTRUEPOS ").count(), 20);
    assert!(!text.contains("ROBOTLASER1 0"));
    let back = read_str(&text, &CarmenOptions::default()).unwrap();
    assert_eq!(back.info.skipped_lines, 0);
    assert_same(&records, &back.records);
}

#[test]
fn carmen_round_trip_falls_back_to_robotlaser1() {
    // Off-centre beams, a side-mounted and turned laser, and a record of another range.
    let skewed = BeamGeometry {
        angle_min: -2.0,
        angle_increment: 0.0123,
        max_range: 30.0,
        min_range: 0.0,
    };
    let mut records = drive(10, skewed, Pose2::new(0.2, -0.1, 0.3));
    let centred = BeamGeometry::centered(181, PI, 60.0);
    let mut more = drive(12, centred, Pose2::IDENTITY);
    more[5].scan = Scan::new(
        more[5].timestamp(),
        BeamGeometry::centered(181, PI, 40.0),
        more[5].scan.ranges().to_vec(),
    )
    .unwrap();
    more[7].laser_offset = Pose2::new(0.0, 0.1, 0.0);
    records.extend(more.into_iter().map(|mut r| {
        r.scan = Scan::new(
            r.timestamp() + 100.0,
            r.scan.geometry,
            r.scan.ranges().to_vec(),
        )
        .unwrap();
        r
    }));
    let mut out = Vec::new();
    write_carmen(&mut out, &records).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert_eq!(text.matches("\nROBOTLASER1 ").count(), 12);
    assert_eq!(text.matches("\nFLASER ").count(), 10);
    let back = read_str(&text, &CarmenOptions::default()).unwrap();
    assert_same(&records, &back.records);
}

#[test]
fn carmen_round_trip_through_bzip2_file() {
    let dir = scratch("roundtrip-bz2");
    let records = drive(8, BeamGeometry::centered(181, PI, 80.0), Pose2::IDENTITY);
    let path = dir.join("drive.clf.bz2");
    let file = std::fs::File::create(&path).unwrap();
    let mut enc = BzEncoder::new(file, Compression::fast());
    write_carmen(&mut enc, &records).unwrap();
    enc.finish().unwrap();
    let back = read_carmen(&path, &CarmenOptions::default()).unwrap();
    assert_same(&records, &back.records);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn tum_round_trip_and_errors() {
    let dir = scratch("tum");
    let poses: Vec<(f64, Pose2)> = (0..100)
        .map(|i| {
            let f = f64::from(i);
            (1.6e9 + f / 7.0, Pose2::new(f.sqrt(), -f / 3.0, f * 0.1))
        })
        .collect();
    let path = dir.join("traj.tum");
    write_tum(std::fs::File::create(&path).unwrap(), &poses).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let first: Vec<&str> = text.lines().nth(1).unwrap().split(' ').collect();
    assert_eq!(first.len(), 8);
    assert_eq!(first[3], "0");
    let back = read_tum(&path).unwrap();
    for ((t, p), (tb, pb)) in poses.iter().zip(&back) {
        assert_eq!((t, p.x, p.y), (tb, pb.x, pb.y));
        assert!(normalize_angle(p.theta - pb.theta).abs() < 1e-13);
    }

    std::fs::write(
        &path,
        "# t x y z qx qy qz qw\n\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n",
    )
    .unwrap();
    let err = read_tum(&path).unwrap_err();
    assert!(matches!(err, LogError::Malformed { line: 4, .. }), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn eval_cli_scores_files() {
    let dir = scratch("cli");
    let truth: Vec<(f64, Pose2)> = (0..200)
        .map(|i| {
            let f = f64::from(i);
            (f * 0.1, Pose2::new(f * 0.05, (f * 0.02).sin(), f * 0.01))
        })
        .collect();
    let moved = Pose2::new(3.0, 4.0, 1.0);
    let est: Vec<(f64, Pose2)> = truth.iter().map(|(t, p)| (*t, moved * *p)).collect();
    let (tp, ep) = (dir.join("truth.tum"), dir.join("est.tum"));
    write_tum(std::fs::File::create(&tp).unwrap(), &truth).unwrap();
    write_tum(std::fs::File::create(&ep).unwrap(), &est).unwrap();
    let rels: String = truth
        .windows(10)
        .map(|w| {
            let d = w[0].1.between(&w[9].1);
            format!("{} {} {} {} 0 0 0 {}\n", w[0].0, w[9].0, d.x, d.y, d.theta)
        })
        .collect();
    let rp = dir.join("drive.relations");
    std::fs::write(&rp, rels).unwrap();

    let qicp = env!("CARGO_BIN_EXE_qicp");
    let out = std::process::Command::new(qicp)
        .args(["eval", "ate"])
        .arg(&ep)
        .arg(&tp)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["n"], 200);
    assert!(v["ate_rmse_m"].as_f64().unwrap() < 1e-9);

    let out = std::process::Command::new(qicp)
        .args(["eval", "relations"])
        .arg(&ep)
        .arg(&rp)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["n"], 191);
    assert_eq!(v["missing"], 0);
    assert!(v["trans_mean"].as_f64().unwrap() < 1e-9);

    let out = std::process::Command::new(qicp)
        .args(["eval", "relations"])
        .arg(dir.join("absent.tum"))
        .arg(&rp)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("absent.tum"));
    std::fs::remove_dir_all(&dir).ok();
}
