//! What the bridge's integration tests share: service names unique to a test run, a record
//! whose every field tells it apart, and short timeouts.

#![allow(dead_code)]

use qicp_bridge::{ScanSubscriber, SubscriberOptions, Topics, WaitOptions};
use qicp_core::{BeamGeometry, Pose2, Record, Scan};
use std::time::Duration;

/// Services of the test `test` of the suite `suite`, unique to this process.
pub fn topics(suite: &str, test: &str) -> Topics {
    Topics::new(&format!("qicp-{suite}-{}-{test}", std::process::id()))
}

/// Record `i`: 181 beams whose ranges, time, odometry and (every second record) truth all
/// depend on `i`.
pub fn record(i: usize) -> Record {
    let geometry = BeamGeometry::centered(181, std::f64::consts::PI, 20.0);
    let ranges = (0..181)
        .map(|b| 1.0 + (i * 181 + b) as f64 * 1e-3)
        .collect();
    Record {
        scan: Scan::new(i as f64 * 0.1, geometry, ranges).expect("scan"),
        odometry: Pose2::new(i as f64, 0.5, 0.01 * i as f64),
        truth: i.is_multiple_of(2).then(|| Pose2::new(i as f64, 0.0, 0.0)),
        laser_offset: Pose2::IDENTITY,
    }
}

/// Timeouts short enough for tests, long enough for a loaded machine.
pub fn quick_wait() -> WaitOptions {
    WaitOptions {
        connect_timeout: Duration::from_secs(10),
        reconnect_timeout: Duration::from_secs(2),
        idle_timeout: Duration::from_secs(10),
        tick: Duration::from_millis(50),
    }
}

/// A scan subscriber on `topics` that gives up 0.3 s after finding no publisher.
pub fn impatient_subscriber(topics: &Topics) -> ScanSubscriber {
    ScanSubscriber::create(
        topics,
        &SubscriberOptions {
            wait: WaitOptions {
                connect_timeout: Duration::from_millis(300),
                ..quick_wait()
            },
            ..SubscriberOptions::default()
        },
    )
    .expect("subscriber")
}
