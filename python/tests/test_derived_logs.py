"""The derived logs (python/benchmarks/derived_logs.py): exact transformations of a log and its
relations, each its own inverse."""

import bz2
import importlib.util
import itertools
import math

import numpy as np
import pytest

import qicp

from conftest import INTEL_RELATIONS, REPO

SCRIPT = REPO / "python" / "benchmarks" / "derived_logs.py"
SPEC = importlib.util.spec_from_file_location("derived_logs", SCRIPT)
derived_logs = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(derived_logs)


def intel_head(intel, lines):
    with bz2.open(intel, "rt") as f:
        return [line.rstrip("\n") for line in itertools.islice(f, lines)]


def numbers(lines):
    """Each line's fields, numbers as floats; an angular offset of 0 left out (mirroring twice
    writes it where the log had none)."""
    out = []
    for line in lines:
        fields = line.split()
        if fields[:2] == ["PARAM", derived_logs.ANGULAR_OFFSET] and float(fields[2]) == 0.0:
            continue
        parsed = []
        for f in fields:
            try:
                parsed.append(float(f))
            except ValueError:
                parsed.append(f)
        out.append(parsed)
    return out


def close(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert len(x) == len(y), (x[:3], y[:3])
        for u, v in zip(x, y):
            if isinstance(u, float):
                assert u == pytest.approx(v, abs=1e-9), (x[:3], u, v)
            else:
                assert u == v


def test_mirroring_or_reversing_twice_gives_the_log_back(intel):
    log = intel_head(intel, 600)
    close(numbers(derived_logs.mirror(derived_logs.mirror(log))), numbers(log))
    close(numbers(derived_logs.reverse(derived_logs.reverse(log))), numbers(log))
    relations = INTEL_RELATIONS.read_text().splitlines()[:50]
    for kind in ("mirror", "reverse"):
        once = derived_logs.relations(relations, kind, log)
        log_once = derived_logs.reverse(log) if kind == "reverse" else log
        back = derived_logs.relations(once, kind, log_once)
        close(numbers(back), numbers(relations))


def test_a_reversed_relation_names_the_same_records(intel):
    # Each relation's timestamps, mapped, must find the laser lines that hold the same
    # odometry as the original's lines at the original timestamps.
    log = intel_head(intel, 3000)
    odometry = {}
    for fields in map(str.split, log):
        if fields and fields[0] == "FLASER":
            n = int(fields[1])
            odometry[fields[-3]] = fields[2 + n + 3 : 2 + n + 6]
    stamps = sorted(odometry)[::50]
    relations = [f"{a} {b} 1.0 0.0 0 0 0 0.1" for a, b in zip(stamps, stamps[1:])]
    reversed_log = derived_logs.reverse(log)
    reversed_odometry = {}
    for fields in map(str.split, reversed_log):
        if fields and fields[0] == "FLASER":
            n = int(fields[1])
            reversed_odometry[fields[-3]] = fields[2 + n + 3 : 2 + n + 6]
    mapped = derived_logs.relations(relations, "reverse", log)
    assert len(mapped) == len(relations) > 10
    for before, after in zip(relations, mapped):
        a, b = before.split()[:2]
        ra, rb = after.split()[:2]
        assert reversed_odometry[ra] == odometry[a] and reversed_odometry[rb] == odometry[b]
        assert after.split()[2:] == before.split()[2:]
    # Played backwards: the laser lines in reverse order (Intel's stamps jitter, so file
    # order, not time order), each stamp mapped.
    def laser(lines):
        return [f for f in map(str.split, lines) if f and f[0] == "FLASER"]

    to_reversed = derived_logs.time_map(log)
    assert [f[-3] for f in laser(reversed_log)] == [to_reversed(f[-3]) for f in laser(log)[::-1]]


def robot_frame_points(record):
    """The scan's points (valid ranges) in the robot frame, beam by beam."""
    ranges = record.ranges
    angles = record.angle_min + record.angle_increment * np.arange(len(ranges))
    off = record.laser_offset
    valid = (ranges > record.range_min) & (ranges < record.range_max)
    x, y = ranges * np.cos(angles), ranges * np.sin(angles)
    c, s = math.cos(off[2]), math.sin(off[2])
    points = np.stack([off[0] + c * x - s * y, off[1] + s * x + c * y], axis=1)
    return np.where(valid[:, None], points, np.nan)


def test_a_mirrored_log_reads_as_the_mirror_image(intel, tmp_path):
    # Intel's 180 beams do not span their field of view symmetrically (the last one a step
    # short of +90°): without the angular offset the mirrored scans would read one beam step
    # (1°) turned, which matching turns into decimetres over a drive.
    log = intel_head(intel, 600)
    (tmp_path / "log.clf").write_text("\n".join(log) + "\n")
    (tmp_path / "mirror.clf").write_text("\n".join(derived_logs.mirror(log)) + "\n")
    original = list(qicp.read_carmen(tmp_path / "log.clf"))
    mirrored = list(qicp.read_carmen(tmp_path / "mirror.clf"))
    assert len(original) == len(mirrored) > 150
    for a, b in zip(original, mirrored):
        pa, pb = robot_frame_points(a), robot_frame_points(b)[::-1]
        np.testing.assert_allclose(pb, pa * [1.0, -1.0], atol=1e-9)
        (x, y, theta), (mx, my, mtheta) = a.odometry, b.odometry
        assert (mx, my, mtheta) == pytest.approx((x, -y, -theta), abs=1e-12)


def tum_from_odometry(log):
    """The log's laser odometry as a TUM trajectory (pure yaw), stamped as the laser lines."""
    out = []
    for fields in map(str.split, log):
        if fields and fields[0] == "FLASER":
            n = int(fields[1])
            x, y, theta = map(float, fields[2 + n + 3 : 2 + n + 6])
            qz, qw = math.sin(theta / 2), math.cos(theta / 2)
            out.append(f"{fields[-3]} {x!r} {y!r} 0 0 0 {qz!r} {qw!r}")
    return out


def poses(tum):
    """Stamp -> (x, y, θ) of a TUM trajectory."""
    out = {}
    for f in map(str.split, tum):
        x, y, qz, qw = float(f[1]), float(f[2]), float(f[6]), float(f[7])
        out[f[0]] = (x, y, 2 * math.atan2(qz, qw))
    return out


def between(a, b):
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return c * dx + s * dy, -s * dx + c * dy, math.remainder(b[2] - a[2], 2 * math.pi)


def test_a_derived_trajectory_agrees_with_the_derived_relations(intel):
    # A sweep of a derived log without relations is scored against a reference trajectory
    # transformed with it: relations drawn along that trajectory must be the transformed
    # relations of the original, and transforming twice gives the trajectory back.
    log = intel_head(intel, 3000)
    tum = tum_from_odometry(log)
    stamps = [line.split()[0] for line in tum][::40]
    pairs = list(zip(stamps, stamps[1:]))
    original = poses(tum)
    relations = []
    for a, b in pairs:
        dx, dy, dth = between(original[a], original[b])
        relations.append(f"{a} {b} {dx!r} {dy!r} 0 0 0 {dth!r}")
    assert len(relations) > 10
    for kind in ("mirror", "reverse"):
        log_once = derived_logs.reverse(log) if kind == "reverse" else log
        once = derived_logs.trajectory(tum, kind, log)
        close(numbers(derived_logs.trajectory(once, kind, log_once)), numbers(tum))
        moved = poses(once)
        for relation in derived_logs.relations(relations, kind, log):
            f = relation.split()
            expected = (float(f[2]), float(f[3]), float(f[7]))
            got = between(moved[f[0]], moved[f[1]])
            assert got == pytest.approx(expected, abs=1e-9), (kind, f[:2])
    # Played backwards, the poses run in the order of the reversed log's laser lines (file
    # order: Intel's stamps jitter).
    back = [line.split()[0] for line in derived_logs.trajectory(tum, "reverse", log)]
    assert back == [line.split()[0] for line in tum_from_odometry(derived_logs.reverse(log))]
