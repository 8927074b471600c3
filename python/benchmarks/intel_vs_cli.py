"""Whole-log time of a matcher through the Python package against the `qicp match` command.

    python python/benchmarks/intel_vs_cli.py [--matcher q-wsm] [--runs 3]

Runs the two alternately (so that load on the machine falls on both) and prints JSON with
each run's seconds, the medians and their ratio, and whether the trajectories are identical.
Both read and parse the bzip2 log; the command line also writes its outputs.
"""

import argparse
import json
import pathlib
import statistics
import subprocess
import tempfile
import time

import qicp

REPO = pathlib.Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default=REPO.parent / "shared/data/intel/intel.clf.bz2")
    ap.add_argument("--matcher", default="q-wsm")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--qicp", default=REPO / "target/release/qicp")
    a = ap.parse_args()
    cli_s, py_s, identical = [], [], True
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        for k in range(a.runs):
            out = tmp / f"cli{k}"
            t0 = time.perf_counter()
            subprocess.run(
                [str(a.qicp), "match", str(a.log), "--matcher", a.matcher, "--out", str(out)],
                check=True,
                capture_output=True,
            )
            cli_s.append(time.perf_counter() - t0)

            t0 = time.perf_counter()
            m = qicp.Matcher(a.matcher)
            traj = []
            for r in qicp.read_carmen(a.log):
                res = m.process_record(r)
                if res.amendment is not None:
                    res.amendment.apply(traj)
                traj.append((res.timestamp, *res.pose))
            py_s.append(time.perf_counter() - t0)
            qicp.write_tum(tmp / "py.tum", traj)
            identical &= (tmp / "py.tum").read_bytes() == (out / "trajectory.tum").read_bytes()
    cli, py = statistics.median(cli_s), statistics.median(py_s)
    print(
        json.dumps(
            {
                "log": str(a.log),
                "matcher": a.matcher,
                "cli_seconds": cli_s,
                "python_seconds": py_s,
                "cli_median_s": cli,
                "python_median_s": py,
                "ratio": py / cli,
                "identical_trajectories": identical,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
