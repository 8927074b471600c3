//! One owner per service (issue 14): a second publisher on a scan or pose service is refused,
//! a service that would allow two is not joined, every message names its publisher, and a
//! `block` publisher whose subscribers all left fails instead of sending into nothing.

mod common;

use common::quick_wait;
use qicp_bridge::{
    ConnectError, PosePublisher, PublishError, PublisherOptions, ScanHeader, ScanPublisher,
    ScanSubscriber, StreamEvent, SubscriberOptions, Topics,
};
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use std::ops::ControlFlow;
use std::time::Duration;

fn topics(test: &str) -> Topics {
    common::topics("owner", test)
}

fn record(i: usize) -> Record {
    let geometry = BeamGeometry::centered(181, std::f64::consts::PI, 20.0);
    Record {
        scan: Scan::new(i as f64, geometry, vec![2.0; 181]).expect("scan"),
        odometry: Pose2::new(i as f64, 0.0, 0.0),
        truth: None,
        laser_offset: Pose2::IDENTITY,
    }
}

#[test]
fn second_scan_publisher_is_refused() {
    let topics = topics("scan");
    let _owner = ScanPublisher::create(&topics, &PublisherOptions::default()).expect("first");
    let second = ScanPublisher::create(&topics, &PublisherOptions::default());
    assert!(
        matches!(&second, Err(ConnectError::Owned { service }) if service == &topics.scan()),
        "{second:?}"
    );
    let text = second.expect_err("refused").to_string();
    assert!(text.contains("already publishes"), "{text}");
}

#[test]
fn second_pose_publisher_is_refused() {
    let topics = topics("pose");
    let _owner = PosePublisher::create(&topics).expect("first");
    let second = PosePublisher::create(&topics);
    assert!(
        matches!(&second, Err(ConnectError::Owned { service }) if service == &topics.pose()),
        "{second:?}"
    );
}

#[test]
fn a_publisher_that_left_frees_the_service() {
    let topics = topics("freed");
    drop(ScanPublisher::create(&topics, &PublisherOptions::default()).expect("first"));
    ScanPublisher::create(&topics, &PublisherOptions::default()).expect("the next owner");
}

/// A service created by another program for two publishers could mix two streams: qicp
/// neither publishes nor subscribes there.
#[test]
fn service_that_allows_two_publishers_is_not_joined() {
    use iceoryx2::prelude::*;
    let topics = topics("foreign");
    let node = NodeBuilder::new()
        .config(&iceoryx2::config::Config::default())
        .create::<ipc::Service>()
        .expect("node");
    let _service = node
        .service_builder(&ServiceName::new(&topics.scan()).expect("name"))
        .publish_subscribe::<[f64]>()
        .user_header::<ScanHeader>()
        .history_size(qicp_bridge::SCAN_HISTORY_MAX)
        .subscriber_max_buffer_size(qicp_bridge::SCAN_BUFFER_MAX)
        .max_subscribers(qicp_bridge::MAX_SUBSCRIBERS)
        .max_publishers(2)
        .enable_safe_overflow(false)
        .create()
        .expect("a foreign service");
    let publisher = ScanPublisher::create(&topics, &PublisherOptions::default());
    assert!(
        matches!(
            publisher,
            Err(ConnectError::NotSingleOwner {
                max_publishers: 2,
                ..
            })
        ),
        "{publisher:?}"
    );
    let subscriber = ScanSubscriber::create(&topics, &SubscriberOptions::default());
    assert!(
        matches!(subscriber, Err(ConnectError::NotSingleOwner { .. })),
        "{subscriber:?}"
    );
}

#[test]
fn every_scan_names_its_publisher() {
    let topics = topics("identity");
    let subscriber = ScanSubscriber::create(
        &topics,
        &SubscriberOptions {
            wait: quick_wait(),
            ..SubscriberOptions::default()
        },
    )
    .expect("subscriber");
    let t = topics.clone();
    let publisher = std::thread::spawn(move || {
        let mut p = ScanPublisher::create(&t, &PublisherOptions::default()).expect("publisher");
        assert!(
            p.wait_for_subscribers(1, Duration::from_secs(10))
                .expect("wait")
        );
        for i in 0..5 {
            p.publish(&record(i)).expect("publish");
        }
        p.end_of_stream().expect("end");
        p.linger(Duration::from_secs(10)).expect("linger");
        p.identity()
    });
    let mut named = Vec::new();
    let report = subscriber
        .run(|event| {
            if let StreamEvent::Data(view) = event {
                named.push(view.header.publisher);
            }
            ControlFlow::Continue(())
        })
        .expect("run");
    drop(subscriber);
    let identity = publisher.join().expect("publisher thread");
    assert!(report.is_complete(), "{report:?}");
    assert_ne!(identity, 0);
    assert_eq!(named, vec![identity; 5]);
}

/// Issue 14: the block-mode publisher whose only subscriber left published the rest into
/// nothing and exited 0.
#[test]
fn block_publisher_fails_once_its_subscribers_left() {
    let topics = topics("left");
    let subscriber =
        ScanSubscriber::create(&topics, &SubscriberOptions::default()).expect("subscriber");
    let mut p = ScanPublisher::create(&topics, &PublisherOptions::default()).expect("publisher");
    p.publish(&record(0)).expect("a subscriber is there");
    p.publish(&record(1)).expect("a subscriber is there");
    drop(subscriber);
    let error = p.publish(&record(2)).expect_err("nobody left to send to");
    assert!(
        matches!(error, PublishError::SubscribersLeft { sent: 2, .. }),
        "{error:?}"
    );
    assert!(error.to_string().contains("left after 2"), "{error}");
}

#[test]
fn drop_oldest_publisher_without_subscribers_goes_on() {
    let topics = topics("live");
    let options = PublisherOptions {
        backpressure: qicp_bridge::BackPressure::DropOldest,
        ..PublisherOptions::default()
    };
    let subscriber = ScanSubscriber::create(
        &topics,
        &SubscriberOptions {
            backpressure: Some(qicp_bridge::BackPressure::DropOldest),
            ..SubscriberOptions::default()
        },
    )
    .expect("subscriber");
    let mut p = ScanPublisher::create(&topics, &options).expect("publisher");
    p.publish(&record(0)).expect("publish");
    drop(subscriber);
    p.publish(&record(1))
        .expect("live mode publishes whoever listens");
}

#[test]
fn missing_iceoryx2_config_file_is_refused_with_its_path() {
    let path = std::path::Path::new("/nonexistent/qicp/iceoryx2.toml");
    let error = Topics::new("x")
        .with_config_file(path)
        .expect_err("missing");
    assert!(
        matches!(&error, ConnectError::Config { path: p, .. } if p == path),
        "{error:?}"
    );
    assert!(
        error
            .to_string()
            .contains("/nonexistent/qicp/iceoryx2.toml")
    );
}

#[test]
fn iceoryx2_config_file_is_parsed_and_garbage_refused() {
    let dir = std::env::temp_dir().join(format!("qicp-owner-{}-config", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let good = dir.join("good.toml");
    std::fs::write(&good, "[global]\nprefix = \"qicp_test_\"\n").expect("write");
    let topics = Topics::new("x").with_config_file(&good).expect("parsed");
    assert_eq!(topics.config_file(), Some(good.as_path()));
    assert_ne!(
        topics,
        Topics::new("x"),
        "the configuration is part of the topics"
    );
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[global\nprefix = ").expect("write");
    let error = Topics::new("x")
        .with_config_file(&bad)
        .expect_err("garbage");
    assert!(matches!(error, ConnectError::Config { .. }), "{error:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
