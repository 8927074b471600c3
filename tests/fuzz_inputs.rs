//! Property-based fuzzing of every reader of outside input: CARMEN logs, relations, TUM
//! trajectories and matcher configs. Each input, however mangled, gives a value or an error,
//! never a panic or a hang; what is accepted is usable (records with finite times, in time
//! order when sorted, and finite poses; a config that validates builds and matches scans).
//!
//! The inputs are mutations of valid files (tokens replaced by the numbers that broke readers
//! before: counts near 2⁶⁴, NaN, inf, 1e308, negative and zero values; tokens dropped or
//! repeated; lines cut, swapped and duplicated) and raw bytes. Cases per property:
//! `QICP_FUZZ_CASES` (default 5,000); CI runs the default, a longer session sets it higher.

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use qicp::logs::carmen::{CarmenOptions, CarmenReader, RecordOrder};
use qicp::logs::relations::read_relations_from;
use qicp::logs::tum::read_tum_from;
use qicp_core::testdata::SyntheticWorld;
use qicp_core::{Pose2, Record};
use qicp_matchers::{MatcherConfig, MatcherKind};

fn cases() -> u32 {
    std::env::var("QICP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5000)
}

fn runner() -> TestRunner {
    TestRunner::new(Config {
        cases: cases(),
        failure_persistence: None,
        ..Config::default()
    })
}

/// Tokens that broke readers before, and ordinary ones.
const NASTY: &[&str] = &[
    "18446744073709551615",
    "18446744073709551616",
    "9223372036854775807",
    "4294967295",
    "-1",
    "0",
    "-0",
    "1e308",
    "-1e308",
    "1e-308",
    "nan",
    "-nan",
    "inf",
    "-inf",
    "3e9",
    "",
    "x",
    "0x10",
    "1.5.2",
    "\u{feff}",
    "180",
    "181",
    "361",
    "10001",
    "PARAM",
    "FLASER",
    "#",
];

/// A valid CARMEN log of a few kinds of lines.
fn carmen_seed() -> Vec<String> {
    let ranges = |n: usize| vec!["2.5"; n].join(" ");
    vec![
        "PARAM laser_front_laser_fov 180 host 0".to_string(),
        "PARAM robot_front_laser_max 30 host 0".to_string(),
        "ODOM 0 0 0 0 0 0 1.0 host 1.0".to_string(),
        format!("FLASER 5 {} 0 0 0 0 0 0 1.1 host 1.1", ranges(5)),
        "TRUEPOS 0 0 0 0 0 0 1.1 host 1.1".to_string(),
        format!(
            "ROBOTLASER1 0 -1.5 3.0 0.75 80 0.01 0 5 {} 0 0.1 0 0 0 0 0 0 0 0 0 0 1.2 host 1.2",
            ranges(5)
        ),
        format!("FLASER 5 {} 0.1 0 0 0.1 0 0 1.3 host 1.3", ranges(5)),
        "SYNC x".to_string(),
    ]
}

/// Mutations of a file's lines.
#[derive(Debug, Clone)]
enum Mutation {
    /// Replace token `tok` of line `line` with a nasty one.
    Replace {
        line: usize,
        tok: usize,
        with: usize,
    },
    /// Drop a token.
    Drop { line: usize, tok: usize },
    /// Repeat a token.
    Repeat { line: usize, tok: usize },
    /// Cut a line at a byte.
    Cut { line: usize, at: usize },
    /// Swap two lines.
    Swap { a: usize, b: usize },
    /// Duplicate a line.
    Duplicate { line: usize },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let i = || 0usize..64;
    prop_oneof![
        4 => (i(), i(), 0..NASTY.len()).prop_map(|(line, tok, with)| Mutation::Replace { line, tok, with }),
        1 => (i(), i()).prop_map(|(line, tok)| Mutation::Drop { line, tok }),
        1 => (i(), i()).prop_map(|(line, tok)| Mutation::Repeat { line, tok }),
        1 => (i(), 0usize..400).prop_map(|(line, at)| Mutation::Cut { line, at }),
        1 => (i(), i()).prop_map(|(a, b)| Mutation::Swap { a, b }),
        1 => i().prop_map(|line| Mutation::Duplicate { line }),
    ]
}

fn apply(lines: &[String], mutations: &[Mutation]) -> String {
    let mut lines: Vec<Vec<String>> = lines
        .iter()
        .map(|l| l.split(' ').map(str::to_string).collect())
        .collect();
    for m in mutations {
        let n = lines.len();
        if n == 0 {
            break;
        }
        match *m {
            Mutation::Replace { line, tok, with } => {
                let l = &mut lines[line % n];
                if !l.is_empty() {
                    let k = tok % l.len();
                    l[k] = NASTY[with].to_string();
                }
            }
            Mutation::Drop { line, tok } => {
                let l = &mut lines[line % n];
                if !l.is_empty() {
                    let k = tok % l.len();
                    l.remove(k);
                }
            }
            Mutation::Repeat { line, tok } => {
                let l = &mut lines[line % n];
                if !l.is_empty() {
                    let k = tok % l.len();
                    let t = l[k].clone();
                    l.insert(k, t);
                }
            }
            Mutation::Cut { line, at } => {
                let joined = lines[line % n].join(" ");
                let cut = joined
                    .char_indices()
                    .nth(at)
                    .map_or(joined.len(), |(i, _)| i);
                lines[line % n] = joined[..cut].split(' ').map(str::to_string).collect();
            }
            Mutation::Swap { a, b } => lines.swap(a % n, b % n),
            Mutation::Duplicate { line } => {
                let l = lines[line % n].clone();
                lines.insert(line % n, l);
            }
        }
    }
    lines.iter().map(|l| l.join(" ") + "\n").collect()
}

/// Reads a log in both modes; checks what is accepted and counts it.
fn read_both(text: &[u8]) -> Result<usize, TestCaseError> {
    let mut accepted = 0;
    for (lenient, order) in [
        (false, RecordOrder::File),
        (true, RecordOrder::File),
        (true, RecordOrder::Time),
    ] {
        let opts = CarmenOptions {
            lenient,
            order,
            ..CarmenOptions::default()
        };
        let reader = CarmenReader::new(text, "fuzz.clf", &opts).expect("default options");
        let mut last = f64::NEG_INFINITY;
        for item in reader {
            let Ok(record) = item else { break };
            let record: Record = record;
            let t = record.timestamp();
            prop_assert!(t.is_finite(), "time {t}");
            if order == RecordOrder::Time {
                prop_assert!(t >= last, "time order: {t} after {last}");
            }
            last = t;
            prop_assert!(record.odometry.is_finite());
            prop_assert!(record.scan.beams() >= 1);
            accepted += 1;
        }
    }
    Ok(accepted)
}

#[test]
fn carmen_reader_survives_mutated_logs() {
    let seed = carmen_seed();
    let records = std::cell::Cell::new(0usize);
    runner()
        .run(&prop::collection::vec(mutation(), 1..8), |m| {
            records.set(records.get() + read_both(apply(&seed, &m).as_bytes())?);
            Ok(())
        })
        .expect("no panic, accepted records usable");
    eprintln!("{} cases, {} records accepted", cases(), records.get());
    assert!(
        records.get() > 0,
        "every mutated log refused: the checks never ran"
    );
}

#[test]
fn carmen_reader_survives_raw_bytes() {
    runner()
        .run(&prop::collection::vec(any::<u8>(), 0..600), |bytes| {
            read_both(&bytes).map(|_| ())
        })
        .expect("no panic");
}

#[test]
fn relations_and_tum_readers_survive_mutated_files() {
    let relations = vec![
        "1.0 2.0 0.5 0.1 0 0 0 0.2".to_string(),
        "2.0 3.5 -0.5 0.0 0 0 0 -0.1".to_string(),
        "# comment".to_string(),
    ];
    let tum = vec![
        "1.0 0 0 0 0 0 0 1".to_string(),
        "2.0 1 0.5 0 0 0 0.1 0.99".to_string(),
    ];
    runner()
        .run(&prop::collection::vec(mutation(), 1..6), |m| {
            if let Ok(rels) = read_relations_from(&mut apply(&relations, &m).as_bytes(), "r") {
                for r in rels {
                    prop_assert!(r.t1.is_finite() && r.t2.is_finite() && r.delta.is_finite());
                }
            }
            if let Ok(poses) = read_tum_from(&mut apply(&tum, &m).as_bytes(), "t") {
                for (t, p) in poses {
                    prop_assert!(t.is_finite() && p.is_finite());
                }
            }
            Ok(())
        })
        .expect("no panic, accepted values finite");
}

/// A few scans of a room along a short path, for configs that validate.
fn room_records() -> Vec<Record> {
    let room = SyntheticWorld::room();
    (0..4)
        .map(|k| {
            let pose = Pose2::new(0.1 * k as f64, 0.05 * k as f64, 0.02 * k as f64);
            Record {
                scan: room.scan(&pose, 0.005, k),
                odometry: pose,
                truth: None,
                laser_offset: Pose2::IDENTITY,
            }
        })
        .collect()
}

/// Values a config key is set to.
const VALUES: &[&str] = &[
    "0",
    "-1",
    "1",
    "0.5",
    "1e308",
    "-1e308",
    "1e-308",
    "nan",
    "inf",
    "-inf",
    "4294967295",
    "9223372036854775807",
    "true",
    "\"x\"",
    "[]",
    "{}",
];

#[test]
fn matcher_configs_that_validate_build_and_match() {
    let records = room_records();
    // Every key of every section of the effective configs.
    let keys: Vec<(MatcherKind, String, String)> = MatcherKind::ALL
        .iter()
        .flat_map(|&kind| {
            let mut c = MatcherConfig::defaults(kind);
            c.fill_defaults();
            let table: toml::Table = toml::from_str(&c.to_toml()).expect("own TOML");
            let matcher = table["matcher"].as_table().expect("[matcher]").clone();
            matcher
                .iter()
                .filter_map(|(section, v)| v.as_table().map(|t| (section.clone(), t.clone())))
                .flat_map(|(section, t)| {
                    t.keys()
                        .map(|k| (kind, section.clone(), k.clone()))
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let cases = cases().min(keys.len() as u32 * VALUES.len() as u32);
    let accepted = std::cell::Cell::new(0usize);
    TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    })
    .run(&(0..keys.len(), 0..VALUES.len()), |(k, v)| {
        let (kind, section, key) = &keys[k];
        let text = format!(
            "[matcher]\nkind = \"{}\"\n[matcher.{section}]\n{key} = {}\n",
            kind.name(),
            VALUES[v]
        );
        let Ok(mut config) = MatcherConfig::from_toml(&text) else {
            return Ok(());
        };
        if config.validate().is_err() {
            return Ok(());
        }
        config.fill_defaults();
        accepted.set(accepted.get() + 1);
        let mut odometry = config
            .build()
            .map_err(|e| TestCaseError::fail(format!("validated but does not build: {e}")))?;
        for r in &records {
            let estimate = odometry.process(r);
            prop_assert!(
                estimate.pose.is_finite(),
                "{text}: pose {:?}",
                estimate.pose
            );
        }
        Ok(())
    })
    .expect("a config that validates builds and matches");
    eprintln!(
        "{cases} configs tried, {} validated and ran",
        accepted.get()
    );
    assert!(
        accepted.get() > 0,
        "no config validated: the property was never checked"
    );
}

/// Numbers a neighbour process might put in a message: anything at all, and the usual
/// suspects.
fn any_number() -> impl Strategy<Value = f64> {
    prop_oneof![
        2 => -100.0..100.0f64,
        1 => any::<f64>(),
        1 => prop::sample::select(vec![
            f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0, -0.0, 1e308, 3e9, -3e9, 1e-320,
        ]),
    ]
}

#[test]
fn bridge_scan_messages_decode_to_usable_records_or_are_refused() {
    use qicp_bridge::messages::{FLAG_HAS_TRUTH, PoseC, ScanHeader};
    let decoded = std::cell::Cell::new(0usize);
    runner()
        .run(
            &(
                prop::collection::vec(any_number(), 14),
                any::<bool>(),
                prop::collection::vec(any_number(), 0..200),
            ),
            |(v, truth, ranges)| {
                let pose = |i: usize| PoseC {
                    x: v[i],
                    y: v[i + 1],
                    theta: v[i + 2],
                };
                let header = ScanHeader {
                    timestamp: v[0],
                    odometry: pose(1),
                    truth: pose(4),
                    laser_offset: pose(7),
                    angle_min: v[10],
                    angle_increment: v[11],
                    max_range: v[12],
                    min_range: v[13],
                    beams: ranges.len() as u32,
                    flags: if truth { FLAG_HAS_TRUTH } else { 0 },
                    ..ScanHeader::default()
                };
                if let Ok(record) = header.to_record(&ranges) {
                    let limit = qicp_core::index::MAX_COORDINATE;
                    let usable =
                        |p: &Pose2| p.is_finite() && p.x.abs() <= limit && p.y.abs() <= limit;
                    prop_assert!(usable(&record.odometry), "odometry {:?}", record.odometry);
                    prop_assert!(
                        usable(&record.laser_offset),
                        "offset {:?}",
                        record.laser_offset
                    );
                    prop_assert!(
                        record.truth.is_none_or(|t| usable(&t)),
                        "truth {:?}",
                        record.truth
                    );
                    prop_assert!(record.timestamp().is_finite());
                    prop_assert_eq!(record.scan.beams(), ranges.len());
                    decoded.set(decoded.get() + 1);
                }
                Ok(())
            },
        )
        .expect("a decoded scan is usable");
    assert!(
        decoded.get() > 0,
        "no message decoded: the property was never checked"
    );
}

#[test]
fn bridge_scan_with_nan_or_far_odometry_is_refused_not_matched() {
    use qicp_bridge::messages::{PoseC, ScanHeader};
    let ranges = [1.0, 2.0, 3.0];
    let good = ScanHeader {
        timestamp: 1.0,
        angle_min: -1.0,
        angle_increment: 0.5,
        max_range: 10.0,
        beams: 3,
        ..ScanHeader::default()
    };
    assert!(good.to_record(&ranges).is_ok());
    for odometry in [
        PoseC {
            x: f64::NAN,
            y: 0.0,
            theta: 0.0,
        },
        PoseC {
            x: 0.0,
            y: 3e9,
            theta: 0.0,
        },
        PoseC {
            x: 0.0,
            y: 0.0,
            theta: f64::INFINITY,
        },
    ] {
        let bad = ScanHeader { odometry, ..good };
        let why = bad.to_record(&ranges).expect_err("refused").to_string();
        assert!(why.contains("odometry"), "{why}");
    }
}
