"""A long drive from a short log: N passes over a CARMEN log, every second one reversed in time.

    python examples/intel_passes.py LOG PASSES OUT [--order file|time]

Writes OUT, a CARMEN log of the PARAM lines of LOG followed by its FLASER lines PASSES times:
pass 1 as recorded, pass 2 backwards (the robot drives its path again from its end to its
start, so the drive has no jump), pass 3 forwards again, and so on, each pass's timestamps
shifted to follow the last. `--order time` sorts the laser lines by timestamp first (the
default keeps the file's order, the order the laser took them). It is the long log of the
README's memory and revisit figures (`qicp match OUT --matcher q-wsm`, peak memory with
`/usr/bin/time -f %M`): the drive revisits every place once per pass, so what grows with the
passes is the map, not the place.
"""

import argparse
import bz2
import sys


def open_log(path):
    """The log's text, plain or bz2."""
    with open(path, "rb") as f:
        magic = f.read(3)
    return bz2.open(path, "rt") if magic == b"BZh" else open(path, "rt")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="CARMEN log (plain or .bz2) with FLASER lines")
    parser.add_argument("passes", type=int, help="number of passes (at least 1)")
    parser.add_argument("out", help="the CARMEN log to write")
    parser.add_argument("--order", choices=["file", "time"], default="file")
    args = parser.parse_args()
    if args.passes < 1:
        sys.exit("passes must be at least 1")

    params, lasers = [], []
    with open_log(args.log) as f:
        for line in f:
            if line.startswith("PARAM"):
                params.append(line.rstrip("\n"))
            elif line.startswith("FLASER"):
                lasers.append(line.split())
    if not lasers:
        sys.exit(f"{args.log}: no FLASER lines")
    # FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp
    stamps = [float(fields[-3]) for fields in lasers]
    if args.order == "time":
        order = sorted(range(len(lasers)), key=lambda i: stamps[i])
        lasers = [lasers[i] for i in order]
        stamps = [stamps[i] for i in order]
    first, last = min(stamps), max(stamps)
    span = last - first + 0.1

    with open(args.out, "w") as out:
        for line in params:
            out.write(line + "\n")
        for k in range(args.passes):
            forward = k % 2 == 0
            indices = range(len(lasers)) if forward else range(len(lasers) - 1, -1, -1)
            for i in indices:
                fields = list(lasers[i])
                offset = stamps[i] - first if forward else last - stamps[i]
                stamp = first + k * span + offset
                fields[-3] = f"{stamp:.6f}"
                fields[-1] = f"{stamp - first:.6f}"
                out.write(" ".join(fields) + "\n")
    print(f"{args.out}: {args.passes} passes of {len(lasers)} scans")


if __name__ == "__main__":
    main()
