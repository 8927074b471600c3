"""OpenKarto's correlative scan matcher (slam_toolbox's) as laser odometry, beside a qicp matcher.

    pip install karto-scanmatcher==1.0.0 ./python
    python python/benchmarks/karto_peer.py [--matcher q-wsm] [--buffer-scans 10]

Karto runs as slam_toolbox runs it between loop closures: each scan is predicted from the
previous corrected pose and the odometry since, and matched (with its motion penalty and the
fine refinement) against a running buffer of earlier scans. A scan joins the buffer once the
robot has moved `--buffer-travel` metres or turned as many radians since the last one joined,
and the buffer keeps the newest `--buffer-scans` within `--buffer-distance` metres (slam_toolbox:
0.5 m / 0.5 rad, 10 scans, 10 m). The matcher's parameters are slam_toolbox's defaults
(`--params slam_toolbox`: a distance penalty that holds the prediction where the scan does not,
a 0.5 m window, 20 m range) or the package's own (`--params karto`, OpenKarto's, without a
distance penalty: along a corridor the match then roams the window). Both trajectories are
scored with the same relations, and the qicp matcher runs in the same sitting through the
Python package (each run's seconds include reading and parsing the log). Prints JSON.
"""

import argparse
import itertools
import json
import math
import pathlib
import statistics
import time

import karto_scanmatcher as karto

import qicp

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared/data/intel"


def compose(a, b):
    """a ⊕ b for poses (x, y, θ)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


def inverse(a):
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


# slam_toolbox's mapper_params (correlation_search_space_*, *_penalty, *_angle_*).
SLAM_TOOLBOX = {
    "search_size": 0.5,
    "resolution": 0.01,
    "smear_deviation": 0.1,
    "distance_variance_penalty": 0.5,
    "angle_variance_penalty": 1.0,
    "fine_search_angle_resolution": 0.00349,
    "coarse_search_angle_offset": 0.349,
    "coarse_angle_resolution": 0.0349,
    "minimum_angle_penalty": 0.9,
    "minimum_distance_penalty": 0.5,
    "use_response_expansion": True,
}


def matcher_config(params):
    config = karto.ScanMatcherConfig()
    if params == "slam_toolbox":
        for key, value in SLAM_TOOLBOX.items():
            setattr(config, key, value)
    return config


def records(a):
    """The log's records, the first `--scans` of them if given."""
    return itertools.islice(qicp.read_carmen(a.log), a.scans or None)


def karto_run(a):
    """Karto's trajectory (robot poses) and the seconds each match took."""
    matcher = karto.Wrapper(matcher_config(a.params))
    buffer, traj, match_s = [], [], []
    last_buffered = None
    prev_odom = prev_pose = None
    for num, r in enumerate(records(a)):
        n = len(r.ranges)
        config = karto.LaserScanConfig(
            r.angle_min,
            r.angle_min + (n - 1) * r.angle_increment,
            r.angle_increment,
            r.range_min,
            r.range_max,
            min(r.range_max, a.range_threshold),
            "laser",
        )
        odom = r.odometry
        if prev_pose is None:
            pose = odom
        else:
            pose = compose(prev_pose, compose(inverse(prev_odom), odom))
        # Karto matches the laser's pose; the robot's is recovered through the laser's offset.
        laser = compose(pose, r.laser_offset)
        scan = karto.LocalizedRangeScan(
            config,
            r.ranges.tolist(),
            karto.Pose2(*compose(odom, r.laser_offset)),
            karto.Pose2(*laser),
            num,
            r.timestamp,
        )
        if buffer:
            t0 = time.perf_counter()
            best = matcher.match_scan(scan, buffer, True, True).best_pose
            match_s.append(time.perf_counter() - t0)
            laser = (best.x, best.y, best.yaw)
            scan.corrected_pose = best
            pose = compose(laser, inverse(r.laser_offset))
        traj.append((r.timestamp, *pose))
        moved = last_buffered is None or (
            math.hypot(laser[0] - last_buffered[0], laser[1] - last_buffered[1]) >= a.buffer_travel
            or abs(math.remainder(laser[2] - last_buffered[2], math.tau)) >= a.buffer_travel
        )
        if moved:
            buffer.append(scan)
            last_buffered = laser
            buffer = [
                s
                for s in buffer[-a.buffer_scans :]
                if math.hypot(s.corrected_pose.x - laser[0], s.corrected_pose.y - laser[1])
                <= a.buffer_distance
            ]
        prev_odom, prev_pose = odom, pose
    return traj, match_s


def qicp_run(a):
    """The qicp matcher's trajectory over the same records, as `qicp match` runs it."""
    matcher = qicp.Matcher(a.matcher)
    traj = []
    for res in map(matcher.process_record, records(a)):
        if res.amendment is not None:  # a re-anchoring spread over the poses before it
            res.amendment.apply(traj)
        traj.append((res.timestamp, *res.pose))
    return traj


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default=DATA / "intel.clf.bz2")
    ap.add_argument("--relations", default=DATA / "intel.relations")
    ap.add_argument("--matcher", default="q-wsm", help="the qicp matcher run beside Karto")
    ap.add_argument("--buffer-scans", type=int, default=10)
    ap.add_argument("--buffer-travel", type=float, default=0.5)
    ap.add_argument("--buffer-distance", type=float, default=10.0)
    ap.add_argument("--params", choices=("slam_toolbox", "karto"), default="slam_toolbox")
    ap.add_argument(
        "--range-threshold", type=float, help="m (default: 20 for slam_toolbox, 40 for karto)"
    )
    ap.add_argument("--scans", type=int, default=0, help="only the first N scans (0: all)")
    ap.add_argument("--out", help="write Karto's trajectory to DIR/karto.tum (default: not written)")
    a = ap.parse_args()
    if a.range_threshold is None:
        a.range_threshold = 20.0 if a.params == "slam_toolbox" else 40.0

    t0 = time.perf_counter()
    traj, match_s = karto_run(a)
    karto_s = time.perf_counter() - t0
    karto_scores = qicp.evaluate_relations(traj, a.relations)

    t0 = time.perf_counter()
    qicp_traj = qicp_run(a)
    qicp_s = time.perf_counter() - t0
    qicp_scores = qicp.evaluate_relations(qicp_traj, a.relations)
    if a.out:
        qicp.write_tum(pathlib.Path(a.out) / "karto.tum", traj)

    def figures(scores, seconds):
        keep = ("n", "missing", "trans_mean", "trans_max", "rot_mean_deg")
        return {"seconds": seconds, **{k: scores[k] for k in keep}}

    print(
        json.dumps(
            {
                "log": str(a.log),
                "scans": len(traj),
                "karto": {
                    **figures(karto_scores, karto_s),
                    "matches": len(match_s),
                    "ms_per_match_median": 1e3 * statistics.median(match_s) if match_s else None,
                    "params": a.params,
                    "range_threshold_m": a.range_threshold,
                    "buffer": {
                        "scans": a.buffer_scans,
                        "travel": a.buffer_travel,
                        "distance_m": a.buffer_distance,
                    },
                },
                a.matcher: figures(qicp_scores, qicp_s),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
