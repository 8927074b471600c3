"""ROS 2 bags: a bag written by the PyPI packages `mcap` and `mcap-ros2-support` (independent
of qicp's writer) matches like the CARMEN log it came from; qicp's own bags read back with
those packages."""

import itertools
import math

import mcap_ros2.writer as mcap_ros2_writer
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest

import qicp
from conftest import run_cli

SCANS = 2000
SEP = "=" * 80 + "\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
VEC3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
LASER_SCAN = SEP.join(
    [
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n",
        HEADER,
        TIME,
    ]
)
ODOMETRY = SEP.join(
    [
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n",
        HEADER,
        TIME,
        "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n",
        "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n",
        "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
        QUAT,
        "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n",
        "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n",
        VEC3,
    ]
)


def stamp(t):
    sec = math.floor(t)
    nsec = round((t - sec) * 1e9)
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return {"sec": sec, "nanosec": nsec}, sec * 1_000_000_000 + nsec


def write_bag(path, records, odometry=True, scan_topic="/scan"):
    """The records as a rosbag2 MCAP file: LaserScan on /scan, Odometry on /odom."""
    with open(path, "wb") as f:
        w = mcap_ros2_writer.Writer(f)
        scan_schema = w.register_msgdef("sensor_msgs/msg/LaserScan", LASER_SCAN)
        odom_schema = w.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY)
        for r in records:
            st, ns = stamp(r.timestamp)
            n = len(r.ranges)
            header = {"stamp": st, "frame_id": "laser"}
            scan = {
                "header": header,
                "angle_min": r.angle_min,
                "angle_max": r.angle_min + (n - 1) * r.angle_increment,
                "angle_increment": r.angle_increment,
                "time_increment": 0.0,
                "scan_time": 0.0,
                "range_min": r.range_min,
                "range_max": r.range_max,
                "ranges": [float(x) for x in r.ranges],
                "intensities": [],
            }
            w.write_message(scan_topic, scan_schema, scan, log_time=ns, publish_time=ns)
            if not odometry:
                continue
            x, y, th = r.odometry
            odom = {
                "header": {"stamp": st, "frame_id": "odom"},
                "child_frame_id": "base_link",
                "pose": {
                    "pose": {
                        "position": {"x": x, "y": y, "z": 0.0},
                        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(th / 2), "w": math.cos(th / 2)},
                    },
                    "covariance": [0.0] * 36,
                },
                "twist": {
                    "twist": {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}},
                    "covariance": [0.0] * 36,
                },
            }
            w.write_message("/odom", odom_schema, odom, log_time=ns, publish_time=ns)
        w.finish()


@pytest.fixture(scope="module")
def records(intel):
    # In time order, as a bag holds them and `qicp convert` writes them (Intel's stamps jitter
    # against its file order, and a bag's odometry is interpolated by stamp).
    return list(itertools.islice(qicp.read_carmen(intel, order="time"), SCANS))


@pytest.fixture(scope="module")
def bag(records, tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "intel2k.mcap"
    write_bag(path, records)
    return path


def messages(path):
    """(topic, decoded message) of every message of a bag, decoded by mcap-ros2-support."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            yield channel.topic, msg


def match_bag(qicp_bin, bag, matcher, out, *extra):
    cli = run_cli(qicp_bin, "match", bag, "--matcher", matcher, "--out", out, *extra)
    assert cli.returncode == 0, cli.stderr
    return qicp.read_tum(out / "trajectory.tum")


def python_run(records, matcher, float32=False):
    f = (lambda v: float(np.float32(v))) if float32 else float
    m = qicp.Matcher(matcher)
    out = []
    for r in records:
        ranges = r.ranges.astype(np.float32).astype(np.float64) if float32 else r.ranges
        res = m.process(
            ranges,
            f(r.angle_min),
            f(r.angle_increment),
            odometry=r.odometry,
            timestamp=r.timestamp,
            range_max=f(r.range_max),
            range_min=f(r.range_min),
            laser_offset=r.laser_offset,
        )
        if res.amendment is not None:  # as the command line's trajectory takes it
            res.amendment.apply(out)
        out.append((res.timestamp, *res.pose))
    return np.array(out)


def position_gap(a, b):
    assert a.shape == b.shape
    assert np.abs(a[:, 0] - b[:, 0]).max() < 1e-6  # the same scans, the same times
    return np.hypot(*(a[:, 1:3] - b[:, 1:3]).T).max()


def test_a_bag_of_the_first_2000_intel_scans_matches_like_the_log(qicp_bin, bag, records, tmp_path):
    # Scan to scan, the float32 ranges and angles of LaserScan are the only difference.
    wsm = match_bag(qicp_bin, bag, "wsm", tmp_path / "wsm")
    assert position_gap(wsm, python_run(records, "wsm")) < 1e-3
    # The map matcher amplifies that rounding, so compare it with the log's scans rounded to
    # float32 as LaserScan stores them: nothing else may differ.
    qwsm = match_bag(qicp_bin, bag, "q-wsm", tmp_path / "qwsm")
    assert position_gap(qwsm, python_run(records, "q-wsm", float32=True)) < 1e-3


def test_convert_writes_the_bag_the_independent_writer_writes(qicp_bin, intel, bag, tmp_path):
    ours = tmp_path / "ours.mcap"
    cli = run_cli(qicp_bin, "convert", intel, ours, "--max-records", SCANS)
    assert cli.returncode == 0, cli.stderr
    a = match_bag(qicp_bin, ours, "q-wsm", tmp_path / "a")
    b = match_bag(qicp_bin, bag, "q-wsm", tmp_path / "b")
    assert position_gap(a, b) < 1e-9

    # And the independent reader decodes qicp's bag.
    scans = odoms = 0
    for topic, msg in messages(ours):
        if topic == "/scan":
            scans += 1
            assert msg.header.frame_id == "laser" and len(msg.ranges) == 180
        elif topic == "/odom":
            odoms += 1
    assert scans == SCANS and odoms == SCANS


def test_out_mcap_holds_the_estimated_poses(qicp_bin, bag, tmp_path):
    out = tmp_path / "run.mcap"
    traj = match_bag(qicp_bin, bag, "wsm", tmp_path / "run", "--out-mcap", out)
    poses = []
    tf_map_odom = 0
    for topic, msg in messages(out):
        if topic == "/qicp/odom":
            p = msg.pose.pose
            q = p.orientation
            poses.append((p.position.x, p.position.y, 2 * math.atan2(q.z, q.w)))
            assert msg.header.frame_id == "map"
        elif topic == "/tf":
            tf_map_odom += sum(t.header.frame_id == "map" for t in msg.transforms)
    poses = np.array(poses)
    assert len(poses) == len(traj) == SCANS and tf_map_odom == SCANS
    assert np.abs(poses[:, :2] - traj[:, 1:3]).max() < 1e-9


def test_bag_errors_name_what_is_missing(qicp_bin, records, bag, tmp_path):
    cli = run_cli(qicp_bin, "match", bag, "--matcher", "wsm", "--out", tmp_path / "a", "--scan-topic", "/nope")
    assert cli.returncode != 0
    assert "no topic /nope; the bag has: /odom (nav_msgs/msg/Odometry), /scan (sensor_msgs/msg/LaserScan)" in cli.stderr
    cli = run_cli(qicp_bin, "match", bag, "--matcher", "wsm", "--out", tmp_path / "b", "--scan-topic", "/odom")
    assert "topic /odom carries nav_msgs/msg/Odometry, not sensor_msgs/msg/LaserScan" in cli.stderr
    lonely = tmp_path / "lonely.mcap"
    write_bag(lonely, records[:20], odometry=False)
    cli = run_cli(qicp_bin, "match", lonely, "--matcher", "wsm", "--out", tmp_path / "c")
    assert cli.returncode != 0 and "20 scans but no odometry topic /odom" in cli.stderr
    # Read without odometry, every scan is a record at one pose.
    cli = run_cli(qicp_bin, "match", lonely, "--matcher", "wsm", "--out", tmp_path / "e", "--no-odometry")
    assert cli.returncode == 0, cli.stderr
    assert len((tmp_path / "e" / "trajectory.tum").read_text().splitlines()) == 20
    unmoved = list(qicp.read_bag(lonely, odom_topic=None))
    assert len(unmoved) == 20 and all(r.odometry == (0.0, 0.0, 0.0) for r in unmoved)
    cli = run_cli(qicp_bin, "match", bag, "--matcher", "wsm", "--out", tmp_path / "d", "--odom-frame", "odom")
    assert cli.returncode != 0 and "no transform odom -> base_link on /tf" in cli.stderr


def test_read_bag_gives_the_records_qicp_match_reads(qicp_bin, bag, records, tmp_path):
    m = qicp.Matcher("wsm")
    log = qicp.read_bag(bag)
    traj = []
    for res in map(m.process_record, log):
        if res.amendment is not None:
            res.amendment.apply(traj)
        traj.append((res.timestamp, *res.pose))
    assert log.records == SCANS and log.dropped == 0
    qicp.write_tum(tmp_path / "py.tum", traj)
    cli = match_bag(qicp_bin, bag, "wsm", tmp_path / "cli")
    assert (tmp_path / "py.tum").read_bytes() == (tmp_path / "cli" / "trajectory.tum").read_bytes()
    assert len(cli) == SCANS
    first = next(iter(qicp.read_bag(bag)))
    assert first.ranges.tolist() == np.float32(records[0].ranges).astype(np.float64).tolist()
    assert np.allclose(first.odometry, records[0].odometry, atol=1e-12)

    with pytest.raises(qicp.QicpError, match="no topic /laser; the bag has: /odom"):
        list(qicp.read_bag(bag, scan_topic="/laser"))
    with pytest.raises(qicp.QicpError, match="not a ROS 2 bag"):
        qicp.read_bag(qicp_bin)
