//! ROS 2 bags: what the writer writes, the reader reads back; odometry is interpolated to the
//! scans' times; bad bags are refused with the reason.

use mcap::records::MessageHeader;
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use qicp_io::LogError;
use qicp_io::rosbag::msgs::{self, LaserScan, Odometry, Transform};
use qicp_io::rosbag::{BagLayout, BagOptions, BagReader, BagWriter, OdometrySource};
use std::collections::BTreeMap;
use std::io::Cursor;

fn record(t: f64, odometry: Pose2) -> Record {
    let geometry = BeamGeometry {
        angle_min: -1.5,
        angle_increment: 0.01,
        max_range: 30.0,
        min_range: 0.1,
    };
    let ranges = (0..301).map(|i| 1.0 + f64::from(i) * 0.013).collect();
    Record {
        scan: Scan::new(t, geometry, ranges).expect("a valid scan"),
        odometry,
        truth: None,
        laser_offset: Pose2::new(0.2, 0.0, 0.1),
    }
}

fn read_all(bytes: Vec<u8>, opts: &BagOptions) -> Result<Vec<Record>, LogError> {
    BagReader::new(Cursor::new(bytes), "test.mcap", opts).collect()
}

fn odom_topic() -> BagOptions {
    BagOptions::new("/scan", OdometrySource::Topic("/odom".into()))
}

#[test]
fn written_records_read_back_as_float32_scans_with_their_odometry() {
    let records: Vec<Record> = (0..50)
        .map(|i| {
            let t = 100.0 + f64::from(i) * 0.2;
            record(t, Pose2::new(t * 0.1, -t * 0.05, (t * 0.3).sin()))
        })
        .collect();
    let mut w = BagWriter::new(Cursor::new(Vec::new()), "test.mcap", BagLayout::default())
        .expect("a writer");
    for r in &records {
        w.record(r).expect("written");
    }
    let bytes = w.finish().expect("finished").into_inner();
    for opts in [
        odom_topic(),
        BagOptions::new(
            "/scan",
            OdometrySource::Tf {
                odom_frame: "odom".into(),
                base_frame: "base_link".into(),
            },
        ),
    ] {
        let back = read_all(bytes.clone(), &opts).expect("readable");
        assert_eq!(back.len(), records.len());
        for (a, b) in records.iter().zip(&back) {
            assert!((a.timestamp() - b.timestamp()).abs() < 1e-6);
            let f32s: Vec<f64> = a
                .scan
                .ranges()
                .iter()
                .map(|&r| f64::from(r as f32))
                .collect();
            assert_eq!(b.scan.ranges(), f32s.as_slice());
            assert!(a.odometry.distance(&b.odometry) < 1e-12);
            assert!((a.odometry.theta - b.odometry.theta).abs() < 1e-12);
            // The laser's pose on the robot comes back from /tf_static.
            assert!(
                (b.laser_offset.x - 0.2).abs() < 1e-12
                    && (b.laser_offset.theta - 0.1).abs() < 1e-12
            );
        }
    }
}

/// A bag of hand-placed messages: (time, topic, encoded message).
fn bag(messages: &[(f64, &str, Vec<u8>)]) -> Vec<u8> {
    let mut w = mcap::Writer::new(Cursor::new(Vec::new())).expect("a writer");
    let mut channels = BTreeMap::new();
    for (topic, ty) in [
        ("/scan", msgs::LASER_SCAN),
        ("/odom", msgs::ODOMETRY),
        ("/tf", msgs::TF_MESSAGE),
    ] {
        let schema = w
            .add_schema(ty, "ros2msg", msgs::schema_text(ty).as_bytes())
            .expect("schema");
        let id = w
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .expect("channel");
        channels.insert(topic, id);
    }
    for (t, topic, data) in messages {
        let header = MessageHeader {
            channel_id: channels[topic],
            sequence: 0,
            log_time: msgs::nanos(*t),
            publish_time: msgs::nanos(*t),
        };
        w.write_to_known_channel(&header, data).expect("message");
    }
    w.finish().expect("finished");
    w.into_inner().into_inner()
}

fn scan_msg(t: f64) -> (f64, &'static str, Vec<u8>) {
    let msg = LaserScan {
        stamp: t,
        frame_id: "base_link".into(),
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 0.5,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: 0.0,
        range_max: 10.0,
        ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0],
        intensities: vec![],
    };
    (t, "/scan", msg.encode())
}

fn odom_msg(t: f64, pose: Pose2) -> (f64, &'static str, Vec<u8>) {
    let msg = Odometry {
        stamp: t,
        frame_id: "odom".into(),
        child_frame_id: "base_link".into(),
        pose,
    };
    (t, "/odom", msg.encode())
}

/// Odometry moving at 1 m/s along x and turning at 0.5 rad/s.
fn moving(t: f64) -> Pose2 {
    Pose2::new(t - 10.0, 0.0, 0.5 * (t - 10.0))
}

#[test]
fn odometry_is_interpolated_to_each_scan_and_scans_outside_it_are_counted() {
    let mut messages = vec![scan_msg(9.95)]; // before any odometry: dropped
    for k in 0..=10 {
        let t = 10.0 + f64::from(k) * 0.1;
        messages.push(odom_msg(t, moving(t)));
        // A scan between two samples, and one that arrives after the sample past it.
        messages.push(scan_msg(t + 0.03));
        if k > 0 {
            messages.push(scan_msg(t - 0.01));
        }
    }
    messages.push(scan_msg(11.2)); // after the last odometry: dropped
    let mut reader = BagReader::new(Cursor::new(bag(&messages)), "t.mcap", &odom_topic());
    let records: Vec<Record> = reader.by_ref().collect::<Result<_, _>>().expect("readable");
    // 10 scans at t + 0.03 inside the odometry (the one after 11.0 is not), 10 at t - 0.01.
    assert_eq!(records.len(), 20);
    for r in &records {
        let expected = moving(r.timestamp());
        assert!(r.odometry.distance(&expected) < 1e-9, "{:?}", r.odometry);
        assert!((r.odometry.theta - expected.theta).abs() < 1e-9);
        assert_eq!(r.laser_offset, Pose2::IDENTITY);
    }
    assert_eq!(reader.info().without_odometry, 3);
}

#[test]
fn a_bag_read_without_odometry_keeps_every_scan_at_one_pose() {
    // Scans only, with no odometry topic at all: every scan is a record, read with the
    // identity as its odometry, none dropped for want of odometry.
    let messages: Vec<_> = (0..12)
        .map(|k| scan_msg(10.0 + f64::from(k) * 0.1))
        .collect();
    let opts = BagOptions::new("/scan", OdometrySource::None);
    let mut reader = BagReader::new(Cursor::new(bag(&messages)), "t.mcap", &opts);
    let records: Vec<Record> = reader.by_ref().collect::<Result<_, _>>().expect("readable");
    assert_eq!(records.len(), 12);
    assert!(records.iter().all(|r| r.odometry == Pose2::IDENTITY));
    assert_eq!(reader.info().without_odometry, 0);
    // The same bag asked for its odometry topic is refused, naming it.
    let err = read_all(bag(&messages), &odom_topic()).expect_err("no /odom");
    assert!(err.to_string().contains("no odometry topic /odom"), "{err}");
}

#[test]
fn odometry_from_tf_between_the_named_frames() {
    let mut messages = Vec::new();
    for k in 0..5 {
        let t = 10.0 + f64::from(k) * 0.1;
        let tfs = [
            Transform {
                stamp: t,
                parent: "map".into(),
                child: "odom".into(),
                pose: Pose2::new(5.0, 5.0, 1.0),
            },
            Transform {
                stamp: t,
                parent: "/odom".into(),
                child: "base_footprint".into(),
                pose: moving(t),
            },
        ];
        messages.push((t, "/tf", msgs::encode_tf(&tfs)));
        messages.push(scan_msg(t + 0.05));
    }
    let opts = BagOptions::new(
        "/scan",
        OdometrySource::Tf {
            odom_frame: "odom".into(),
            base_frame: "base_footprint".into(),
        },
    );
    let records = read_all(bag(&messages), &opts).expect("readable");
    assert_eq!(records.len(), 4);
    for r in &records {
        assert!(r.odometry.distance(&moving(r.timestamp())) < 1e-9);
    }
}

#[test]
fn bad_bags_are_refused_with_the_reason() {
    let good = bag(&[scan_msg(1.0), odom_msg(1.0, Pose2::IDENTITY)]);
    let why = |bytes: Vec<u8>, opts: &BagOptions| match read_all(bytes, opts) {
        Err(e) => e.to_string(),
        Ok(r) => panic!("read {} records", r.len()),
    };
    let e = why(good[..good.len() / 2].to_vec(), &odom_topic());
    assert!(e.starts_with("test.mcap: not a readable MCAP file"), "{e}");
    let e = why(b"not an mcap file at all".to_vec(), &odom_topic());
    assert!(e.contains("not a readable MCAP file"), "{e}");
    let e = why(
        good.clone(),
        &BagOptions::new("/laser", OdometrySource::Topic("/odom".into())),
    );
    assert!(
        e.contains("no topic /laser; the bag has: /odom (nav_msgs/msg/Odometry), /scan"),
        "{e}"
    );
    let e = why(
        good.clone(),
        &BagOptions::new("/odom", OdometrySource::Topic("/odom".into())),
    );
    assert!(
        e.contains("topic /odom carries nav_msgs/msg/Odometry"),
        "{e}"
    );
    let mut small = odom_topic();
    small.max_beams = 3;
    let e = why(good, &small);
    assert!(
        e.contains("scan 1 has 5 beams, more than --max-beams 3"),
        "{e}"
    );
    // A scan message cut short is an error naming the scan, not a panic.
    let (t, topic, data) = scan_msg(1.0);
    let e = why(bag(&[(t, topic, data[..30].to_vec())]), &odom_topic());
    assert!(e.contains("scan 1 on /scan: message ends inside"), "{e}");
}
