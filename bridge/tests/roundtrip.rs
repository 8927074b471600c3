//! Publisher and subscriber in one process (two threads): every scan arrives intact, in
//! order, read in place; the report is complete; poses round-trip the same way.

mod common;

use common::{quick_wait, record};
use qicp_bridge::{
    BackPressure, PoseMessage, PosePublisher, PoseSubscriber, PublisherOptions, ScanPublisher,
    ScanSubscriber, StreamEnd, StreamEvent, SubscriberOptions, Topics,
};
use qicp_core::{MatchResult, Pose2, Record};
use std::ops::ControlFlow;
use std::time::Duration;

fn topics(test: &str) -> Topics {
    common::topics("test", test)
}

#[test]
fn scans_arrive_intact_and_in_order() {
    let topics = topics("scans");
    let records: Vec<Record> = (0..50).map(record).collect();
    let subscriber = ScanSubscriber::create(
        &topics,
        &SubscriberOptions {
            buffer: 8,
            wait: quick_wait(),
            ..SubscriberOptions::default()
        },
    )
    .expect("subscriber");
    assert_eq!(subscriber.backpressure(), BackPressure::Block);
    let sent = records.clone();
    let t = topics.clone();
    let publisher = std::thread::spawn(move || {
        let mut p = ScanPublisher::create(&t, &PublisherOptions::default()).expect("publisher");
        assert!(
            p.wait_for_subscribers(1, Duration::from_secs(10))
                .expect("wait")
        );
        for r in &sent {
            p.publish(r).expect("publish");
        }
        p.end_of_stream().expect("end");
        assert!(
            p.blocked_sends() > 0,
            "a buffer of 8 must have blocked 50 sends"
        );
        p.linger(Duration::from_secs(10)).expect("linger")
    });
    let mut got = Vec::new();
    let report = subscriber
        .run(|event| {
            if let StreamEvent::Data(view) = event {
                if got.is_empty() {
                    // Fall behind on the first scan, so that the 8-slot buffer fills and the
                    // publisher must block whatever the machine's load: a subscriber that
                    // kept pace on a busy host once let this test see no blocked send.
                    std::thread::sleep(Duration::from_millis(300));
                }
                got.push(view.header.to_record(view.ranges).expect("record"));
            }
            ControlFlow::Continue(())
        })
        .expect("run");
    drop(subscriber);
    assert!(
        publisher.join().expect("publisher thread"),
        "publisher lingered to timeout"
    );
    assert_eq!(report.end, Some(StreamEnd::EndOfStream));
    assert!(report.is_complete(), "{report:?}");
    assert_eq!(report.received, 50);
    assert_eq!(got, records);
}

#[test]
fn poses_round_trip() {
    let topics = topics("poses");
    let subscriber = PoseSubscriber::create(
        &topics,
        &SubscriberOptions {
            wait: quick_wait(),
            ..SubscriberOptions::default()
        },
    )
    .expect("subscriber");
    let t = topics.clone();
    let publisher = std::thread::spawn(move || {
        let mut p = PosePublisher::create(&t).expect("publisher");
        let result = MatchResult::fallback(Pose2::IDENTITY, qicp_core::Fallback::EmptyReference);
        for i in 0..10u64 {
            p.publish(PoseMessage::of(
                0,
                i,
                i as f64,
                Pose2::new(i as f64, 0.0, 0.0),
                &result,
                true,
            ))
            .expect("publish");
        }
        p.end_of_stream().expect("end");
        p.linger(Duration::from_secs(10)).expect("linger")
    });
    let mut got = Vec::new();
    let report = subscriber
        .run(|event| {
            if let StreamEvent::Data(m) = event {
                got.push(*m);
            }
            ControlFlow::Continue(())
        })
        .expect("run");
    drop(subscriber);
    publisher.join().expect("publisher thread");
    assert!(report.is_complete(), "{report:?}");
    assert_eq!(got.len(), 10);
    assert_eq!(got[3].scan_seq, 3);
    assert_eq!(got[3].pose.x, 3.0);
    assert_eq!(
        got[3].fallback,
        qicp_bridge::messages::fallback_code::EMPTY_REFERENCE
    );
}

#[test]
fn no_publisher_times_out() {
    let subscriber = common::impatient_subscriber(&topics("nobody"));
    let report = subscriber.run(|_| ControlFlow::Continue(())).expect("run");
    assert_eq!(report.end, Some(StreamEnd::NoPublisher));
}
