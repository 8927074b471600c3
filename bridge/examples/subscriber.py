"""qicp bridge subscriber in Python: reads qicp's scans and poses from iceoryx2, zero-copy.

How to run (iceoryx2 from PyPI, the same version as the Rust crate):

    python3 -m venv target/bridge-venv
    target/bridge-venv/bin/pip install 'iceoryx2==0.10.*'
    target/bridge-venv/bin/python bridge/examples/subscriber.py            # terminal 1
    qicp match --subscribe --matcher q-wsm --out /tmp/park-match            # terminal 2
    qicp sim configs/worlds/park.toml --publish --wait-subscribers 2        # terminal 3

Arguments: [PREFIX] (default "qicp": services qicp/scan and qicp/pose), --timeout SECONDS
(give up when nothing arrives for this long, default 30). It waits on a WaitSet (no spinning)
until both streams sent their end-of-stream marker, then prints a JSON summary on stdout.

The ctypes layouts below mirror qicp-bridge's `#[repr(C)]` types (bridge/README.md has the
tables); `type_name()` must return the Rust type names for iceoryx2 to match the services.
"""

import ctypes
import json
import sys
import time

import iceoryx2 as iox2

LAYOUT_VERSION = 3
KIND_DATA = 0
KIND_END_OF_STREAM = 1
FLAG_HAS_TRUTH = 1

# Must equal the Rust constants (qicp_bridge::SCAN_HISTORY_MAX, …): whichever process comes
# first creates the service with these settings, and the others require them.
SCAN_HISTORY_MAX = 64
SCAN_BUFFER_MAX = 256
POSE_HISTORY_MAX = 64
POSE_BUFFER_MAX = 256
MAX_SUBSCRIBERS = 8
MAX_PUBLISHERS = 1  # one owner per service: qicp refuses a service that allows more

# Event ids (qicp_bridge::event_id).
SAMPLE = 1
SUBSCRIBER_CONNECTED = 2
SUBSCRIBER_LEFT = 3
PUBLISHER_CONNECTED = 4
PUBLISHER_LEFT = 5
SUBSCRIBER_READY = 6


class PoseC(ctypes.Structure):
    """x, y (m), theta (rad): 24 bytes."""

    _fields_ = [("x", ctypes.c_double), ("y", ctypes.c_double), ("theta", ctypes.c_double)]

    @staticmethod
    def type_name() -> str:
        return "qicp::PoseC"


class ScanHeader(ctypes.Structure):
    """User header of a `<prefix>/scan` sample (144 bytes); the payload is `beams` doubles."""

    _fields_ = [
        ("layout_version", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("timestamp", ctypes.c_double),
        ("odometry", PoseC),
        ("truth", PoseC),
        ("laser_offset", PoseC),
        ("angle_min", ctypes.c_double),
        ("angle_increment", ctypes.c_double),
        ("max_range", ctypes.c_double),
        ("min_range", ctypes.c_double),
        ("beams", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("publisher", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "qicp::ScanHeader"


class PoseMessage(ctypes.Structure):
    """Payload of `<prefix>/pose` (176 bytes)."""

    _fields_ = [
        ("layout_version", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("scan_seq", ctypes.c_uint64),
        ("timestamp", ctypes.c_double),
        ("pose", PoseC),
        ("covariance", ctypes.c_double * 9),
        ("residual", ctypes.c_double),
        ("certainty", ctypes.c_double),
        ("fallback", ctypes.c_uint32),
        ("inserted", ctypes.c_uint32),
        ("iterations", ctypes.c_uint32),
        ("correspondences", ctypes.c_uint32),
        ("publisher", ctypes.c_uint64),
        ("scan_publisher", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "qicp::PoseMessage"


assert ctypes.sizeof(ScanHeader) == 144 and ctypes.sizeof(PoseMessage) == 176


class Stream:
    """One qicp stream: the publish-subscribe service, its event service, and the counts."""

    def __init__(self, node, name, payload, header=None, safe_overflow=False, history_max=64,
                 buffer_max=256):
        service_name = iox2.ServiceName.new(name)
        self.name = name
        builder = node.service_builder(service_name).publish_subscribe(payload)
        if header is not None:
            builder = builder.user_header(header)
        builder = (builder.history_size(history_max)
                   .subscriber_max_buffer_size(buffer_max)
                   .max_subscribers(MAX_SUBSCRIBERS)
                   .max_publishers(MAX_PUBLISHERS))
        try:
            # An existing service keeps its back-pressure mode; adopt it.
            self.service = builder.open()
        except iox2.PublishSubscribeOpenError:
            self.service = builder.enable_safe_overflow(safe_overflow).open_or_create()
        self.subscriber = self.service.subscriber_builder().create()
        events = node.service_builder(service_name).event().open_or_create()
        self.listener = events.listener_builder().create()
        self.notifier = events.notifier_builder().create()
        self.notifier.notify_with_custom_event_id(iox2.EventId.new(SUBSCRIBER_CONNECTED))
        self.known_publishers = -1
        self.expected = {}  # publisher id -> next seq
        self.received = 0
        self.missing = 0
        self.missed_before_join = 0
        self.ended = False

    def publishers(self):
        return self.service.dynamic_config.number_of_publishers

    def handle_events(self):
        """Consumes the listener's events; tells new publishers this subscriber is ready."""
        seen = [e.id.as_value for e in self.listener.try_wait()]
        count = self.publishers()
        if PUBLISHER_CONNECTED in seen or count > self.known_publishers:
            self.subscriber.has_samples()  # attaches to every publisher counted above
            if count > 0:
                self.notifier.notify_with_custom_event_id(iox2.EventId.new(SUBSCRIBER_READY))
        self.known_publishers = count

    def check(self, origin, seq):
        """Sequence check: counts late-join skips and gaps, like qicp_bridge::SequenceTracker."""
        expected = self.expected.get(origin)
        if expected is None:
            self.missed_before_join += seq
        elif seq > expected:
            self.missing += seq - expected
        self.expected[origin] = seq + 1
        self.received += 1

    def close(self):
        self.subscriber.delete()
        self.notifier.notify_with_custom_event_id(iox2.EventId.new(SUBSCRIBER_LEFT))


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    prefix = args[0] if args else "qicp"
    timeout = 30.0
    if "--timeout" in sys.argv:
        timeout = float(sys.argv[sys.argv.index("--timeout") + 1])

    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    # iceoryx2's built-in settings, as qicp uses by default: without .config() iceoryx2 would
    # read config/iceoryx2.toml from the working directory, and might not meet qicp.
    node = iox2.NodeBuilder.new().config(iox2.config.default()).create(iox2.ServiceType.Ipc)
    scans = Stream(node, f"{prefix}/scan", iox2.Slice[ctypes.c_double], ScanHeader,
                   safe_overflow=False, history_max=SCAN_HISTORY_MAX, buffer_max=SCAN_BUFFER_MAX)
    poses = Stream(node, f"{prefix}/pose", PoseMessage, None, safe_overflow=True,
                   history_max=POSE_HISTORY_MAX, buffer_max=POSE_BUFFER_MAX)

    waitset = iox2.WaitSetBuilder.new().create(iox2.ServiceType.Ipc)
    guards = [waitset.attach_notification(s.listener) for s in (scans, poses)]
    print(f"waiting on {scans.name} and {poses.name}", file=sys.stderr, flush=True)

    summary = {"scans": 0, "beams": None, "range_sum": 0.0, "truth_poses": 0, "poses": 0,
               "last_pose": None, "matched": 0, "scan_publisher": None}
    last_activity = time.monotonic()
    while not (scans.ended and poses.ended):
        for stream in (scans, poses):
            stream.handle_events()

        while (sample := scans.subscriber.receive()) is not None:
            header = sample.user_header().contents
            assert header.layout_version == LAYOUT_VERSION, header.layout_version
            if header.kind == KIND_END_OF_STREAM:
                scans.ended = True
                summary["scans_announced"] = header.seq
                break
            # The publisher's identity is in the header too (header.publisher); iceoryx2's
            # publisher_id is the same port's full id.
            scans.check(str(sample.header.publisher_id), header.seq)
            ranges = sample.payload()  # an iox2.Slice: a view into shared memory, no copy
            # The Python binding 0.10 reports Slice.len() of a received [f64] in bytes, not
            # elements: take the count from the header (and check it fits).
            beams = header.beams
            assert beams * ctypes.sizeof(ctypes.c_double) <= ranges.len(), beams
            # A ctypes array over the same shared memory, no copy.
            values = (ctypes.c_double * beams).from_address(ranges.as_ptr())
            summary["scans"] += 1
            summary["beams"] = beams
            summary["scan_publisher"] = header.publisher
            summary["range_sum"] += sum(values)
            summary["truth_poses"] += 1 if header.flags & FLAG_HAS_TRUTH else 0
            last_activity = time.monotonic()

        while (sample := poses.subscriber.receive()) is not None:
            pose = sample.payload().contents
            if pose.kind == KIND_END_OF_STREAM:
                poses.ended = True
                summary["poses_announced"] = pose.seq
                break
            poses.check(str(sample.header.publisher_id), pose.seq)
            summary["poses"] += 1
            summary["matched"] += 1 if pose.fallback == 0 else 0
            summary["last_pose"] = {"scan_seq": pose.scan_seq,
                                    "scan_publisher": pose.scan_publisher,
                                    "publisher": pose.publisher, "timestamp": pose.timestamp,
                                    "x": pose.pose.x, "y": pose.pose.y, "theta": pose.pose.theta,
                                    "covariance": list(pose.covariance)}
            last_activity = time.monotonic()

        if scans.ended and poses.ended:
            break
        if time.monotonic() - last_activity > timeout:
            summary["timeout"] = True
            break
        # Sleep until an event (or 100 ms, to notice silence).
        waitset.wait_and_process_with_timeout(iox2.Duration.from_millis(100))

    for stream, key in ((scans, "scan"), (poses, "pose")):
        summary[f"{key}_missing"] = stream.missing
        summary[f"{key}_missed_before_join"] = stream.missed_before_join
        summary[f"{key}_end"] = stream.ended
        stream.close()
    del guards
    print(json.dumps(summary))
    return 0 if scans.ended and poses.ended else 1


if __name__ == "__main__":
    sys.exit(main())
