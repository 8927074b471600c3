"""`qicp sweep` on Ray: every run of the sweep (the default and each variant) is one Ray task.

    python examples/ray_sweep.py LOG [RELATIONS] [--matcher q-wsm | --config FILE] [--scans N]
        [--variants a,b,...] [--address auto|local|ray://HOST:10001] [--out FILE]
        [--reference TUM] [--drawn-relations FILE]

Writes the JSON report of `qicp sweep LOG --matcher ... --relations RELATIONS --json`: the
same runs, the same figures (only the wall times per scan differ), the same ratios. Without
RELATIONS it is the report of `qicp sweep LOG --json`, a sweep against the default run: the
default runs first (one task), writing the relations drawn along its trajectory to
`--drawn-relations` (default: a temporary file, which on a cluster must be replaced by a path
every node reads), and the variants' tasks are scored with them. With `--reference TUM`
instead of RELATIONS it is the report of `qicp sweep LOG --reference TUM`: the relations are
drawn along that trajectory first (to `--drawn-relations`), and every run, the default's too,
is scored with them.

On one machine, `--address local` starts a Ray instance for the sweep and stops it after. On a
cluster, start Ray on the nodes (`ray start --head` on one, `ray start --address HEAD:6379` on
the others), install the qicp wheel on every node (`pip install ./python`), make LOG and
RELATIONS readable at the same path on every node (a shared file system), and run this script
with `--address auto` on the head node (or `ray://HEAD:10001` from elsewhere). Each task reads
the log itself, so only the file names travel.
"""

import argparse
import json
import os
import sys
import tempfile

import ray

import qicp


@ray.remote
def run(log, relations, name, matcher, config, scans, lenient):
    """One run of the sweep: its figures, or the message of its failure."""
    try:
        return qicp.sweep_run(
            log, relations, name, matcher=matcher, config=config, scans=scans, lenient=lenient
        )
    except qicp.QicpError as e:
        return str(e)


@ray.remote
def default_run(log, out, matcher, config, scans, lenient):
    """The default run of a sweep without relations: its figures (it writes the relations
    drawn along it to `out`), or the message of its failure."""
    try:
        return qicp.sweep_relations(
            log, out, matcher=matcher, config=config, scans=scans, lenient=lenient
        )
    except qicp.QicpError as e:
        return str(e)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("relations", nargs="?", help="Freiburg relations (default: the default run's)")
    ap.add_argument("--reference", help="a TUM trajectory to score every run against (no RELATIONS)")
    ap.add_argument("--drawn-relations",
                    help="where the relations drawn along the default run or the reference go")
    ap.add_argument("--matcher", default="q-wsm")
    ap.add_argument("--config", help="TOML file with a [matcher] table (instead of --matcher)")
    ap.add_argument("--scans", type=int, help="use only the first N records of the log")
    ap.add_argument("--variants", help="comma-separated variant names (default: all)")
    ap.add_argument("--lenient", action="store_true")
    ap.add_argument("--address", default="local", help="auto, local, or a Ray address")
    ap.add_argument("--out", help="write the JSON report here (default: stdout)")
    a = ap.parse_args(argv)
    if a.relations is not None and a.reference is not None:
        ap.error("RELATIONS and --reference cannot be used together")

    names = qicp.sweep_variants(a.matcher, config=a.config)
    if a.variants:
        wanted = [v.strip() for v in a.variants.split(",") if v.strip() and v.strip() != "default"]
        unknown = [v for v in wanted if v not in names]
        if unknown:
            sys.exit(f"unknown variants {', '.join(unknown)}; known: {', '.join(names)}")
        names = [n for n in names if n in wanted]
    names = ["default", *names]

    against_default = a.relations is None and a.reference is None
    scratch = None
    relations = a.relations
    if relations is None:
        relations = a.drawn_relations
        if relations is None:
            scratch = tempfile.TemporaryDirectory(prefix="qicp-ray-sweep-")
            relations = os.path.join(scratch.name, "drawn.relations")
    if a.reference is not None:
        try:
            qicp.reference_relations(a.log, a.reference, relations, scans=a.scans, lenient=a.lenient)
        except qicp.QicpError as e:
            sys.exit(str(e))

    def report_on(name, result):
        if isinstance(result, str):
            print(f"variant {name} failed: {result}", file=sys.stderr)
        else:
            print(f"variant {name} done (trans_mean {result['trans_mean']:.4f} m)", file=sys.stderr)

    ray.init(address=None if a.address == "local" else a.address, log_to_driver=False)
    try:
        args = (a.matcher, a.config, a.scans, a.lenient)
        results = []
        if against_default:
            # The variants are scored with the default's trajectory: it runs first.
            default = ray.get(default_run.remote(a.log, relations, *args))
            report_on("default", default)
            if isinstance(default, str):
                sys.exit(f"the default run failed: {default}")
            results.append(("default", default))
            names = names[1:]
        futures = [run.remote(a.log, relations, n, *args) for n in names]
        for name, future in zip(names, futures):
            result = ray.get(future)
            results.append((name, result))
            report_on(name, result)
    finally:
        ray.shutdown()

    report = qicp.sweep_report(
        a.log, relations, results, matcher=a.matcher, config=a.config, scans=a.scans,
        lenient=a.lenient, against_default=against_default, reference=a.reference,
    )
    if scratch is not None:
        scratch.cleanup()
    if a.out:
        with open(a.out, "w") as f:
            f.write(report + "\n")
    else:
        print(report)
    json.loads(report)  # a report that does not parse is a bug here, not a result
    return 0


if __name__ == "__main__":
    sys.exit(main())
