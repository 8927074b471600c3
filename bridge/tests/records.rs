//! The scan subscriber as an iterator of records (`ScanSubscriber::records`): a publisher
//! thread's records come out equal and in order, then `None`, the report says how the stream
//! ended, a scan that cannot become a record is an `Err` item the iteration goes past, and
//! the iterator fits `qicp_io::RecordSource`'s blanket impl.

mod common;

use common::{quick_wait, record};
use qicp_bridge::{
    PublisherOptions, ReceiveError, Records, ScanPublisher, ScanSubscriber, StreamEnd,
    SubscriberOptions, Topics,
};
use qicp_core::Record;
use std::time::Duration;

fn topics(test: &str) -> Topics {
    common::topics("records", test)
}

fn subscriber(topics: &Topics) -> ScanSubscriber {
    ScanSubscriber::create(
        topics,
        &SubscriberOptions {
            buffer: 8,
            wait: quick_wait(),
            ..SubscriberOptions::default()
        },
    )
    .expect("subscriber")
}

/// Publishes `records` on a thread once the subscriber is there, then the end marker.
fn publish(topics: &Topics, records: Vec<Record>) -> std::thread::JoinHandle<u64> {
    let t = topics.clone();
    std::thread::spawn(move || {
        let mut p = ScanPublisher::create(&t, &PublisherOptions::default()).expect("publisher");
        assert!(
            p.wait_for_subscribers(1, Duration::from_secs(10))
                .expect("wait")
        );
        for r in &records {
            p.publish(r).expect("publish");
        }
        p.end_of_stream().expect("end");
        assert!(p.linger(Duration::from_secs(10)).expect("linger"));
        p.identity()
    })
}

/// `qicp_io::RecordSource`'s blanket impl, bound for bound: what it accepts is a record source.
fn takes<I, E>(source: I) -> I
where
    I: Iterator<Item = Result<Record, E>>,
    E: std::error::Error + Send + Sync + 'static,
{
    source
}

#[test]
fn records_arrive_equal_in_order_then_none() {
    let topics = topics("equal");
    let sent: Vec<Record> = (0..40).map(record).collect();
    let mut subscriber = subscriber(&topics);
    let publisher = publish(&topics, sent.clone());
    let mut records: Records<'_> = takes(subscriber.records().expect("records"));
    let mut got = Vec::new();
    while let Some(item) = records.next() {
        let record = item.expect("record");
        let header = records.last_header().expect("a header with every record");
        assert_eq!(header.seq, got.len() as u64);
        assert_eq!(header.timestamp, record.timestamp());
        got.push(record);
    }
    assert!(records.is_finished());
    assert!(records.next().is_none(), "None stays None");
    let report = records.report().clone();
    let last = records.last_header().copied();
    let rejected = records.rejected();
    drop(records);
    drop(subscriber); // the publisher lingers until its subscribers have left
    let identity = publisher.join().expect("publisher thread");
    assert_eq!(got.len(), sent.len());
    for (g, s) in got.iter().zip(&sent) {
        assert_eq!(g.timestamp(), s.timestamp());
        assert_eq!(g.scan.ranges(), s.scan.ranges());
        assert_eq!(g.odometry, s.odometry);
        assert_eq!(g.truth, s.truth);
    }
    assert_eq!(got, sent);
    assert_eq!(last.map(|h| h.publisher), Some(identity));
    assert_eq!(report.end, Some(StreamEnd::EndOfStream));
    assert_eq!(report.received, sent.len() as u64);
    assert!(report.is_complete(), "{report:?}");
    assert_eq!(rejected, 0);
}

#[test]
fn a_scan_that_is_no_record_is_an_error_item() {
    let topics = topics("rejected");
    let mut sent: Vec<Record> = (0..5).map(record).collect();
    sent[2].odometry.x = 1e12; // off the map: the subscriber refuses it
    let mut subscriber = subscriber(&topics);
    let publisher = publish(&topics, sent.clone());
    let mut records = subscriber.records().expect("records");
    let items: Vec<_> = records.by_ref().collect();
    let (report, rejected) = (records.report().clone(), records.rejected());
    drop(records);
    drop(subscriber);
    publisher.join().expect("publisher thread");
    assert_eq!(items.len(), 5);
    for (i, item) in items.iter().enumerate() {
        match item {
            Ok(r) => assert_eq!(r, &sent[i]),
            Err(ReceiveError::Rejected { seq, service, .. }) => {
                assert_eq!((i, *seq), (2, 2));
                assert_eq!(service, &topics.scan());
            }
            Err(e) => panic!("item {i}: {e}"),
        }
    }
    assert!(items[2].is_err());
    assert_eq!(rejected, 1);
    assert_eq!(report.received, 5);
    assert_eq!(report.end, Some(StreamEnd::EndOfStream));
}

#[test]
fn no_publisher_ends_the_iteration() {
    let mut subscriber = common::impatient_subscriber(&topics("nobody"));
    let mut records = subscriber.records().expect("records");
    assert!(records.next().is_none());
    assert_eq!(records.report().end, Some(StreamEnd::NoPublisher));
    assert!(records.last_header().is_none());
    drop(records);
    // The subscriber's own loop still runs after an iteration (the WaitSet is reused).
    let report = subscriber
        .run(|_| std::ops::ControlFlow::Continue(()))
        .expect("run");
    assert_eq!(report.end, Some(StreamEnd::NoPublisher));
}
