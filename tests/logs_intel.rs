//! The Intel Research Lab log (Radish / Freiburg SLAM benchmark): the CARMEN reader on a real,
//! bzip2-compressed, out-of-order log, and the relations metric on its raw odometry, whose
//! published figure is 7.37 ± 14.35 m, 39.2° (shared/data/README.md).
#![allow(clippy::unwrap_used)] // tests: a panic is the failure report

use qicp::eval::{DEFAULT_MAX_DT, evaluate_relations};
use qicp::logs::carmen::{CarmenOptions, RecordOrder, read_carmen};
use qicp::logs::relations::read_relations;
use std::path::Path;
use std::time::Instant;

const INTEL_LOG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/intel/intel.clf.bz2"
);
const INTEL_RELATIONS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/intel/intel.relations"
);

fn present(path: &str) -> bool {
    let ok = Path::new(path).exists();
    if !ok {
        println!("skipping: {path} is absent");
    }
    ok
}

#[test]
fn intel_log_reads_in_file_order_with_odometry_matching_the_benchmark() {
    if !present(INTEL_LOG) || !present(INTEL_RELATIONS) {
        return;
    }
    let start = Instant::now();
    let log = read_carmen(Path::new(INTEL_LOG), &CarmenOptions::default()).unwrap();
    let elapsed = start.elapsed();
    println!("{}", log.report());
    println!("read in {:.3} s", elapsed.as_secs_f64());
    // A loose bound: a pathological reader (seconds per MB) fails it, a busy machine does not.
    assert!(elapsed.as_secs_f64() < 10.0, "reading took {elapsed:?}");

    assert_eq!(log.records.len(), 13_631);
    assert_eq!(log.info.counts.get("FLASER"), Some(&13_631));
    assert_eq!(log.info.counts.get("ODOM"), Some(&26_915));
    assert_eq!(log.info.counts.get("PARAM"), Some(&2));
    assert_eq!(log.odometry.len(), 26_915);
    assert!(
        log.info.unknown_types.is_empty(),
        "{:?}",
        log.info.unknown_types
    );
    assert_eq!(log.info.skipped_lines, 0);
    assert!(log.info.out_of_order > 600, "{}", log.info.out_of_order);
    assert!(
        log.records
            .windows(2)
            .any(|w| w[0].timestamp() > w[1].timestamp())
    );
    assert!(log.records.iter().all(|r| r.scan.beams() == 180));
    assert!(log.records.iter().all(|r| r.truth.is_none()));
    let (first, last) = log.info.span.unwrap();
    let duration = last - first;
    assert!((2680.0..2700.0).contains(&duration), "{duration}");

    // CARMEN's 180-beam layout: −90° … +89° in 1° steps; no-returns at 81 m and beyond.
    let g = log.records[0].scan.geometry;
    assert!((g.angle_min + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!((g.angle_increment - 1f64.to_radians()).abs() < 1e-12);
    assert_eq!(g.max_range, 81.0);
    let [valid, max_range, _, invalid] = log
        .records
        .iter()
        .map(|r| r.scan.status_counts())
        .fold([0; 4], |a, c| {
            [a[0] + c[0], a[1] + c[1], a[2] + c[2], a[3] + c[3]]
        });
    assert!(valid > 13_631 * 100, "{valid}");
    assert!(max_range > 0);
    assert_eq!(invalid, 0);

    let relations = read_relations(Path::new(INTEL_RELATIONS)).unwrap();
    assert_eq!(relations.len(), 2984);
    let report = evaluate_relations(&log.laser_odometry(), &relations, DEFAULT_MAX_DT).unwrap();
    println!("{report:?}");
    assert_eq!(report.n, 2984);
    assert_eq!(report.missing, 0);
    assert!((7.0..7.8).contains(&report.trans_mean), "{report:?}");
    assert!((14.0..14.7).contains(&report.trans_std), "{report:?}");
    assert!((38.5..40.0).contains(&report.rot_mean_deg), "{report:?}");
}

/// Length of the path the records' odometry draws, record after record (m).
fn odometry_path(records: &[qicp_core::Record]) -> f64 {
    records
        .windows(2)
        .map(|w| w[0].odometry.distance(&w[1].odometry))
        .sum()
}

/// Intel's laser lines stand in the file in the order the laser took them, while their
/// timestamps jitter by up to 0.6 s: sorted by time, the scans of a steady drive go forwards
/// and back by up to 0.15 m, and the odometry's path grows by a third (scan-to-scan IDC scored
/// 0.44 m on the relations that way, 0.18 m in file order).
#[test]
fn intel_scans_keep_the_order_the_laser_took_them() {
    if !present(INTEL_LOG) {
        return;
    }
    let in_file = read_carmen(Path::new(INTEL_LOG), &CarmenOptions::default()).unwrap();
    let by_time = read_carmen(
        Path::new(INTEL_LOG),
        &CarmenOptions {
            order: RecordOrder::Time,
            ..CarmenOptions::default()
        },
    )
    .unwrap();
    let (file, time) = (
        odometry_path(&in_file.records),
        odometry_path(&by_time.records),
    );
    println!("odometry path: file order {file:.1} m, time order {time:.1} m");
    assert!((500.0..520.0).contains(&file), "{file}");
    assert!(time > 1.25 * file, "{time} against {file}");
}

#[test]
fn relation_timestamps_are_laser_timestamps() {
    if !present(INTEL_LOG) || !present(INTEL_RELATIONS) {
        return;
    }
    let log = read_carmen(Path::new(INTEL_LOG), &CarmenOptions::default()).unwrap();
    let relations = read_relations(Path::new(INTEL_RELATIONS)).unwrap();
    // The README says so; with a window of zero seconds nothing may go missing.
    let report = evaluate_relations(&log.laser_odometry(), &relations, 0.0).unwrap();
    assert_eq!((report.n, report.missing), (2984, 0));
}

const MIT_LOG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/mit-csail/mit-csail.clf.bz2"
);

#[test]
fn mit_csail_log_has_361_beams_and_odometry_only_in_laser_lines() {
    if !present(MIT_LOG) {
        return;
    }
    let log = read_carmen(Path::new(MIT_LOG), &CarmenOptions::default()).unwrap();
    println!("{}", log.report());
    assert_eq!(log.records.len(), 1988);
    assert!(log.odometry.is_empty());
    assert!(log.records.iter().all(|r| r.scan.beams() == 361));
    // 361 beams spread evenly over 180°: −90° … +90° in 0.5° steps.
    let g = log.records[0].scan.geometry;
    assert!((g.angle(360) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!((g.angle_increment - 0.5f64.to_radians()).abs() < 1e-12);
    assert!(
        log.records
            .windows(2)
            .all(|w| w[0].timestamp() <= w[1].timestamp())
    );
    let moved = log
        .records
        .last()
        .unwrap()
        .odometry
        .distance(&log.records[0].odometry);
    assert!(moved > 1.0, "{moved}");
}
