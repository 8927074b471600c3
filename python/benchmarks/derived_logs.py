"""Logs the defaults were never run on, scored exactly: a CARMEN log mirrored, or driven
backwards, with its relations transformed to match.

    python python/benchmarks/derived_logs.py mirror LOG RELATIONS OUT_LOG OUT_RELATIONS
    python python/benchmarks/derived_logs.py reverse LOG RELATIONS OUT_LOG OUT_RELATIONS
    qicp sweep OUT_LOG --matcher q-wsm --relations OUT_RELATIONS

A log without relations (MIT CSAIL, the Freiburg clinic) is swept against a trajectory of it
(`qicp sweep … --reference TUM`); `--trajectory TUM OUT_TUM` transforms one with the log,
and `-` stands for the relations:

    python python/benchmarks/derived_logs.py reverse LOG - OUT_LOG - --trajectory TUM OUT_TUM
    qicp sweep OUT_LOG --matcher q-idc --reference OUT_TUM

A matcher tuned on one log may owe part of its score to that log's chance: which corridor a
drift happened to slide along, which way the robot turned first. The two derived logs hold the
same building, laser and odometry, and their relations are exact, but every match is a
different computation:

- `mirror` reflects the world across the x axis of the odometry frame: every pose (x, y, θ)
  becomes (x, −y, −θ), every scan is read right to left, every relation (dx, dy, dθ) becomes
  (dx, −dy, −dθ). A `FLASER` scan of 180 or 360 beams does not span its field of view
  symmetrically (the first beam at −fov/2, the last one step short of +fov/2; see
  `qicp_io::carmen::flaser_geometry`), so its mirror image is laid out one step to the left of
  where a reader puts it: a `PARAM robot_frontlaser_angular_offset` says so (the log's own
  offset mirrored, plus that step). `ROBOTLASER1` lines carry their own start angle.
- `reverse` plays the log backwards, as a robot driving in reverse would record it: the timed
  lines in reverse order, each timestamp t mapped to t_first + t_last − t (exactly, in
  decimal), velocities negated. The laser then looks where the robot has been, and new ground
  appears beside it instead of ahead. The relations keep their values and map their
  timestamps the same way.

Both transformations are their own inverse. Lines the script does not know (`RAWLASER1`,
`SYNC`, comments) are copied unchanged; `reverse` writes them, and the `PARAM`s, before the
timed lines, and `mirror` writes every `PARAM` first, as a reader needs them before the first
laser line.
"""

import argparse
import bz2
import decimal
import math
import pathlib
import sys

# FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
# ROBOTLASER1 type start fov res max_range accuracy remission_mode n r_1..r_n m rem_1..rem_m
#     laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv fwd_safety side_safety
#     turn_axis ipc_timestamp host logger_timestamp
# ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp
# TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
# (The angular offset below assumes every FLASER line of a log has as many beams as the first.)
TIMED = {"FLASER", "ROBOTLASER1", "ODOM", "TRUEPOS"}
DEFAULT_FOV_DEG = 180.0
ANGULAR_OFFSET = "robot_frontlaser_angular_offset"


def read_lines(path):
    opener = bz2.open if str(path).endswith(".bz2") else open
    with opener(path, "rt") as f:
        return f.read().splitlines()


def negate(text):
    """The number written in `text`, negated without rounding: the sign flipped."""
    return text[1:] if text.startswith("-") else "-" + text.lstrip("+")


def negate_at(fields, *indices):
    for i in indices:
        fields[i] = negate(fields[i])


def flaser_shift(beams, fov_deg):
    """How far (rad) the last beam of a `FLASER` scan of `beams` beams falls short of +fov/2
    as a reader lays it out: one step (fov/n) for the 180- and 360-beam layouts, none where
    the beams span the field of view evenly (step fov/(n−1)). The mirror image of the scan
    lies that much to the left of where a reader puts it."""
    return math.radians(fov_deg) / beams if beams in (180, 360) else 0.0


def mirror_line(fields):
    kind = fields[0]
    if kind == "FLASER":
        n = int(fields[1])
        fields[2 : 2 + n] = fields[2 : 2 + n][::-1]
        rest = 2 + n  # x y theta odom_x odom_y odom_theta
        negate_at(fields, rest + 1, rest + 2, rest + 4, rest + 5)
    elif kind == "ROBOTLASER1":
        start, res, n = float(fields[2]), float(fields[4]), int(fields[8])
        fields[2] = repr(-(start + (n - 1) * res))
        fields[9 : 9 + n] = fields[9 : 9 + n][::-1]
        m_at = 9 + n
        m = int(fields[m_at])
        fields[m_at + 1 : m_at + 1 + m] = fields[m_at + 1 : m_at + 1 + m][::-1]
        p = m_at + 1 + m  # laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
        negate_at(fields, p + 1, p + 2, p + 4, p + 5, p + 7)
    elif kind == "ODOM":
        negate_at(fields, 2, 3, 5)
    elif kind == "TRUEPOS":
        negate_at(fields, 2, 3, 5, 6)
    return fields


def mirror(lines, fov_deg=None):
    """The log reflected across the x axis of its odometry frame."""
    params = {}
    for line in lines:
        f = line.split()
        if len(f) >= 3 and f[0] == "PARAM":
            params[f[1]] = f[2]
    if fov_deg is None:
        fov_deg = float(params.get("laser_front_laser_fov", DEFAULT_FOV_DEG))
    beams = next((int(f[1]) for f in map(str.split, lines) if f and f[0] == "FLASER"), None)
    shift = flaser_shift(beams, fov_deg) if beams is not None else 0.0
    offset = -float(params.get(ANGULAR_OFFSET, "0")) + shift
    head, body = [], []
    for line in lines:
        f = line.split()
        if f and f[0] == "PARAM":
            if f[1] == ANGULAR_OFFSET:
                continue
            if f[1] == "robot_frontlaser_side_offset":
                negate_at(f, 2)
            head.append(" ".join(f))
        elif f and f[0] in TIMED:
            body.append(" ".join(mirror_line(f)))
        else:
            (head if not body else body).append(line)
    if beams is not None and (offset != 0.0 or ANGULAR_OFFSET in params):
        head.append(f"PARAM {ANGULAR_OFFSET} {offset!r} derived_logs 0")
    return head + body


def timestamps(fields):
    """Indices of a timed line's ipc and logger timestamps."""
    return len(fields) - 3, len(fields) - 1


def time_map(lines, which=0):
    """t ↦ t_first + t_last − t over the timed lines' ipc timestamps (`which` 0) or logger
    timestamps (1), in decimal."""
    stamps = [
        decimal.Decimal(f[timestamps(f)[which]])
        for f in map(str.split, lines)
        if f and f[0] in TIMED
    ]
    if not stamps:
        raise SystemExit("no timed lines (FLASER, ROBOTLASER1, ODOM, TRUEPOS) in the log")
    total = min(stamps) + max(stamps)
    return lambda text: str(total - decimal.Decimal(text))


def reverse(lines):
    """The log played backwards."""
    ipc, logger = time_map(lines, 0), time_map(lines, 1)
    head, timed = [], []
    for line in lines:
        f = line.split()
        if f and f[0] in TIMED:
            i, j = timestamps(f)
            f[i], f[j] = ipc(f[i]), logger(f[j])
            if f[0] == "ODOM":
                negate_at(f, 4, 5)
            elif f[0] == "ROBOTLASER1":
                n = int(f[8])
                p = 9 + n + 1 + int(f[9 + n])
                negate_at(f, p + 6, p + 7)
            timed.append(" ".join(f))
        else:
            head.append(line)
    return head + timed[::-1]


def relations(lines, kind, log_lines):
    """The relations (t1 t2 dx dy dz roll pitch yaw) for the derived log."""
    ipc = time_map(log_lines) if kind == "reverse" else None
    out = []
    for line in lines:
        f = line.split()
        if len(f) < 8:
            out.append(line)
            continue
        if kind == "mirror":
            negate_at(f, 3, 7)
        else:
            f[0], f[1] = ipc(f[0]), ipc(f[1])
        out.append(" ".join(f))
    return out


def trajectory(lines, kind, log_lines):
    """A TUM trajectory (t x y z qx qy qz qw, stamps as the log's ipc timestamps, a pure yaw)
    for the derived log: mirrored, y, qx and qz negated (the yaw θ becomes −θ); played
    backwards, each stamp mapped as the log's and the poses in reverse order, as its laser
    lines."""
    ipc = time_map(log_lines) if kind == "reverse" else None
    head, poses = [], []
    for line in lines:
        f = line.split()
        if len(f) < 8 or line.lstrip().startswith("#"):
            head.append(line)
            continue
        if kind == "mirror":
            negate_at(f, 2, 4, 6)
        else:
            f[0] = ipc(f[0])
        poses.append(f)
    if kind == "reverse":
        poses.reverse()
    return head + [" ".join(f) for f in poses]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=["mirror", "reverse"])
    parser.add_argument("log", type=pathlib.Path, help="CARMEN log (plain or .bz2)")
    parser.add_argument("relations", help="its relations (- for none)")
    parser.add_argument("out_log", type=pathlib.Path)
    parser.add_argument("out_relations", help="(- with no relations)")
    parser.add_argument(
        "--trajectory",
        nargs=2,
        metavar=("TUM", "OUT_TUM"),
        type=pathlib.Path,
        help="also transform a trajectory of the log (TUM), e.g. the reference of a sweep",
    )
    parser.add_argument(
        "--fov-deg",
        type=float,
        help="field of view of FLASER scans (default: the log's PARAM laser_front_laser_fov, "
        "else 180), as `qicp match --fov-deg`",
    )
    args = parser.parse_args(argv)
    if (args.relations == "-") != (args.out_relations == "-"):
        parser.error("relations and out_relations: both files, or both -")
    decimal.getcontext().prec = 40
    log = read_lines(args.log)
    derived = mirror(log, args.fov_deg) if args.kind == "mirror" else reverse(log)
    args.out_log.write_text("\n".join(derived) + "\n")
    print(f"{args.kind}: {args.out_log} ({len(derived)} lines)", end="")
    if args.relations != "-":
        rel = relations(read_lines(args.relations), args.kind, log)
        pathlib.Path(args.out_relations).write_text("\n".join(rel) + "\n")
        print(f", {args.out_relations} ({len(rel)} relations)", end="")
    if args.trajectory:
        tum, out_tum = args.trajectory
        poses = trajectory(read_lines(tum), args.kind, log)
        out_tum.write_text("\n".join(poses) + "\n")
        print(f", {out_tum} ({len(poses)} poses)", end="")
    print()


if __name__ == "__main__":
    sys.exit(main())
