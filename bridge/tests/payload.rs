//! Byte payloads: written into the loan, read in place, every byte and every message in order;
//! the service is sized for its payload and has one owner.

use qicp_bridge::payload::{PayloadPublisher, PayloadSubscriber, Waiting};
use qicp_bridge::{ConnectError, Topics};
use std::ops::ControlFlow;
use std::time::Duration;

fn topics(test: &str) -> Topics {
    Topics::new(&format!("qicp-payload-{}-{test}", std::process::id()))
}

fn byte(i: usize, seq: u64) -> u8 {
    (i as u8).wrapping_mul(3).wrapping_add(seq as u8)
}

#[test]
fn payloads_arrive_whole_and_in_order_read_in_place() {
    const BYTES: usize = 100_003;
    const MESSAGES: u64 = 40;
    for waiting in [Waiting::Event, Waiting::Spin] {
        let topics = topics(&format!("{waiting:?}"));
        let subscriber = PayloadSubscriber::create(&topics, 2).expect("subscriber");
        let t = topics.clone();
        let publisher = std::thread::spawn(move || {
            let notify = waiting == Waiting::Event;
            let mut p = PayloadPublisher::create(&t, BYTES, 2, notify, Duration::from_secs(10))
                .expect("publisher");
            assert!(
                p.wait_for_subscriber(Duration::from_secs(10))
                    .expect("wait")
            );
            for seq in 0..MESSAGES {
                let s = p
                    .publish_with(BYTES, |i| byte(i, seq), || seq as f64)
                    .expect("publish");
                assert_eq!(s, seq);
            }
            // Leave only once everything was read (the subscriber drops first).
            std::thread::sleep(Duration::from_millis(200));
            p.sent()
        });
        let mut next = 0u64;
        let received = subscriber
            .run(waiting, Duration::from_secs(10), |header, payload| {
                assert_eq!(header.seq, next);
                assert_eq!(header.sent, next as f64);
                assert_eq!(payload.len(), BYTES);
                assert!(payload.iter().enumerate().all(|(i, b)| *b == byte(i, next)));
                next += 1;
                if next == MESSAGES {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            })
            .expect("run");
        assert_eq!(received, MESSAGES, "{waiting:?}");
        drop(subscriber);
        assert_eq!(publisher.join().expect("publisher thread"), MESSAGES);
    }
}

#[test]
fn second_payload_publisher_is_refused() {
    let topics = topics("owner");
    let _first =
        PayloadPublisher::create(&topics, 1024, 2, true, Duration::from_secs(1)).expect("first");
    let second = PayloadPublisher::create(&topics, 1024, 2, true, Duration::from_secs(1));
    assert!(
        matches!(second, Err(ConnectError::Owned { .. })),
        "{second:?}"
    );
}

#[test]
fn payloads_sent_just_before_the_publisher_leaves_are_all_taken() {
    // A publisher that leaves right after its last payload: the subscriber ends its run on
    // the publisher's leaving only once every payload sent before it was taken. (It counts
    // the publishers before each look at its buffer; the race this order closes, a payload
    // and the leaving both falling between an empty look and the count, is too narrow to
    // hit on purpose, so twenty rounds run with the threads interleaving as they will.)
    const MESSAGES: u64 = 3;
    for round in 0..20 {
        let topics = topics(&format!("leave-{round}"));
        let subscriber = PayloadSubscriber::create(&topics, 4).expect("subscriber");
        let t = topics.clone();
        let publisher = std::thread::spawn(move || {
            let mut p = PayloadPublisher::create(&t, 64, 4, true, Duration::from_secs(10))
                .expect("publisher");
            assert!(
                p.wait_for_subscriber(Duration::from_secs(10))
                    .expect("wait")
            );
            for seq in 0..MESSAGES {
                p.publish_with(64, |i| byte(i, seq), || seq as f64)
                    .expect("publish");
            }
        });
        let mut next = 0u64;
        let received = subscriber
            .run(
                Waiting::Event,
                Duration::from_secs(10),
                |header, payload| {
                    assert_eq!(header.seq, next);
                    assert!(payload.iter().enumerate().all(|(i, b)| *b == byte(i, next)));
                    next += 1;
                    ControlFlow::Continue(())
                },
            )
            .expect("run");
        publisher.join().expect("publisher thread");
        assert_eq!(received, MESSAGES, "round {round}");
    }
}
